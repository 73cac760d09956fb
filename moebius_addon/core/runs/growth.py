"""Length growth (``length_target=``, ``length_growth=``): a curve whose total length grows
during the run to a target, a little every iteration (curve packing; Repulsive Curves' length
constraint with a growth scale).

A feasible run holds every edge at a target length (:mod:`..constraints`). Growth scales those
targets up by a factor ``1 + length_growth`` per iteration, capped so that the target length is
met exactly and then held; the back-projection of the step reaches the new lengths. The
schedule here only does the bookkeeping: which edges grow (every real edge that is not between
two pins: those have no row and cannot change), the length each component has grown to, and the
new constraints of a proposed growth. The step itself, with its contact test of the straight
path to the grown polygon, is :meth:`.projected.Relaxation._grow`.

Lengths here are in the run's units (the start scaled to total length 1, :mod:`.base`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from ..geometry.constraints import Constraints
from .checks import check_number

#: The largest ``length_growth``: each iteration at most doubles the edges (a loop of 60 edges
#: grew to three times its length at rates 1, 2 and 30; at 300 it never grew, "no room to grow
#: without contact").
MAX_LENGTH_GROWTH = 1.0
#: ``length_growth`` when only ``length_target`` is given: 1 % more length per iteration.
DEFAULT_LENGTH_GROWTH = 0.01
#: A target below the start's length by less than this fraction counts as the start's length
#: (a run that goes on from a grown polygon, e.g. after a split, measures it in the last bits).
_SAME_LENGTH = 1e-9


def _as_targets(length_target, k: int) -> np.ndarray | float:
    """``length_target`` checked: one positive number, or one per component (``k``)."""
    if isinstance(length_target, (Sequence, np.ndarray)) and not isinstance(
            length_target, (str, bytes)):
        if len(length_target) != k:
            raise ValueError(f"length_target must be one number, or one per component ({k}), "
                             f"got {len(length_target)} numbers")
        return np.array([check_number(f"length_target[{c}]", t, 0, above=True)
                         for c, t in enumerate(length_target)])
    return check_number("length_target", length_target, 0, above=True)


def _refuse_stuck(goal: np.ndarray, free: np.ndarray) -> None:
    """ValueError for a component asked to grow (``goal`` above ``free``) with no edge that
    can (``free`` 0: every edge between two pins)."""
    stuck = np.flatnonzero((goal > free) & (free == 0.0))
    if stuck.size:
        raise ValueError(f"component {int(stuck[0])} cannot grow: every edge of it lies "
                         "between two pinned vertices; unpin some")


class LengthGrowth:
    """The growth schedule of one run.

    Parameters
    ----------
    length_target : float or sequence of float
        Total length to reach in the caller's units: of the whole curve (every component grows
        by the same factor), or one per component.
    length_growth : float
        Relative growth per iteration (0.01: 1 %), > 0.
    lengths0 : (N,) array
        The run's target edge lengths at the start (run units).
    layout, pinned
        The run's components and its pinned vertices (stacked indices or None).
    scale : float
        Caller's units per run unit.

    Raises
    ------
    ValueError
        For a rate or target that is not a positive finite number, a target below the start's
        length, or a component to grow that has no edge that can change length.
    """

    def __init__(self, length_target, length_growth, lengths0: np.ndarray, layout, pinned,
                 scale: float):
        self.rate = check_number("length_growth", length_growth, 0, above=True)
        if self.rate > MAX_LENGTH_GROWTH:
            raise ValueError(f"length_growth must be at most {MAX_LENGTH_GROWTH:g} (every edge "
                             f"{1 + MAX_LENGTH_GROWTH:g} times as long per iteration), got "
                             f"{length_growth!r}: a larger step leaves no room to grow without "
                             "contact, and the curve never grows")
        targets = _as_targets(length_target, layout.k)
        grows = np.ones(layout.n, bool) if not layout.has_open else layout.real.copy()
        if pinned is not None:
            pin = np.zeros(layout.n, bool)
            pin[pinned] = True
            grows &= ~(pin & pin[layout.nxt])  # no row: its length cannot change
        real = np.ones(layout.n, bool) if not layout.has_open else layout.real
        self.layout = layout
        #: edges whose target length grows
        self.grows = grows
        comp = layout.comp
        #: per component: the length of the edges that grow, and of those that do not
        self.free = np.bincount(comp[grows], lengths0[grows], layout.k)
        self.fixed = np.bincount(comp[real & ~grows], lengths0[real & ~grows], layout.k)
        start = (self.free + self.fixed) * scale  # caller's units
        self.start_length = float(start.sum())
        if np.ndim(targets) == 0:
            if targets < self.start_length * (1 - _SAME_LENGTH):
                raise ValueError(
                    f"length_target {targets:.6g} is below the curve's length at the start, "
                    f"{self.start_length:.6g}: growth only lengthens a curve; give a target of "
                    f"at least that (or no length_target to keep the length)")
            goal = start * max(1.0, targets / self.start_length)
        else:
            low = np.flatnonzero(targets < start * (1 - _SAME_LENGTH))
            if low.size:
                c = int(low[0])
                raise ValueError(
                    f"length_target[{c}] = {targets[c]:.6g} is below the length of component "
                    f"{c} at the start, {start[c]:.6g}: growth only lengthens a curve; give "
                    f"a target of at least that")
            goal = np.maximum(start, targets)
        #: per component: the length the growing edges reach at the target (run units)
        self.goal = np.maximum(goal / scale - self.fixed, self.free)
        _refuse_stuck(self.goal, self.free)
        self.scale = float(scale)
        #: per component: the length of the growing edges at the start (the least goal)
        self.free0 = self.free.copy()
        #: mean length of a growing edge at the start (run units): the split rule's yardstick
        self.start_edge = float(lengths0[grows].mean()) if grows.any() else 1.0

    def retarget(self, factor: float) -> None:
        """A new goal: every component's length ``factor`` (≥ 1) times its length at the
        start; below the length reached the growing edges shrink back towards it at the same
        rate (Live's *Grow* slider, which may be dragged both ways)."""
        factor = check_number("factor", factor, 1.0)
        goal = (self.free0 + self.fixed) * factor - self.fixed
        _refuse_stuck(goal, self.free0)
        self.goal = goal

    @property
    def reached(self) -> bool:
        """Whether every component has reached its target (it is held from then on)."""
        return bool(np.all(self.free == self.goal))

    def propose(self, rate: float) -> np.ndarray:
        """The free length of each component after one growth at ``rate`` (capped at its
        goal; components that reached it stay), or one shrink by ``1 + rate`` towards a goal
        below it (:meth:`retarget`)."""
        return np.where(self.free <= self.goal, np.minimum(self.free * (1.0 + rate), self.goal),
                        np.maximum(self.free / (1.0 + rate), self.goal))

    def constraints(self, con: Constraints, free: np.ndarray) -> Constraints:
        """``con`` with the growing edges' targets scaled to the free lengths ``free``, and
        the barycenter targets scaled alike (Σ l m of a curve scaled about its weighted
        barycenter scales as the lengths: the barycenter stays where it is)."""
        f = free / self.free
        lengths0 = con.lengths0.copy()
        lengths0[self.grows] *= f[self.layout.comp[self.grows]]
        return dataclasses.replace(con, lengths0=lengths0,
                                   barycenter0=con.barycenter0 * f[:, None])

    def commit(self, free: np.ndarray) -> None:
        """The growth to ``free`` (of :meth:`propose`: exactly the goal where it was capped)
        was made."""
        self.free = free.copy()

    def edge_ratio(self, lengths0: np.ndarray) -> float:
        """Longest growing target edge over the start's mean growing edge."""
        return float(lengths0[self.grows].max()) / self.start_edge if self.grows.any() else 1.0

    def words(self) -> str:
        """Where the growth stands, in the caller's units."""
        now = float((self.free + self.fixed).sum()) * self.scale
        goal = float((self.goal + self.fixed).sum()) * self.scale
        return f"length {now:.6g} of the target {goal:.6g}"
