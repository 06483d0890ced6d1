"""Build parameters of a tree: thresholds, saliency radii, DMP and perception settings.

A tree records the parameters it was built with; compiling more logs into it with other
parameters is refused unless the tree is rebuilt. ``--set KEY=VALUE`` overrides one value
by its dotted path (``t_hp=0.12``, ``dmp.n_basis=50``, ``idle.trim=false``).

A setting added after trees were written either has a default that means the old
behaviour (``omit_default``: left out of the file at that default, so old trees keep their
digest), or, when the new default changes what compile does, a ``legacy`` value: what a
tree that lacks the key was built with. It is left out of the file at that value and
filled in when the key is missing (``idle``: trees from before idle trimming load with
``trim=False`` and keep their digest; new trees write their ``idle`` settings).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from smccli.errors import SmcError
from smccli.learn.dmp import DmpParams
from smccli.learn.trim import IdleParams
from smccli.perception import PerceptionParams
from smccli.perception.saliency import DEFAULT_EPSILON
from smccli.perception.scan import ScanParams


@dataclass(frozen=True, slots=True)
class SmcParams:
    """Everything that shapes a tree, with the paper's defaults where it has them."""

    t_ha: float = 0.02
    """Action contingency threshold T_hA (eq. 31) [m]: D_A below it means the same action."""
    t_hp: float = 0.1
    """Perception contingency threshold T_hP (eq. 31, 36): D_P below it means the same context."""
    epsilon: float = DEFAULT_EPSILON
    """Saliency radius of object clusters (eq. 21) [m]: horizontal distance to the POI."""
    scan_epsilon: float = 8.0
    """Saliency radius of a lidar scan (eq. 18) [m]: the scan is salient when the fragment's
    goal lies this close to where it was taken, i.e. within the lidar's range (8 m), where
    the scan can place it."""
    weight_window: float = 0.15
    """The scale is read as the median over this window ending at the decision point [s]."""
    weight_scale: float = 0.05
    """Weight difference that counts as clearly different (normalises d_P of the scale) [kg]."""
    yaw_scale: float = 0.05
    """Metres of goal distance per radian of goal yaw difference in D_A [m/rad]."""
    approach_length: float = 0.1
    """How much of a path's end D_A compares: the last this-many metres before the goal [m]."""
    approach_samples: int = 20
    """Points the approach is sampled at, evenly along the path."""
    snap_window: float = 0.5
    """Operator marks snap to a gripper or weight edge this close [s]."""
    min_fragment: float = 0.3
    """Fragments shorter than this are dropped (e.g. the tail after the last mark) [s]."""
    auto_gap: float = 4.0
    """With ``--segment both``, automatic cuts only fill unmarked stretches longer than this [s]."""
    idle: IdleParams = field(
        default_factory=IdleParams, metadata={"legacy": IdleParams(trim=False, squeeze=False)}
    )
    """Trimming of fragments' idle heads and tails (:mod:`smccli.learn.trim`); a tree
    without this key was compiled untrimmed."""
    dmp: DmpParams = field(default_factory=DmpParams)
    """Movement primitive settings (eq. 27-28)."""
    perception: PerceptionParams = field(default_factory=PerceptionParams)
    """Point cloud, clustering and histogram settings (section 3.3)."""
    scan: ScanParams = field(default_factory=ScanParams)
    """Scan alignment and distance settings (4.2)."""


def params_to_dict(params: Any, *, full: bool = False) -> dict[str, Any]:
    """Nested plain-JSON dict of a params dataclass (tuples become lists). Settings added
    later are left out at their default (trees written before keep their digest) unless
    ``full``."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(params):
        v = getattr(params, f.name)
        if f.metadata.get("omit_default") and v == f.default and not full:
            continue
        if "legacy" in f.metadata and v == f.metadata["legacy"] and not full:
            continue
        if dataclasses.is_dataclass(v):
            out[f.name] = params_to_dict(v, full=full)
        elif isinstance(v, tuple):
            out[f.name] = [list(x) if isinstance(x, tuple) else x for x in v]
        else:
            out[f.name] = v
    return out


def params_from_dict(cls: type, data: dict[str, Any]) -> Any:
    """Inverse of :func:`params_to_dict`; unknown keys are an error naming them, a missing
    key with a ``legacy`` value takes that value, any other missing key its default."""
    names = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - set(names))
    if unknown:
        raise SmcError(f"unknown parameter(s) {', '.join(unknown)}; valid: {', '.join(names)}")
    kwargs: dict[str, Any] = {
        name: f.metadata["legacy"]
        for name, f in names.items()
        if name not in data and "legacy" in f.metadata
    }
    defaults = cls()
    for name, value in data.items():
        current = getattr(defaults, name)
        if dataclasses.is_dataclass(current):
            kwargs[name] = params_from_dict(type(current), value)
        elif isinstance(current, tuple):
            kwargs[name] = tuple(tuple(x) if isinstance(x, list) else x for x in value)
        else:
            kwargs[name] = type(current)(value) if current is not None else value
    return cls(**kwargs)


def with_overrides(params: SmcParams, assignments: list[str]) -> SmcParams:
    """Apply ``KEY=VALUE`` overrides (dotted keys into nested settings)."""
    data = params_to_dict(params, full=True)
    for item in assignments:
        key, sep, raw = item.partition("=")
        if not sep or not key:
            raise SmcError(f"--set {item!r}: expected KEY=VALUE, e.g. t_hp=0.12 or dmp.n_basis=50")
        node = data
        parts = key.strip().split(".")
        for part in parts[:-1]:
            if not isinstance(node.get(part), dict):
                raise SmcError(f"--set {item!r}: {part!r} is not a group of parameters")
            node = node[part]
        leaf = parts[-1]
        if leaf not in node:
            raise SmcError(f"--set {item!r}: unknown parameter {leaf!r}; valid: {', '.join(node)}")
        old = node[leaf]
        try:
            if isinstance(old, bool):
                value: Any = raw.strip().lower() in ("1", "true", "yes", "on")
            elif isinstance(old, int):
                value = int(raw)
            elif isinstance(old, float):
                value = float(raw)
            elif isinstance(old, list):
                value = [float(x) for x in raw.strip("[]() ").split(",")]
            else:
                value = raw
        except ValueError:
            raise SmcError(f"--set {item!r}: {raw!r} is not a valid {type(old).__name__}") from None
        node[leaf] = value
    return params_from_dict(SmcParams, data)
