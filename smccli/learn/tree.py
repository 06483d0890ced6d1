"""The SMC tree (paper 3.8, Algorithm 1) and its file, ``tree.json``.

Nodes are decision points, edges are SMCs. A demonstration's chain of SMCs is inserted by
walking from the root: among the current node's children contingent with the next SMC
(C_F, eq. 43) the one with the least D_P (eq. 44) absorbs it (support-weighted merge);
when none is contingent the rest of the chain hangs from the current node.

The file (schema: ``schemas/tree.schema.json``) is plain JSON: nothing in it is ever
executed. It is replaced atomically (write ``.part``, fsync, rename) under a lock file, so
an interrupted or concurrent compile never leaves it half-written.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from smccli.errors import SmcError, TreeError
from smccli.learn.contingency import c_f, d_p, merge
from smccli.learn.params import SmcParams, params_from_dict, params_to_dict
from smccli.learn.smc import Smc, Source, smc_from_dict, smc_to_dict

FORMAT = "smc-tree"
SCHEMA_VERSION = 1
ROOT = "n0"


@dataclass(frozen=True, slots=True)
class Edge:
    """One SMC hanging between two decision points."""

    id: str
    """Edge id, ``e1``, ``e2``, ... in creation order."""
    parent: str
    """Node id of the decision point where this SMC is chosen."""
    child: str
    """Node id reached when its action is done."""
    smc: Smc
    """Salient perceptions and action."""
    support: int
    """How many demonstration fragments were merged into it."""
    sources: tuple[Source, ...]
    """Those fragments (log sha256 + time window)."""


@dataclass(frozen=True, slots=True)
class Tree:
    """An SMC tree with its build parameters and compile history."""

    params: SmcParams
    """Parameters it was built with."""
    nodes: tuple[str, ...] = (ROOT,)
    """Decision point ids; ``n0`` is the root."""
    edges: tuple[Edge, ...] = ()
    """SMCs, in creation order."""
    version: int = 0
    """Grows by one with each compile that changes the tree."""
    history: tuple[dict[str, Any], ...] = ()
    """One entry per compile that changed the tree: version, time, logs added, smc version."""
    scene: dict[str, Any] = field(default_factory=dict)
    """Scene of the first log: name, digest, the log holding it, and the sensors the tree
    perceives through (camera resolution and field of view, whether a scale)."""
    robot: dict[str, Any] = field(default_factory=dict)
    """Robot the tree was taught on: name and kinematics digest
    (:func:`smccli.world.robot.kinematics_digest`). Empty in trees from before robot files."""

    def children(self, node: str) -> list[Edge]:
        """Edges leaving ``node``, in creation order."""
        return [e for e in self.edges if e.parent == node]

    def log_digests(self) -> set[str]:
        """sha256 of every log whose fragments are in the tree."""
        return {s.sha256 for e in self.edges for s in e.sources}


def insert_chain(
    tree: Tree, chain: Sequence[Smc], sources: Sequence[Source], at: str = ROOT
) -> Tree:
    """Algorithm 1: insert one demonstration's SMC chain, merging contingent prefixes;
    from the root, or from node ``at`` (a continuation taught where replay found no
    contingent SMC)."""
    if at not in tree.nodes:
        raise TreeError(f"the tree has no node {at!r} to insert at")
    nodes = list(tree.nodes)
    edges = list(tree.edges)
    node = at
    for j, (smc, src) in enumerate(zip(chain, sources, strict=True)):
        candidates = [e for e in edges if e.parent == node and c_f(smc, e.smc, tree.params)]
        if not candidates:
            # No contingent SMC: the rest of the chain becomes a new branch (line 19).
            for smc_k, src_k in zip(chain[j:], sources[j:], strict=True):
                child = f"n{len(nodes)}"
                nodes.append(child)
                edges.append(
                    Edge(
                        id=f"e{len(edges) + 1}",
                        parent=node,
                        child=child,
                        smc=smc_k,
                        support=1,
                        sources=(src_k,),
                    )
                )
                node = child
            break
        best = min(candidates, key=lambda e: d_p(smc.perception, e.smc.perception, tree.params))
        merged = Edge(
            id=best.id,
            parent=best.parent,
            child=best.child,
            smc=merge(best.smc, smc, best.support, 1, tree.params),
            support=best.support + 1,
            sources=(*best.sources, src),
        )
        edges[edges.index(best)] = merged
        node = best.child
    return replace(tree, nodes=tuple(nodes), edges=tuple(edges))


# --- file ---------------------------------------------------------------------------------


def _content(tree: Tree) -> dict[str, Any]:
    """What the digest covers: parameters, nodes and edges (not version, time or history)."""
    edges = []
    for e in tree.edges:
        perception, action = smc_to_dict(e.smc)
        edges.append(
            {
                "id": e.id,
                "parent": e.parent,
                "child": e.child,
                "perception": perception,
                "action": action,
                "support": e.support,
                "sources": [
                    {"log": s.log, "sha256": s.sha256, "t0": s.t0, "t1": s.t1} for s in e.sources
                ],
            }
        )
    return {
        "params": params_to_dict(tree.params),
        "nodes": [{"id": n} for n in tree.nodes],
        "edges": edges,
    }


def digest(tree: Tree) -> str:
    """Content digest ``sha256:<hex>`` of parameters, nodes and edges."""
    canon = json.dumps(_content(tree), sort_keys=True, separators=(",", ":"), allow_nan=False)
    return "sha256:" + hashlib.sha256(canon.encode()).hexdigest()


def tree_to_dict(tree: Tree) -> dict[str, Any]:
    """The JSON document of a tree (outline fixed by docs/design.md section 4)."""
    content = _content(tree)
    return {
        "format": FORMAT,
        "schema_version": SCHEMA_VERSION,
        "version": tree.version,
        "digest": digest(tree),
        "scene": tree.scene,
        "robot": tree.robot,
        "params": content["params"],
        "history": list(tree.history),
        "nodes": content["nodes"],
        "edges": content["edges"],
    }


@functools.cache
def _validator() -> Any:
    """The tree schema's validator, built once (checking the schema itself costs ~10 ms)."""
    import jsonschema

    from smccli.schemas import load_schema

    schema = load_schema("tree")
    cls = jsonschema.validators.validator_for(schema)
    cls.check_schema(schema)
    return cls(schema)


_FLOAT_MAX = sys.float_info.max


def _bad_number(doc: Any) -> tuple[str, str] | None:
    """(path, problem) of the first number ``json.loads`` accepts but a tree never holds
    (``save_tree`` writes with ``allow_nan=False``): NaN, infinity, an integer beyond float
    range. Iterative: a document can nest deeper than Python's recursion limit."""
    stack: list[tuple[tuple[Any, ...], Any]] = [((), doc)]
    while stack:
        path, value = stack.pop()
        if isinstance(value, float) and not math.isfinite(value):
            return "/".join(map(str, path)), f"{value} (NaN and infinity are not JSON numbers)"
        if isinstance(value, int) and not isinstance(value, bool) and abs(value) > _FLOAT_MAX:
            return "/".join(map(str, path)), "integer beyond float range"
        if isinstance(value, dict):
            stack.extend(((*path, k), v) for k, v in value.items())
        elif isinstance(value, list):
            stack.extend(((*path, i), v) for i, v in enumerate(value))
    return None


def _only_numbers(value: Any) -> bool:
    """A number or (nested) lists of numbers; booleans and strings are not numbers."""
    if isinstance(value, list):
        return all(_only_numbers(v) for v in value)
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _edge_from_dict(e: dict[str, Any]) -> Edge:
    # dmp.from_dict converts with np.asarray(..., float), which takes "inf" and "1e999"
    # (strings) for numbers: what it converts must be numbers already.
    dmp = e["action"]["dmp"]
    for key in ("weights", "start", "goal", "duration"):
        if key in dmp and not _only_numbers(dmp[key]):
            raise TreeError(f"action/dmp/{key}: expected numbers")
    params = dmp.get("params")
    if isinstance(params, dict) and not all(_only_numbers(v) for v in params.values()):
        raise TreeError("action/dmp/params: expected numbers")
    return Edge(
        id=e["id"],
        parent=e["parent"],
        child=e["child"],
        smc=smc_from_dict(e["perception"], e["action"]),
        support=int(e["support"]),
        sources=tuple(
            Source(log=s["log"], sha256=s["sha256"], t0=float(s["t0"]), t1=float(s["t1"]))
            for s in e["sources"]
        ),
    )


def tree_from_dict(doc: Any, where: str = "tree") -> Tree:
    """Validate and decode a tree document; TreeError names ``where`` and the problem."""
    from jsonschema.exceptions import best_match

    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise TreeError(f'{where}: not an smc tree (expected "format": "{FORMAT}")')
    if doc.get("schema_version") != SCHEMA_VERSION:
        raise TreeError(
            f"{where}: schema_version {doc.get('schema_version')!r} not supported "
            f"(this smc reads {SCHEMA_VERSION})"
        )
    bad = _bad_number(doc)
    if bad is not None:
        raise TreeError(f"{where}: invalid at {bad[0] or '(top)'}: {bad[1]}")
    try:
        err = best_match(_validator().iter_errors(doc))
    except RecursionError:
        raise TreeError(f"{where}: nested too deeply to be an smc tree") from None
    if err is not None:
        path = "/".join(str(p) for p in err.absolute_path) or "(top)"
        raise TreeError(f"{where}: invalid at {path}: {' '.join(err.message.split())[:200]}")
    # The schema fixes the outline; what is inside params, clusters and DMPs is checked by
    # their decoders, which raise TreeError / SmcError with the problem but not the file.
    try:
        params = params_from_dict(SmcParams, doc["params"])
    except SmcError as exc:  # unknown parameter
        raise TreeError(f"{where}: invalid at params: {exc}") from None
    except (TypeError, ValueError, AttributeError) as exc:  # a group that is not a mapping
        raise TreeError(f"{where}: invalid at params ({exc})") from None
    edges = []
    for i, e in enumerate(doc["edges"]):
        try:
            edges.append(_edge_from_dict(e))
        except TreeError as exc:
            raise TreeError(f"{where}: invalid at edges/{i}: {exc}") from None
        except (KeyError, TypeError, ValueError) as exc:
            raise TreeError(f"{where}: invalid at edges/{i} ({exc!r})") from None
    tree = Tree(
        params=params,
        nodes=tuple(n["id"] for n in doc["nodes"]),
        edges=tuple(edges),
        version=int(doc["version"]),
        history=tuple(doc["history"]),
        scene=dict(doc.get("scene", {})),
        robot=dict(doc.get("robot", {})),
    )
    try:
        actual = digest(tree)
    except ValueError:  # json.dumps(allow_nan=False): a value decoded to NaN or infinity
        raise TreeError(
            f"{where}: a value decodes to NaN or infinity (a string in a list of numbers?)"
        ) from None
    if actual != doc["digest"]:
        raise TreeError(f"{where}: digest mismatch (file edited or corrupt)")
    node_ids = set(tree.nodes)
    for e in edges:
        if e.parent not in node_ids or e.child not in node_ids:
            raise TreeError(f"{where}: edge {e.id} refers to a node that does not exist")
    return tree


def load_tree(path: Path) -> Tree:
    """Read and validate ``tree.json``."""
    path = Path(path)
    if not path.is_file():
        raise TreeError(f"{path}: no such tree file")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise TreeError(
            f"{path}: not valid JSON ({exc.__class__.__name__}: {str(exc).splitlines()[0]})"
        ) from None
    except RecursionError:
        raise TreeError(f"{path}: not valid JSON (nested too deeply)") from None
    except OSError as exc:
        raise TreeError(f"{path}: cannot read ({exc.strerror or exc})") from None
    return tree_from_dict(doc, str(path))


def save_tree(tree: Tree, path: Path) -> None:
    """Replace ``path`` atomically: write ``path.part``, fsync, rename."""
    path = Path(path)
    text = json.dumps(tree_to_dict(tree), indent=1, allow_nan=False) + "\n"
    part = path.with_name(path.name + ".part")
    with open(part, "w", encoding="utf-8") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    os.replace(part, path)
