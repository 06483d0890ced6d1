"""Teaching during replay (``smc replay TREE --teach script|keyboard``), paper section 4:
where a decision finds no contingent SMC the robot does not stop for good; an operator
takes over from that exact state (the robot and the scene as they are), the continuation
is recorded as a log whose metadata names the tree, its digest and the node, and compile
grows the tree from that node (Algorithm 1 inserted there, not at the root; the tree's
version grows by one and its history names the node). Execution then goes on
autonomously from where the taught chain ends.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from smccli.errors import SmcError
from smccli.learn.compile import compile_logs
from smccli.learn.tree import Tree, digest
from smccli.record.session import RecordConfig, RecordStatus, record_session
from smccli.world.sim import Sim


@dataclass(frozen=True, slots=True)
class TeachConfig:
    """Who teaches when replay finds no contingent SMC, and where it goes."""

    tree_path: Path
    """The tree file the taught log is compiled into."""
    operator: str = "script"
    """``script`` or ``keyboard``."""
    script: Path | None = None
    """Teleop script of the continuation (``script``)."""
    log: Path | None = None
    """The taught log; default: beside the tree, ``<tree>_taught_<node>_<k>.mcap``."""
    on_message: Callable[[str], None] | None = None
    """Told where teaching starts and, for the keyboard, the keys once the viewer is up."""
    on_status: Callable[[RecordStatus], None] | None = None
    """The recording's progress, every few ticks (as ``smc record``'s)."""


@dataclass(frozen=True, slots=True)
class Teaching:
    """What one teaching did."""

    node: str
    """Where replay found no contingent SMC and the operator took over."""
    log: Path
    """The recorded continuation."""
    version: int
    """The tree's version once the log was compiled in."""
    end: str
    """The node the taught chain ends at, where execution goes on."""
    marks: int
    """Saliency marks in the continuation (its fragments' boundaries)."""
    interrupted: str | None
    """Why the operator's recording stopped early, or None."""


def taught_log_path(tree_path: Path, node: str) -> Path:
    """The first free ``<tree>_taught_<node>_<k>.mcap`` beside the tree (k = 000, 001...):
    a recording is never overwritten."""
    k = 0
    while (p := tree_path.with_name(f"{tree_path.stem}_taught_{node}_{k:03d}.mcap")).exists():
        k += 1
    return p


def check_teach(cfg: TeachConfig) -> None:
    """Refuse a teaching that cannot start, before the episode runs."""
    if cfg.operator not in ("script", "keyboard"):
        raise SmcError(f"--teach {cfg.operator}: expected script or keyboard")
    if cfg.operator == "script" and cfg.script is None:
        raise SmcError("--teach script needs --script FILE (the continuation's teleop script)")
    if cfg.script is not None and not Path(cfg.script).is_file():
        raise SmcError(f"{cfg.script}: no such teleop script")


def teach(sim: Sim, tree: Tree, node: str, cfg: TeachConfig, seed: int = 0) -> Teaching:
    """The operator drives ``sim`` from its state now; the log is compiled into
    ``cfg.tree_path`` from ``node``. Returns what was taught and where the chain ends."""
    check_teach(cfg)
    out = cfg.log or taught_log_path(cfg.tree_path, node)
    rec = RecordConfig(
        scene=sim.scene.name, operator=cfg.operator, script=cfg.script, seed=seed, output=out
    )
    from smccli.record.keyboard import KeyboardOperator
    from smccli.record.operators import ScriptOperator, load_script

    if cfg.on_message is not None:
        cfg.on_message(
            f"no contingent SMC at {node}: the {cfg.operator} operator continues from here, "
            f"recording {out}"
        )
    operator: ScriptOperator | KeyboardOperator
    if cfg.operator == "script":
        assert cfg.script is not None
        operator = ScriptOperator(load_script(cfg.script), sim, seed=seed)
    else:
        operator = KeyboardOperator(sim, on_ready=cfg.on_message)
    extra = {
        "teach_tree": Path(cfg.tree_path).name,
        "teach_tree_digest": digest(tree),
        "teach_node": node,
        "teach_t0": f"{sim.t:.6f}",
    }
    if cfg.script is not None:
        extra["script"] = Path(cfg.script).name
    try:
        marks, interrupted = record_session(sim, operator, rec, out, extra, cfg.on_status)
    finally:
        if hasattr(operator, "close"):
            operator.close()
    result = compile_logs([out], cfg.tree_path)
    added = result.added[0] if result.added else None
    end = node
    if added is not None:  # follow the edges the taught log is a source of
        while nxt := [
            e for e in result.tree.children(end) if any(s.sha256 == added.sha256 for s in e.sources)
        ]:
            end = nxt[0].child
    return Teaching(
        node=node,
        log=out,
        version=result.tree.version,
        end=end,
        marks=marks,
        interrupted=interrupted,
    )
