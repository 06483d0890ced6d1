"""The package layout of docs/layout.md: folders by pipeline stage, dependencies pointing
down the pipeline, no robot constants in code."""

from __future__ import annotations

import ast
import re
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "smccli"

# Each stage may import itself and what is listed (errors, schemas, outputs: everyone).
ALLOWED = {
    "world": set(),
    "logs": {"world"},
    "perception": {"world"},
    "learn": {"world", "logs", "perception"},
    "record": {"world", "logs", "perception"},
    # Teaching during replay records the operator (execute/teach.py, docs/layout.md).
    "execute": {"world", "logs", "perception", "learn", "record"},
    "inspect": {"world", "logs", "perception", "learn"},
    "bench": {"world", "logs", "perception", "learn", "record", "execute", "inspect"},
}
BOTTOM = {"errors", "schemas", "outputs", "__init__", "__version__"}


def _imports(path: Path) -> set[str]:
    """Top-level smccli subpackages or modules ``path`` imports (at any depth)."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        names = []
        if isinstance(node, ast.ImportFrom) and node.module:
            names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        for name in names:
            parts = name.split(".")
            if parts[0] == "smccli" and len(parts) > 1:
                out.add(parts[1])
    return out


def test_folders_follow_the_pipeline() -> None:
    top = {p.stem for p in PACKAGE.glob("*.py")}
    assert top == {"__init__", "cli", "errors", "schemas", "outputs"}, top
    folders = {p.name for p in PACKAGE.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    assert folders == set(ALLOWED), folders


def test_dependencies_point_down_the_pipeline() -> None:
    bad = []
    for stage, allowed in ALLOWED.items():
        for path in (PACKAGE / stage).rglob("*.py"):
            for dep in _imports(path) - BOTTOM - {stage} - allowed:
                bad.append(f"{path.relative_to(PACKAGE)} imports smccli.{dep}")
    assert not bad, bad


def test_control_never_imports_the_evaluation() -> None:
    """Algorithm 2 and its sensors never see the module that reads the simulator's truth."""
    for name in ("executor.py", "policy.py", "sensing.py"):
        tree = ast.parse((PACKAGE / "execute" / name).read_text())
        modules = [n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)] + [
            a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names
        ]
        assert not [m for m in modules if "evaluation" in m], name


def test_no_robot_constants_in_code() -> None:
    """Joint, actuator and site names live in robot files only."""
    pattern = re.compile(
        r"ARM_JOINTS|ARM_ACTUATORS|GRIPPER_JOINTS|FINGER_TRAVEL|\bHOME\b"
        r"|finger_left|finger_right|\"joint\d|\"act\d|arm_base"
    )
    hits = [
        f"{p.relative_to(PACKAGE)}:{i}: {line.strip()}"
        for p in PACKAGE.rglob("*.py")
        for i, line in enumerate(p.read_text().splitlines(), 1)
        if pattern.search(line)
    ]
    assert not hits, hits


def test_library_does_not_print() -> None:
    """Library modules return data; cli.py (and the bench scripts) print."""
    offenders = []
    for path in PACKAGE.rglob("*.py"):
        rel = path.relative_to(PACKAGE)
        if rel.parts[0] in ("cli.py", "bench"):
            continue
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "print":
                offenders.append(f"{rel}:{node.lineno}")
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("rich"):
                offenders.append(f"{rel}:{node.lineno} imports {node.module}")
    assert not offenders, offenders
