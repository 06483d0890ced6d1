"""The package layout of docs/layout.md: folders by pipeline stage, dependencies pointing
down the pipeline, no robot constants in code."""

from __future__ import annotations

import ast
import re
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "smccli"

# Each stage may import itself and what is listed (errors, schemas, outputs, workers:
# everyone).
ALLOWED = {
    "world": set(),
    "logs": {"world"},
    "perception": {"world"},
    "learn": {"world", "logs", "perception"},
    "record": {"world", "logs", "perception"},
    # Teaching during replay records the operator (execute/teach.py, docs/layout.md).
    "execute": {"world", "logs", "perception", "learn", "record"},
    "inspect": {"world", "logs", "perception", "learn"},
    # smc run and smc sim over ROS: the executor's loop on a robot's topics.
    "ros": {"world", "logs", "perception", "learn", "execute"},
    "bench": {"world", "logs", "perception", "learn", "record", "execute", "inspect", "ros"},
}
BOTTOM = {"errors", "schemas", "outputs", "workers", "__init__", "__version__"}


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
    assert top == {"__init__", "cli", "errors", "schemas", "outputs", "workers"}, top
    folders = {p.name for p in PACKAGE.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    # commands: cli.py's, one module per command; like cli.py they may import any stage.
    assert folders == set(ALLOWED) | {"commands"}, folders


def test_dependencies_point_down_the_pipeline() -> None:
    bad = []
    for stage, allowed in ALLOWED.items():
        for path in (PACKAGE / stage).rglob("*.py"):
            for dep in _imports(path) - BOTTOM - {stage} - allowed:
                bad.append(f"{path.relative_to(PACKAGE)} imports smccli.{dep}")
    assert not bad, bad


CONTROL_EXECUTE = [
    "executor",
    "policy",
    "sensing",
    "matching",
    "decision",
    "observation",
    "plan",
    "looking",
    "speed",
]
"""The modules of ``execute/`` that run Algorithm 2 (the rest is the harness around it)."""
CONTROL = [
    *(PACKAGE / "execute" / f"{name}.py" for name in CONTROL_EXECUTE),
    PACKAGE / "ros" / "node.py",
    PACKAGE / "ros" / "inbox.py",
    *sorted((PACKAGE / "perception").rglob("*.py")),
    *sorted((PACKAGE / "learn").rglob("*.py")),
]
"""Algorithm 2, what it perceives with, and what it learnt: the modules control runs."""


def _runtime_imports(path: Path) -> list[str]:
    """Every module ``path`` imports when it runs (``if TYPE_CHECKING:`` blocks left out:
    they import for the type checker only)."""
    out: list[str] = []

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and getattr(node.test, "id", None) == "TYPE_CHECKING":
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, ast.ImportFrom) and node.module:
            out.extend([node.module] + [f"{node.module}.{a.name}" for a in node.names])
        elif isinstance(node, ast.Import):
            out.extend(a.name for a in node.names)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(ast.parse(path.read_text()))
    return out


def test_control_never_imports_the_simulator_or_the_evaluation() -> None:
    """Control reaches the simulator through ``execute/sensing.Sensors`` alone, handed to
    it: no control module imports the simulator or the module that reads its truth."""
    bad = [
        f"{path.relative_to(PACKAGE)} imports {m}"
        for path in CONTROL
        for m in _runtime_imports(path)
        if m.startswith(("smccli.world.sim", "smccli.execute.evaluation"))
    ]
    assert not bad, bad


def _module_path(name: str) -> Path | None:
    """The file of smccli module ``name`` (a package: its ``__init__.py``), None if not one."""
    parts = name.split(".")
    if parts[0] != "smccli":
        return None
    base = PACKAGE.joinpath(*parts[1:])
    for path in (base.with_suffix(".py"), base / "__init__.py"):
        if path.is_file():
            return path
    return None


def test_control_never_imports_the_truth() -> None:
    """The honesty rule as an import rule: what only evaluation and the episode harness may
    read of the simulator (``smccli.world.truth``: object poses, the success criterion,
    the disturbances) is out of control's reach, directly or through any module it imports
    when it runs."""
    bad = []
    for path in CONTROL:
        seen: set[Path] = set()
        todo = [(path, str(path.relative_to(PACKAGE)))]
        while todo:
            here, chain = todo.pop()
            if here in seen:
                continue
            seen.add(here)
            for m in _runtime_imports(here):
                if m == "smccli.world.truth" or m.startswith("smccli.world.truth."):
                    bad.append(f"{chain} imports {m}")
                elif (dep := _module_path(m)) is not None:
                    todo.append((dep, f"{chain} -> {dep.relative_to(PACKAGE)}"))
    assert not bad, bad


VOCABULARY = {"world", "hand", "poi", "lidar", "gripper"}
"""Words that are smc's own concepts (goal frames, robot-file keys) and happen to name a
part of a built-in robot too."""


def _robot_names() -> set[str]:
    """Every named joint, actuator, site, body and geom of every built-in robot's MJCF."""
    import mujoco

    names: set[str] = set()
    for mjcf in (PACKAGE / "world" / "robots").glob("*/robot.xml"):
        m = mujoco.MjModel.from_xml_path(str(mjcf))
        for kind, n in (
            (mujoco.mjtObj.mjOBJ_JOINT, m.njnt),
            (mujoco.mjtObj.mjOBJ_ACTUATOR, m.nu),
            (mujoco.mjtObj.mjOBJ_SITE, m.nsite),
            (mujoco.mjtObj.mjOBJ_BODY, m.nbody),
            (mujoco.mjtObj.mjOBJ_GEOM, m.ngeom),
        ):
            names.update(filter(None, (mujoco.mj_id2name(m, kind, i) for i in range(n))))
    return names - VOCABULARY


def test_no_robot_constants_in_code() -> None:
    """Joint, actuator, site, body and geom names live in robot files only: no string in
    the package names a part of a built-in robot (read from their MJCF, so a robot added
    tomorrow is covered), and no constant holds a robot's joint list or home posture."""
    names = _robot_names()
    assert {"joint1", "finger_left_joint", "base_x"} <= names, "the robots' names were read"
    hits = [
        f"{p.relative_to(PACKAGE)}:{n.lineno}: {n.value!r}"
        for p in PACKAGE.rglob("*.py")
        for n in ast.walk(ast.parse(p.read_text()))
        if isinstance(n, ast.Constant) and isinstance(n.value, str) and n.value in names
    ]
    assert not hits, hits
    pattern = re.compile(r"ARM_JOINTS|ARM_ACTUATORS|GRIPPER_JOINTS|FINGER_TRAVEL|\bHOME\b")
    hits = [
        f"{p.relative_to(PACKAGE)}:{i}: {line.strip()}"
        for p in PACKAGE.rglob("*.py")
        for i, line in enumerate(p.read_text().splitlines(), 1)
        if pattern.search(line)
    ]
    assert not hits, hits


def test_library_does_not_print() -> None:
    """Library modules return data; cli.py and its commands (and the bench scripts) print."""
    offenders = []
    for path in PACKAGE.rglob("*.py"):
        rel = path.relative_to(PACKAGE)
        if rel.parts[0] in ("cli.py", "commands", "bench"):
            continue
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "print":
                offenders.append(f"{rel}:{node.lineno}")
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("rich"):
                offenders.append(f"{rel}:{node.lineno} imports {node.module}")
    assert not offenders, offenders
