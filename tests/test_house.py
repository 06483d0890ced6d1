"""The house rules on ``smccli/``: no module over 600 lines, no function over 80, no import
circle (deferred and ``if TYPE_CHECKING:`` imports included), and every ``docs/...md`` or
``DESIGN.md`` that ``smccli/`` and ``docs/`` cite is a file of the repository.

Each checker is a function tried first on small synthetic packages (so it can fail), then
on the real tree.
"""

from __future__ import annotations

import ast
import re
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
PACKAGE = REPO / "smccli"
MAX_MODULE_LINES = 600
MAX_FUNCTION_LINES = 80
CITING = ("smccli", "docs")
"""Folders whose files' citations of docs must resolve."""
CITE = re.compile(r"(?<![\w.-])(/?(?:[\w.-]+/)*(?:DESIGN\.md|docs/[\w./-]*?\.md))(?![\w/-])")
"""A cited ``docs/...md`` or ``DESIGN.md`` path (with whatever folders precede it)."""


# --- the checkers -------------------------------------------------------------------------


def long_modules(package: Path, limit: int = MAX_MODULE_LINES) -> list[str]:
    """``path: N lines`` for each ``.py`` under ``package`` over ``limit`` lines (as wc -l)."""
    out = []
    for path in sorted(package.rglob("*.py")):
        n = path.read_text().count("\n")
        if n > limit:
            out.append(f"{path.relative_to(package.parent)}: {n} lines")
    return out


def long_functions(package: Path, limit: int = MAX_FUNCTION_LINES) -> list[str]:
    """``path:line name: N lines`` for each function or method (nested ones too) under
    ``package`` over ``limit`` lines (``end_lineno - lineno + 1``, decorators excluded)."""
    out = []
    for path in sorted(package.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                assert node.end_lineno is not None
                n = node.end_lineno - node.lineno + 1
                if n > limit:
                    where = f"{path.relative_to(package.parent)}:{node.lineno}"
                    out.append(f"{where} {node.name}: {n} lines")
    return out


@dataclass(frozen=True)
class Import:
    """One edge of the import graph: where it is written."""

    path: Path
    line: int
    deferred: bool
    """Written inside a function (runs when the function is first called)."""


def module_files(package: Path) -> dict[str, Path]:
    """Dotted module name -> file, for every ``.py`` under ``package`` (a package's own
    name for its ``__init__.py``)."""
    out = {}
    for path in sorted(package.rglob("*.py")):
        parts = path.relative_to(package.parent).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _imports(tree: ast.AST) -> list[tuple[ast.Import | ast.ImportFrom, bool]]:
    """Every import statement in ``tree`` (module level, ``if TYPE_CHECKING:``, inside
    functions and classes), with whether it is inside a function."""
    found: list[tuple[ast.Import | ast.ImportFrom, bool]] = []

    def visit(node: ast.AST, deferred: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.Import | ast.ImportFrom):
                found.append((child, deferred))
            inner = isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda)
            visit(child, deferred or inner)

    visit(tree, False)
    return found


def _target(name: str, modules: dict[str, Path]) -> str | None:
    """The longest prefix of dotted ``name`` that is one of ``modules``."""
    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        prefix = ".".join(parts[:k])
        if prefix in modules:
            return prefix
    return None


def import_graph(package: Path) -> dict[str, dict[str, Import]]:
    """Module -> {module it imports: where}, within ``package``.

    ``import a.b`` is an edge to ``a.b``; ``from pkg import name`` to ``pkg.name`` when
    that is a module, else to ``pkg`` (its ``__init__``); relative imports are resolved.
    A module importing itself is no edge.
    """
    modules = module_files(package)
    graph: dict[str, dict[str, Import]] = {}
    for name, path in modules.items():
        here = name if path.name == "__init__.py" else name.rpartition(".")[0]
        edges: dict[str, Import] = {}
        for node, deferred in _imports(ast.parse(path.read_text(), filename=str(path))):
            targets: list[str | None] = []
            if isinstance(node, ast.Import):
                targets = [_target(a.name, modules) for a in node.names]
            else:
                if node.level:
                    parts = here.split(".")
                    base = ".".join(parts[: len(parts) - (node.level - 1)])
                    base = f"{base}.{node.module}" if node.module else base
                else:
                    base = node.module or ""
                for a in node.names:
                    sub = f"{base}.{a.name}"
                    targets.append(sub if sub in modules else _target(base, modules))
            for t in targets:
                if t is not None and t != name and t not in edges:
                    edges[t] = Import(path, node.lineno, deferred)
        graph[name] = edges
    return graph


def _components(graph: dict[str, dict[str, Import]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            w = next(children, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return sorted(out)


def _shortest_cycle(graph: dict[str, dict[str, Import]], comp: list[str]) -> list[str]:
    """A shortest cycle through ``comp[0]`` inside ``comp``: [a, b, ..., a]."""
    start, inside = comp[0], set(comp)
    came: dict[str, str] = {}
    frontier = [start]
    while frontier:
        nxt = []
        for v in frontier:
            for w in sorted(graph[v]):
                if w == start:
                    path = [v]
                    while path[-1] != start:
                        path.append(came[path[-1]])
                    return [start, *reversed(path[:-1]), start]
                if w in inside and w not in came:
                    came[w] = v
                    nxt.append(w)
        frontier = nxt
    raise AssertionError(f"no cycle through {start} in {comp}")


def import_circles(package: Path) -> list[str]:
    """One readable chain per circle of modules importing each other, e.g.
    ``pkg.a -> pkg.b (pkg/a.py:3) -> pkg.a (pkg/b.py:7, deferred)``, followed by every
    module of that circle when more than the chain's."""
    graph = import_graph(package)
    out = []
    for comp in _components(graph):
        cycle = _shortest_cycle(graph, comp)
        words = [cycle[0]]
        for a, b in zip(cycle, cycle[1:], strict=False):
            imp = graph[a][b]
            where = f"{imp.path.relative_to(package.parent)}:{imp.line}"
            words.append(f"{b} ({where}{', deferred' if imp.deferred else ''})")
        text = " -> ".join(words)
        if len(comp) > len(cycle) - 1:
            text += f"; all {len(comp)} modules of this circle: {', '.join(comp)}"
        out.append(text)
    return out


def _in_repo(repo: Path, folder: Path, cited: str) -> bool:
    """``cited`` is a file of ``repo``, read from its top or from ``folder`` (a link's
    base); an absolute path never is."""
    if cited.startswith("/"):
        return False
    for base in (repo, folder):
        path = (base / cited).resolve()
        if path.is_file() and path.is_relative_to(repo.resolve()):
            return True
    return False


def missing_cites(repo: Path, folders: tuple[str, ...] = CITING) -> list[str]:
    """``file:line cites PATH`` for each ``docs/...md`` or ``DESIGN.md`` cited in a text file
    under ``folders`` of ``repo`` that is not a file of ``repo`` (paths relative to it)."""
    out = []
    for folder in folders:
        for path in sorted((repo / folder).rglob("*")):
            if not path.is_file():
                continue
            try:
                text = path.read_text()
            except (UnicodeDecodeError, OSError):
                continue  # images and other binaries cite nothing
            for k, line in enumerate(text.splitlines(), start=1):
                for cited in CITE.findall(line):
                    if not _in_repo(repo, path.parent, cited):
                        out.append(f"{path.relative_to(repo)}:{k} cites {cited}")
    return out


# --- the checkers on synthetic packages ---------------------------------------------------


def _package(root: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    return root / next(iter(files)).split("/")[0]


def test_a_circle_through_a_deferred_import_is_found(tmp_path):
    pkg = _package(
        tmp_path,
        {
            "pkg/__init__.py": "",
            "pkg/a.py": "from pkg import b\n",
            "pkg/b.py": "import os\n\n\ndef f():\n    from . import a\n\n    return a, os\n",
            "pkg/c.py": "import pkg.a\n",
        },
    )
    assert import_circles(pkg) == ["pkg.a -> pkg.b (pkg/a.py:1) -> pkg.a (pkg/b.py:5, deferred)"]


def test_circles_through_type_checking_and_a_package_init_are_found(tmp_path):
    pkg = _package(
        tmp_path,
        {
            "pkg/__init__.py": "from pkg.sub.x import X\n",
            "pkg/sub/__init__.py": "",
            "pkg/sub/x.py": (
                "from typing import TYPE_CHECKING\n\nif TYPE_CHECKING:\n"
                "    from ..y import Y\n\nX = 1\n"
            ),
            "pkg/y.py": "from pkg import X\n\nY = X\n",
        },
    )
    circles = import_circles(pkg)
    assert len(circles) == 1
    assert circles[0].startswith("pkg -> pkg.sub.x (pkg/__init__.py:1) -> pkg.y (pkg/sub/x.py:4)")
    assert circles[0].endswith("-> pkg (pkg/y.py:1)")


def test_a_package_without_a_circle_passes(tmp_path):
    pkg = _package(
        tmp_path,
        {
            "pkg/__init__.py": "from pkg.a import A\n",
            "pkg/a.py": "from pkg import b\nfrom pkg.b import B\n\nA = B\n",
            "pkg/b.py": (
                "import json\n\n\ndef f():\n    import pkg.c\n\n    return pkg.c\n\nB = 1\n"
            ),
            "pkg/c.py": "import json\n",
        },
    )
    graph = import_graph(pkg)
    # ``from pkg import b`` is an edge to the module pkg.b, not to pkg's __init__.
    assert {k: set(v) for k, v in graph.items()} == {
        "pkg": {"pkg.a"},
        "pkg.a": {"pkg.b"},
        "pkg.b": {"pkg.c"},
        "pkg.c": set(),
    }
    assert import_circles(pkg) == []
    (pkg / "c.py").write_text("from . import b as _b\nfrom .b import B\n")
    assert import_circles(pkg) == ["pkg.b -> pkg.c (pkg/b.py:5, deferred) -> pkg.b (pkg/c.py:1)"]


def test_sizes_are_counted_as_the_rules_say(tmp_path):
    body = "    x = 1\n"
    method_body = "        x = 1\n"
    pkg = _package(
        tmp_path,
        {
            "pkg/__init__.py": "",
            "pkg/fits.py": "def f():\n" + body * 79,  # 80 lines
            "pkg/long.py": "class C:\n    def m(self):\n" + method_body * 80,  # 81 lines
            "pkg/big.py": "x = 1\n" * 601,
        },
    )
    assert long_functions(pkg) == ["pkg/long.py:2 m: 81 lines"]
    assert long_modules(pkg) == ["pkg/big.py: 601 lines"]


def test_cites_of_missing_docs_are_found(tmp_path):
    repo = tmp_path / "repo"
    _package(
        repo,
        {
            "smccli/a.py": '"""See docs/design.md section 6 and docs/gone.md."""\n',
            "docs/design.md": "# Design\n\nAs DESIGN.md says, and /work/shared/DESIGN.md.\n",
        },
    )
    assert missing_cites(repo) == [
        "smccli/a.py:1 cites docs/gone.md",
        "docs/design.md:3 cites DESIGN.md",
        "docs/design.md:3 cites /work/shared/DESIGN.md",
    ]
    # Read from the top or from the citing file's folder, but never outside the repository.
    (repo / "DESIGN.md").write_text("")
    _package(tmp_path, {"outside/DESIGN.md": ""})
    (repo / "docs" / "more.md").write_text("See ../DESIGN.md and ../../outside/DESIGN.md.\n")
    assert missing_cites(repo) == [
        "smccli/a.py:1 cites docs/gone.md",
        "docs/design.md:3 cites /work/shared/DESIGN.md",
        "docs/more.md:1 cites ../../outside/DESIGN.md",
    ]


# --- the rules on smccli/ -----------------------------------------------------------------


def test_no_module_over_600_lines():
    found = long_modules(PACKAGE)
    assert not found, "modules over 600 lines:\n" + "\n".join(found)


def test_no_function_over_80_lines():
    found = long_functions(PACKAGE)
    assert not found, "functions over 80 lines:\n" + "\n".join(found)


def test_no_import_circle():
    found = import_circles(PACKAGE)
    assert not found, "import circles:\n" + "\n".join(found)


def test_cited_docs_are_in_the_repository():
    found = missing_cites(REPO)
    assert not found, "cited, not in the repository:\n" + "\n".join(found)
