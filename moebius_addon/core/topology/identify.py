"""Which knot or link of the table a closed curve is: invariants of one generic projection,
matched against the shipped table (:mod:`.table`).

The invariants: the number of components, the Alexander polynomial (polynomial time,
:func:`.invariants.alexander_polynomial`), the Jones polynomial (Kauffman's bracket summed
tangle by tangle, :mod:`.jones`; it tells most knots from their mirror images), the signature
(Gordon–Litherland, :mod:`.goeritz`; it tells some chiral knots from their mirror images that
the Jones polynomial cannot, 9_42 and 10_125 among them) and, for links, the linking numbers
(compared up to the order of the components). They are computed on the
projection whose diagram has the fewest crossings after Reidemeister I and II simplification
(:func:`.invariants.planar_diagram`); that crossing count bounds the crossing number from
above, so table entries with more crossings are ruled out. When the entries left differ in
crossing number, further dozens of directions (up to :data:`MORE_DIAGRAMS`) look for a diagram
with fewer crossings that rules out more of them (a relaxed 10_95 at 700 edges: 12 crossings in
the first dozen, 10 in another, which parts it from 12n_595).

Equal invariants do not prove equal knots: mutants (the Conway and Kinoshita–Terasaka knots,
11n_34 and 11n_42) share all of them. Of the 5 877 knots up to 12 crossings with their mirror
images (an amphicheiral knot counted once), 1 260 share their Alexander and Jones polynomials
with another and 1 180 share the signature too; the chiral knots these tell from their mirror
images rise from all but 37 to all but 23 (the HOMFLY-PT polynomial would part none of the
1 180 further: docs/lab/knot-table.md, "Identification"). :func:`identify` then names them all,
and a curve whose invariants match no entry is not in the table (a composite knot, a split
link, or more crossings than the table holds) or was too tangled for the Jones polynomial.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field
from enum import IntEnum
from functools import cache

import numpy as np

from ..geometry.polygon import check_polygon
from . import goeritz, table
from . import jones as _jones
from .invariants import alexander_polynomial, linking_numbers, planar_diagram

__all__ = ["Identification", "Match", "fingerprint", "identify"]


class Match(IntEnum):
    """How the invariants of a curve matched the table (``Identification.status``)."""

    UNIQUE = 0  #: one entry has the curve's invariants
    SEVERAL = 1  #: several entries share them (mutants, or a knot and its mirror image)
    NONE = 2  #: no entry has them


@dataclass(frozen=True)
class Fingerprint:
    """Invariants of a knot or link that identification compares.

    ``jones`` is ``{exponent of t^(1/2): coefficient}`` as a sorted tuple of pairs, or None
    when it was not computed; ``linking`` the sorted pairwise linking numbers; ``signature``
    KnotInfo's convention (3_1: −2)."""

    components: int
    alexander: tuple[int, ...]
    jones: tuple[tuple[int, int], ...] | None
    linking: tuple[int, ...]
    signature: int

    def key(self, with_jones: bool = True) -> tuple:
        return (self.components, self.alexander, self.jones if with_jones else None,
                self.linking, self.signature)


@dataclass(frozen=True)
class Identification:
    """What :func:`identify` found.

    Attributes
    ----------
    names : tuple of str
        Table names whose invariants the curve has (``m`` + name: the mirror image), fewest
        crossings first; empty if none.
    status : Match
        ``UNIQUE``, ``SEVERAL`` or ``NONE``.
    message : str
        One sentence for a user: "3_1 (trefoil)", "one of 11n_34, 11n_42 (the same …)", …
    fingerprint : Fingerprint
        The invariants computed (compare two curves' with ``==``).
    crossings : int
        The fewest crossings of a simplified diagram found (an upper bound of the crossing
        number): the diagram the invariants were read off, or one of another dozen
        directions.
    excluded : tuple of str
        Entries with the same invariants but more crossings than that.
    seconds : float
    """

    names: tuple[str, ...]
    status: Match
    message: str
    fingerprint: Fingerprint
    crossings: int
    excluded: tuple[str, ...] = ()
    seconds: float = 0.0
    linking_matrix: list = field(default_factory=list, compare=False)

    @property
    def name(self) -> str | None:
        """The one matching name, or None (several, or none)."""
        return self.names[0] if self.status == Match.UNIQUE else None

    @property
    def link(self) -> str | None:
        """The link without orientation when every match is an orientation of it (the four
        orientations of the Borromean rings share every invariant: ``"L6a4"``), or the knot
        when the match is unique; else None."""
        bases = {_unoriented(n) for n in self.names}
        return bases.pop() if len(bases) == 1 else None

    @property
    def jones(self) -> tuple[float, list[int]] | None:
        """The Jones polynomial as ``(lowest power of t, coefficients)``, or None."""
        if self.fingerprint.jones is None:
            return None
        return _laurent(dict(self.fingerprint.jones))

    @property
    def alexander(self) -> list[int]:
        return list(self.fingerprint.alexander)


def _laurent(poly: dict[int, int]) -> tuple[float, list[int]]:
    from .invariants import laurent

    return laurent(poly)


def _entry_fingerprint(e: table.Entry) -> Fingerprint:
    lo, coeffs = e.jones
    poly = tuple((lo + 2 * k, c) for k, c in enumerate(coeffs) if c)
    return Fingerprint(e.components, tuple(e.alexander), poly, tuple(sorted(e.linking)),
                       e.signature)


@cache
def _index() -> tuple[dict, dict]:
    """Table fingerprints: ``{key with Jones: [entries]}`` and ``{key without: [entries]}``,
    mirror images included where they differ from every orientation of the same link."""
    full: dict[tuple, list] = {}
    for e in table.entries():
        fp = _entry_fingerprint(e)
        full.setdefault(fp.key(), []).append(e)
    for e in table.entries():
        if e.amphicheiral:  # KnotInfo: the same knot
            continue
        m = e.mirror()
        key = _entry_fingerprint(m).key()
        # an amphicheiral link's mirror image is another orientation LinkInfo lists
        if e.kind == "link" and any(o.unoriented == e.unoriented and o.kind == "link"
                                    for o in full.get(key, [])):
            continue
        full.setdefault(key, []).append(m)
    partial: dict[tuple, list] = {}
    for key, es in full.items():
        partial.setdefault((key[0], key[1], None, *key[3:]), []).extend(es)
    return full, partial


def fingerprint(P, max_states: int = _jones.MAX_STATES) -> tuple[Fingerprint, int, np.ndarray]:
    """Invariants of the knot or link ``P`` (polygon or list of polygons): the
    :class:`Fingerprint`, the crossings of the simplified diagram, the linking matrix. The
    Jones polynomial is left out (None) when its sum needs more than ``max_states`` states."""
    check_polygon(P, coarseness=False)
    d = planar_diagram(P)
    K = len(P) if isinstance(P, list | tuple) else 1
    L = linking_numbers(P) if K > 1 else np.zeros((1, 1), np.int64)
    alexander = tuple(alexander_polynomial(d))  # first: it refuses diagrams too large
    try:
        jp = tuple(sorted(_jones.jones(d, max_states).items()))
    except _jones.TooComplex:
        jp = None
    upper = tuple(sorted(int(L[a, b]) for a in range(K) for b in range(a + 1, K)))
    return Fingerprint(K, alexander, jp, upper, goeritz.signature(d)), d.crossings, L


MORE_DIAGRAMS = 16
"""How many further dozens of projection directions :func:`identify` tries for a diagram with
fewer crossings when the entries its invariants match differ in crossing number (about 3 ms
each for a relaxed 10-crossing knot of 700 edges)."""


def _fewest_crossings(P, crossings: int, target: int) -> int:
    """The fewest crossings of a simplified diagram of ``P`` in the first :data:`MORE_DIAGRAMS`
    further dozens of directions, stopping at ``target`` (no diagram has fewer crossings than
    the knot's crossing number)."""
    for seed in range(1, MORE_DIAGRAMS + 1):
        if crossings <= target:
            break
        crossings = min(crossings, planar_diagram(P, seed).crossings)
    return crossings


def _same_linking(e: table.Entry, L: np.ndarray) -> bool:
    if e.components == 1:
        return True
    W = np.array(e.linking_matrix())
    K = len(W)
    return any((L[np.ix_(p, p)] == W).all() for p in itertools.permutations(range(K)))


def identify(P, max_states: int = _jones.MAX_STATES) -> Identification:
    """The name(s) of the table entry the closed curve ``P`` is, by its invariants.

    Parameters
    ----------
    P : (n, 3) array or list of them
        A knot (one closed polygon) or a link (one per component); it must not touch itself.
    max_states : int
        Budget of the Jones polynomial's sum (:data:`.jones.MAX_STATES`); beyond it the match
        uses the Alexander polynomial and linking numbers alone and the message says so.

    Returns
    -------
    Identification
        ``names`` (fewest crossings first; ``m`` + name for a mirror image), ``status``
        (``Match.UNIQUE``, ``SEVERAL``, ``NONE``), a ``message``, the ``fingerprint``.

    Raises ``ValueError`` for a curve that touches itself, has NaN coordinates or fewer than 4
    vertices per component (``check_polygon``'s messages), or whose every projection keeps more
    than ``invariants.MAX_ALEXANDER_CROSSINGS`` crossings after simplification.
    """
    t0 = time.perf_counter()
    fp, crossings, L = fingerprint(P, max_states)
    full, partial = _index()
    found = full.get(fp.key(), []) if fp.jones is not None else partial.get(fp.key(False), [])
    found = [e for e in found if _same_linking(e, L)]
    found.sort(key=lambda e: (e.crossings, e.mirror_of is not None))
    within = [e for e in found if e.crossings <= crossings]
    if len({e.crossings for e in within}) > 1:  # a simpler diagram may rule out some
        crossings = _fewest_crossings(P, crossings, within[0].crossings)
        within = [e for e in found if e.crossings <= crossings]
    excluded = tuple(e.name for e in found if e.crossings > crossings)
    names = tuple(e.name for e in within)
    if not names:
        status = Match.NONE
    else:
        status = Match.UNIQUE if len(names) == 1 else Match.SEVERAL
    message = _message(status, within, fp, crossings)
    return Identification(names, status, message, fp, crossings, excluded,
                          time.perf_counter() - t0, L.tolist())


def _unoriented(name: str) -> str:
    return name.split("{")[0]


def _label(e: table.Entry) -> str:
    return f"{e.name} ({e.common[0]})" if e.common else e.name


def _labels(entries: list) -> str:
    """Names, the orientations of one link gathered: "L6a4 (Borromean rings) oriented {0,0},
    {1,0}, {0,1} or {1,1}"."""
    groups: dict[str, list] = {}
    for e in entries:
        groups.setdefault(_unoriented(e.name), []).append(e)
    parts = []
    for base, es in groups.items():
        if len(es) == 1:
            parts.append(_label(es[0]))
            continue
        orient = [e.name[len(base):] for e in es]
        common = f" ({es[0].common[0]})" if es[0].common else ""
        parts.append(f"{base}{common} oriented {', '.join(orient[:-1])} or {orient[-1]}")
    return ", ".join(parts)


def _message(status: Match, within: list, fp: Fingerprint, crossings: int) -> str:
    what = "link" if fp.components > 1 else "knot"
    no_jones = ("" if fp.jones is not None else
                f" (the Jones polynomial was not computed: the simplest diagram found has "
                f"{crossings} crossings; relax the curve for a sharper answer)")
    if status == Match.UNIQUE:
        return _label(within[0]) + no_jones
    if status == Match.SEVERAL:
        if len({_unoriented(e.name) for e in within}) == 1:
            return _labels(within) + ": the orientations share every invariant computed" + (
                no_jones)
        return ("one of " + _labels(within) + ": they share every invariant computed" +
                no_jones)
    table_size = ("prime knots up to 12 crossings" if what == "knot" else
                  "prime links up to 11 crossings")
    return (f"no {what} of the table ({table_size}) has these invariants: a composite "
            f"{what}, a split link, or more crossings than the table holds" + no_jones)
