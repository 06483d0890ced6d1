"""A task's success as data: conditions (an object on top of / inside another, the base at a
place) combined in nestable ``all_of`` / ``any_of`` / ``none_of`` groups.

Whether they hold is evaluation's to say (:meth:`smccli.world.truth.Truth.success`).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

RELATIONS = ("on_top_of", "inside")
"""How an object may rest on its target."""
GROUPS = ("all_of", "any_of", "none_of")
"""How a group combines its items: every one holds, at least one, none."""


@dataclass(frozen=True, slots=True)
class Condition:
    """``object`` rests ``relation`` (on top of / inside) ``target``; or, with relation
    ``at``, the mobile base (object :data:`ROBOT_KEY`) stands at the place ``target``
    within ``tolerance``."""

    object: str
    """Name of the object that was moved (:data:`ROBOT_KEY` for ``at``)."""
    relation: str
    """One of :data:`RELATIONS`, or ``at``."""
    target: str
    """Name of the object it must rest on or in, or of the place (``at``)."""
    tolerance: tuple[float, float] = (0.1, math.radians(10))
    """``at``: largest position [m] and heading [rad] error."""


@dataclass(frozen=True, slots=True)
class Group:
    """Conditions combined (nestable): ``all_of`` every item holds, ``any_of`` at least
    one, ``none_of`` none."""

    kind: str
    """One of :data:`GROUPS`."""
    items: tuple[Condition | Group, ...]

    def conditions(self, negated: bool = False) -> Iterator[Condition]:
        """The conditions the task makes hold (``negated``: those it must not)."""
        for item in self.items:
            inner = negated != (self.kind == "none_of")
            if isinstance(item, Group):
                yield from item.conditions(inner)
            elif not inner:
                yield item


@dataclass(frozen=True, slots=True)
class SuccessCriterion:
    """A task's success: every key of its criterion holds, ``all_of`` (every item),
    ``any_of`` (at least one) and ``none_of`` (none), items nestable."""

    task: str
    """Task name, e.g. ``cube_on_green``."""
    rule: Group
    """The criterion: ``all_of`` its keys' groups."""
    variant: str | None = None
    """The criterion only counts in layouts of this variant (the arrow the robot was
    shown); None: in every layout."""

    def conditions(self) -> tuple[Condition, ...]:
        """The conditions the task makes hold (not those of a ``none_of``), in file order."""
        return tuple(self.rule.conditions())
