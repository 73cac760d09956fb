"""Catalogue of closed curves to relax: circles, torus knots, every prime knot up to 8 crossings
(as closed braids), and unknots that are hard to untangle.

Conventions shared by every generator:

* The result is a closed polygon, an ``(n, 3)`` float64 array of ``n`` vertices with equal edges
  (a dense sample of the curve passed through :func:`..geometry.polygon.resample`). A
  curve with several components (a link: a braid whose closure has several components, a torus
  link) is a list of such arrays; the ``n`` vertices are split between the components in
  proportion to their lengths, so all edges have nearly the same length.
* Centred and scaled to the unit ball: the mean of all vertices is the origin and the farthest
  vertex lies at distance 1 (a circle has radius 1). For an equilateral polygon the vertex mean
  is also the length-weighted barycentre that the relaxation keeps fixed.
* Every generator has a default ``n`` that passes the coarseness rule of docs/design.md (checked by
  :func:`moebius_addon.core.check_polygon`: vertices at least 4 apart along the curve are more
  than one mean edge length apart in space) with a wide margin: the ``contact_ratio`` at the
  default is 2.5 to 4 (1.2 for the FHW unknot, whose strands nearly touch). The last column
  is the smallest ``n`` that still passes (ratio >= 1), measured; the relaxation is more robust
  some way above it.

======================  ================================  ===================================
generator               default ``n``                     smallest ``n`` passing
======================  ================================  ===================================
``circle``              64                                4 (no vertex pairs 4 apart below 8)
``torus_knot(p, q)``    ``40 (|p| + |q|)``                about ``5 (|p| + |q|)``: 18 for
                                                          T(2,3), 35 for T(3,4), 33 T(2,5)
``figure_eight``        200                               36
``braid_closure``       3.3 vertices per strand spacing   0.3 × the default: 3_1 27 (of 100),
``named``               of length, at least 100           4_1 52 (180), 7_2 136 (460), 8_1
                                                          and 8_3 197 (660)
``freedman_unknot``     600                               470 (ratio 1.2 at 600)
``helix_unknot``        300                               62 (6 turns)
``random_unknot``       400                               about 50-100 (draws are kept only
                                                          with ratio >= 2 at 400)
======================  ================================  ===================================
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import cache
from pathlib import Path

import numba as nb
import numpy as np

from ..geometry.objio import read_obj
from ..geometry.polygon import (
    CONTACT_RATIO,
    MIN_CHECKED_VERTICES,
    contact_ratio,
    resample,
    suggest_edge_count,
)
from ..runs.memory import check_memory
from . import from_diagram as drawing
from . import notation, pd, table

__all__ = [
    "braid_closure",
    "circle",
    "figure_eight",
    "freedman_unknot",
    "from_braid",
    "from_notation",
    "from_pd",
    "helix_unknot",
    "info",
    "named",
    "names",
    "search",
    "random_unknot",
    "torus_knot",
]

_DATA = Path(__file__).resolve().parents[1] / "data"

Curve = np.ndarray | list[np.ndarray]


# --------------------------------------------------------------------------------------------
# Simple closed curves


def circle(n: int = 64) -> np.ndarray:
    """The regular ``n``-gon inscribed in the unit circle of the xy-plane."""
    n = _check_n(n, 1)
    t = 2.0 * np.pi * np.arange(n) / n
    return np.stack([np.cos(t), np.sin(t), np.zeros(n)], axis=1)


def torus_knot(p: int, q: int, n: int | None = None, R: float = 2.0, r: float = 1.0) -> Curve:
    """The torus knot ``T(p, q)``: ``p`` turns around the z-axis, ``q`` around the tube.

    ``((R + r cos qt) cos pt, (R + r cos qt) sin pt, -r sin qt)`` for positive ``p``, ``q``
    (a positive knot: ``T(2, 3)`` is the positive trefoil 3_1 of :func:`named`, ``T(3, 4)`` is
    8_19); a negative ``p`` or ``q`` gives the mirror image. When ``d = gcd(p, q) > 1`` the
    result is the torus link of ``d`` parallel components, a list of arrays. ``R`` and ``r``
    (tube radius) set the proportions only; the curve is then scaled into the unit ball.

    Default ``n``: ``40 (|p| + |q|)``; with ``R/r = 2`` the coarseness rule holds down to about
    ``5 (|p| + |q|)``.
    """
    p, q = _whole("p", p), _whole("q", q)
    if p == 0 or q == 0:
        raise ValueError(f"torus_knot({p}, {q}): p and q must be nonzero integers")
    if not 0 < r < R:
        raise ValueError(f"torus_knot needs 0 < r < R (got R={R}, r={r})")
    d = math.gcd(p, q)
    n = _check_n(40 * (abs(p) + abs(q)) if n is None else n, d)
    _check_dense(_dense_count(n // d) * d, f"torus_knot({p}, {q})")
    m = _dense_count(n // d)
    t = 2.0 * np.pi * np.arange(m) / m
    curves = []
    for k in range(d):
        # Component k is component 0 turned around the tube by 2πk/|p|: evenly between the
        # passes of component 0 through the half-plane φ = 0.
        phi = (p // d) * t
        psi = (q // d) * t + 2.0 * np.pi * k / abs(p)
        rho = R + r * np.cos(psi)
        # -sin: with +sin the knot would be the negative one (the mirror of the braid σ1³).
        curves.append(np.stack([rho * np.cos(phi), rho * np.sin(phi), -r * np.sin(psi)], axis=1))
    sign = 1 if p * q > 0 else -1  # T(p, q): the closure of (σ1 … σ_{|p|-1})^|q|, mirrored
    return _finish(curves, n, diagram=lambda: pd.from_braid(
        [sign * k for k in range(1, abs(p))] * abs(q), abs(p)))


def figure_eight(n: int = 200) -> np.ndarray:
    """The figure-eight knot 4_1, ``((2 + cos 2t) cos 3t, (2 + cos 2t) sin 3t, sin 4t)``."""
    n = _check_n(n, 1)
    m = _dense_count(n)
    _check_dense(m, "figure_eight")
    t = 2.0 * np.pi * np.arange(m) / m
    rho = 2.0 + np.cos(2.0 * t)
    return _finish([np.stack([rho * np.cos(3 * t), rho * np.sin(3 * t), np.sin(4 * t)], axis=1)],
                   n, diagram=lambda: pd.from_braid(table.entry("4_1").braid))


# --------------------------------------------------------------------------------------------
# Closed braids and the knot table

# Layout of a closed braid (units of the strand spacing): strand k runs around the z-axis at
# radius r0 + k, the word's generators take equal angular slots, and a crossing lifts the over
# strand to +_HZ and the under strand to -_HZ while they swap radii.
_HZ = 0.6
_SLOT = 2.5  # arc length of a slot at the innermost radius (sets r0)
_PER_SLOT = 48  # dense samples per slot and strand
# Peak memory per dense sample of a generator's curve and per vertex of its result (the dense
# arrays, their resampling, the result), with room: measured 144 bytes per sample
# (torus_knot(2, 3, 100 000): 16 samples per vertex) and 234 bytes per vertex (named("3_1",
# 300 000)).
_BYTES_PER_SAMPLE = 200
_BYTES_PER_VERTEX = 400


def braid_closure(word: Sequence[int], n: int | None = None, strands: int | None = None) -> Curve:
    """The closure of a braid, laid around the z-axis as a smooth embedded space curve.

    Parameters
    ----------
    word : sequence of nonzero int
        Generators ``σ_i`` as ``i`` and ``σ_i⁻¹`` as ``-i`` (1-based, KnotInfo's convention:
        ``σ_i`` is a positive crossing, so ``[1, 1, 1]`` is the positive trefoil and the
        closure of ``[1, 1]`` has linking number +1).
    n : int, optional
        Total number of vertices; default 3.3 per strand spacing of length (at least 100), which
        starts neighbouring strands 3.3 edges apart; down to 0.3 times that count they are
        still one edge apart (the coarseness check passes).
    strands : int, optional
        Number of strands, at least ``max|i| + 1`` (the default).

    Returns
    -------
    (n, 3) array for a knot, or a list of arrays (one per component, in the order of their
    lowest starting strand) when the closure is a link.

    Strand ``k`` runs counter-clockwise (seen from +z) around the z-axis at radius ``R0 + k``
    (in strand spacings); each generator gets an equal angular slot in which its two strands
    swap radii along a smooth step while the over strand rises and the under strand sinks, so
    that at every crossing they pass 1.2 spacings apart vertically.
    """
    word, strands = pd.braid_word(word, strands)
    _check_dense(strands * max(len(word), 3) * _PER_SLOT,
                 f"the closure of a braid on {strands} strands")
    curves = _braid_curves(word, strands)
    if n is None:
        n = _braid_default_n(curves)
    n = _check_n(n, len(curves))
    return _finish(curves, n, diagram=lambda: pd.from_braid(word, strands))


def braid_edges(word: Sequence[int], strands: int | None = None) -> int:
    """The edge count :func:`braid_closure` takes for ``n=None`` (3.3 edges per strand
    spacing of length, at least 100), found without resampling: a caller that bounds the
    size (Blender's *Add from Notation*) asks before any work."""
    word, strands = pd.braid_word(word, strands)
    _check_dense(strands * max(len(word), 3) * _PER_SLOT,
                 f"the closure of a braid on {strands} strands")
    return _braid_default_n(_braid_curves(word, strands))


def _braid_curves(word: list[int], strands: int) -> list[np.ndarray]:
    """Dense samples of each component of the closed braid, before scaling."""
    slots = max(len(word), 3)  # fewer slots would make a lonely crossing span a whole turn
    r0 = max(_SLOT * slots / (2.0 * np.pi), 1.5)
    u = (np.arange(_PER_SLOT) + 0.5) / _PER_SLOT  # slot-local parameter, open at both ends
    step = u - np.sin(2.0 * np.pi * u) / (2.0 * np.pi)  # 0 → 1, flat at both ends
    bump = np.sin(np.pi * u) ** 2  # 0 → 1 → 0, flat at both ends
    gens = word + [0] * (slots - len(word))
    seen = [False] * strands
    curves = []
    for start in range(strands):
        if seen[start]:
            continue
        pos, pieces = start, []
        while True:  # one lap per pass, until the strand is back where it started
            seen[pos] = True
            for j, g in enumerate(gens):
                theta = 2.0 * np.pi * (j + u) / slots
                lo = abs(g) - 1
                if g and pos in (lo, lo + 1):
                    up = pos == lo  # moving outwards
                    target = lo + 1 if up else lo
                    rad = r0 + pos + (target - pos) * step
                    # Positive σ_i: the strand moving outwards crosses over (toward +z);
                    # with both strands running counter-clockwise that makes the crossing sign
                    # (t_over × t_under)·ẑ positive.
                    z = (_HZ if up == (g > 0) else -_HZ) * bump
                    pos = target
                else:
                    rad = np.full_like(u, r0 + pos)
                    z = np.zeros_like(u)
                pieces.append(np.stack([rad * np.cos(theta), rad * np.sin(theta), z], axis=1))
            if pos == start:
                break
        curves.append(np.concatenate(pieces))
    return curves


def _braid_default_n(curves: list[np.ndarray]) -> int:
    # Edges of 0.3 strand spacings: the closest strands (one spacing apart) start 3.3 edges
    # apart. With 0.4 (2.5 edges) the start passed the coarseness check, but the flow of 5_2
    # pressed two strands to 0.52 edge lengths (where the discrete energy stops keeping them
    # apart) and stalled at iteration 61; at 0.3 (240 edges) its closest approach in 200
    # iterations was 0.98 edge lengths, and every other knot of the table stayed at 1.14 or
    # more (contact_ratio every 5 iterations).
    total = sum(_length(c) for c in curves)
    return max(100, 10 * math.ceil(total / 0.3 / 10))


def names(kind: str | None = None) -> list[str]:
    """Names of the shipped table: every prime knot up to 12 crossings (``"0_1"``, ``"3_1"``,
    …, ``"12n_888"``), then every prime link up to 11 crossings in each orientation LinkInfo
    lists (``"L2a1{0}"``, …, ``"L11n459{1,1,1}"``); ``kind="knot"`` or ``"link"`` for one of
    them (:mod:`.table`)."""
    return table.names(kind)


def search(text: str, limit: int | None = 50) -> list[str]:
    """Table names matching ``text``, best first (:func:`.table.search`): ``search("borromean")``
    is ``["L6a4{0,0}", …]``, ``search("10_16")`` lists 10_16, 10_160 … 10_165."""
    return table.search(text, limit)


def info(name: str) -> dict:
    """The table entry of a knot or link by name, alias or mirror (:func:`.table.lookup`):
    ``name``, ``kind`` ("knot"/"link"), ``braid`` and ``strands`` (the word ``named`` closes),
    ``crossings``, ``components``, ``alternating``, ``determinant``, ``alexander`` (coefficients
    of t⁰, t¹, …), ``jones`` (``(lowest power of t, coefficients)`` as
    ``invariants.jones_polynomial`` returns it), ``linking`` (matrix), ``common`` names, a
    one-line ``description``, ``mirror_of`` (the table name of a mirror image, else None),
    ``signature`` (KnotInfo's or LinkInfo's, of the orientation named) and for knots
    ``braid_index``, ``unknotting_number``, ``genus``, ``symmetry`` (KnotInfo's)."""
    e = table.entry(name)
    lo, coeffs = e.jones
    return {
        "name": e.name, "kind": e.kind, "braid": list(e.braid), "strands": e.strands,
        "crossings": e.crossings, "components": e.components, "alternating": e.alternating,
        "determinant": e.determinant, "alexander": list(e.alexander),
        "jones": (lo // 2 if lo % 2 == 0 else lo / 2, list(coeffs)),
        "linking": e.linking_matrix(), "signature": e.signature, "common": list(e.common),
        "description": e.description, "mirror_of": e.mirror_of, **e.extra,
    }


def named(name: str, n: int | None = None) -> Curve:
    """A prime knot or link of the table by name (``"3_1"``, ``"10_161"``, ``"12n_888"``,
    ``"L6a4{0,0}"``), alias (``"trefoil"``, ``"figure-eight"``, ``"Hopf link"``, ``"Whitehead
    link"``, ``"Borromean rings"``, ``"Solomon's knot"``, …) or mirror image (``"m3_1"``, the
    left-handed trefoil), as the closure of KnotInfo's or LinkInfo's braid word
    (:func:`braid_closure`; a link as a list of polygons, one per component, oriented as the
    name says). ``"0_1"``/``"unknot"`` is a circle.

    ``n=None`` is :func:`braid_closure`'s default, which grows with the braid: 3_1 gets 100,
    4_1 180, 5_2 240, 7_2 460, 8_1 660; the start passes the coarseness check down to 0.3
    times that count, and the flow from it does not jam (with 0.75 times, 5_2 did).
    """
    e = table.entry(name)
    if e.crossings == 0:
        return circle(64 if n is None else n)
    curve = braid_closure(e.braid, n, strands=e.strands)
    if e.reverse:
        curve = [c[::-1].copy() if k in e.reverse else c for k, c in enumerate(curve)]
    return curve


# --------------------------------------------------------------------------------------------
# From notation: braid words and PD codes as typed

#: Default edge count of :func:`from_pd`: this many times the fewest edges that pass the start
#: check (contact ratio about 3 at the default, as for the braids; at 2 times it was 1.8-2.2).
PD_EDGE_FACTOR = 3.0


def from_braid(word, n: int | None = None, strands: int | None = None) -> Curve:
    """:func:`braid_closure` of a braid word given as a sequence or typed as text:
    ``"1 -2 1 -2"``, ``"[1,-2,1,-2]"``, ``"{3, {1,-2,1,-2}}"`` (strands first, LinkInfo),
    ``"BR[3, {1,-2}]"`` or ``"s1 s2^-1 s1 s2^-1"`` (:func:`.notation.parse_braid`)."""
    if isinstance(word, str):
        word, given = notation.parse_braid(word)
        strands = strands if strands is not None else given
    return braid_closure(word, n, strands)


def from_pd(code, n: int | None = None) -> Curve:
    """A knot or link from a PD code: text (KnotInfo's ``"[[1,5,2,4],[3,1,4,6],[5,3,6,2]]"``,
    LinkInfo's ``{{…}}``, KnotTheory's ``PD[X[…], …]``, Knoodle's rows of five), a list of
    rows, or a :class:`.pd.PlanarDiagram`.

    The diagram is drawn in the plane by Tutte's barycentric embedding of its subdivided map
    and lifted at the crossings (:mod:`.drawing`; kinks and nugatory crossings are removed
    first, which leaves the link as it is); one polygon per component, oriented as the code
    says. The curve is checked against the code (its own Jones polynomial, or Alexander
    polynomial for large diagrams). ``n=None``: :data:`PD_EDGE_FACTOR` times the fewest edges
    that pass the start check (KnotInfo's codes: 3_1 100, 4_1 200; 40 knots of 10 to 12
    crossings 200 to 740, median 410, contact ratio at least 2.8; the Hopf link 600).
    """
    if isinstance(code, str):
        d = pd.parse_pd(code)
    elif isinstance(code, pd.PlanarDiagram):
        d = code
    else:
        d = pd.from_rows(code)
    curves = drawing.diagram_curves(d)
    if n is None:
        # searched upward from a guess above the dense drawing's own count: from a few
        # vertices up, a count far too coarse passed the check by luck (12n_202 at 50)
        dense = curves[0] if len(curves) == 1 else curves
        base = suggest_edge_count(dense) or 20000
        # the guess starts above the smallest count: come down while the check still passes
        # (stopping at the first count that fails)
        while base > 10 * len(curves):
            k = int(base / 1.1)
            counts = _split(k, [_length(c) for c in curves])
            if contact_ratio(resample(curves, counts) if len(curves) > 1
                             else resample(curves[0], k)) < 1.0:
                break
            base = k
        n = max(100, 10 * math.ceil(PD_EDGE_FACTOR * base / 10))
    P = _finish(curves, _check_n(n, len(curves)), diagram=lambda: d)
    drawing.check_same(d, P)
    return P


def from_notation(text: str, n: int | None = None) -> Curve:
    """A knot or link from a typed braid word or PD code (:func:`from_braid`, :func:`from_pd`;
    a PD code is a list of crossings, ``X[…]`` or groups of four numbers in brackets)."""
    kind, value = notation.parse_notation(text)
    if kind == "pd":
        return from_pd(value, n)
    word, strands = value
    return braid_closure(word, n, strands)


# --------------------------------------------------------------------------------------------
# Unknots that look knotted


def freedman_unknot(n: int = 600) -> np.ndarray:
    """The Freedman–He–Wang "difficult" unknot (docs/design.md, "Inputs the paper used").

    The 1184-vertex polygon published with Repulsive Curves (``data/freedman_unknot_1184.obj``,
    MIT licence), resampled to ``n`` vertices. Below 470 vertices two strands come closer than
    an edge length (contact ratio 1.2 at 600, 0.71 at 300).
    """
    n = _check_n(n, 1)
    return _finish(_freedman(), n)


@cache
def _freedman() -> list[np.ndarray]:
    return read_obj(_DATA / "freedman_unknot_1184.obj")


def helix_unknot(n: int = 300, turns: int = 6) -> np.ndarray:
    """A coil closed through itself: an unknot that looks knotted (the paper's Fig. 5).

    A helix of ``turns`` turns (radius 1, pitch 0.8) around the z-axis; at each end a half
    circle in the plane through the axis leads to the axis, and the return strand runs straight
    down the axis, through the coil. The curve lies over a simple closed loop in the half-plane
    (distance to the axis, height) and the axis part has a single point per height, so turning
    the coil back (rotating each height about the axis) is an isotopy to a flat loop: it is an
    unknot. The closest strands are one pitch (0.8) apart.
    """
    n = _check_n(n, 1)
    turns = int(turns)
    if turns < 1:
        raise ValueError(f"helix_unknot needs at least one turn, got {turns}")
    a, pitch = 1.0, 0.8
    half = turns * pitch / 2.0
    m = _dense_count(n)
    # Split the dense samples by arc length (roughly) between helix, caps and axis.
    helix_len = turns * math.hypot(2.0 * np.pi * a, pitch)
    cap_len = np.pi * a / 2.0 * 1.5
    total = helix_len + 2.0 * cap_len + 2.0 * half
    k_helix, k_cap = int(m * helix_len / total), int(m * cap_len / total) + 8
    k_axis = max(m - k_helix - 2 * k_cap, 8)
    # Helix, φ ∈ [0, 2π·turns), z from -half to half.
    s = np.arange(k_helix) / k_helix
    phi_end = 2.0 * np.pi * turns
    omega = phi_end / (2.0 * half)  # dφ/dz on the helix
    helix = _cyl(a, phi_end * s, -half + 2.0 * half * s)
    # Top cap: half circle of radius a/2 in the (ρ, z) half-plane, from (a, half) to (0, half);
    # φ keeps turning at first so that the tangent is continuous, and stops at the axis.
    b = np.pi * np.arange(k_cap) / k_cap
    turn = omega * (a / 2.0) * (b - b**2 / (2.0 * np.pi))
    top = _cyl(a / 2.0 * (1.0 + np.cos(b)), phi_end + turn, half + a / 2.0 * np.sin(b))
    # Axis, from half down to -half.
    z = half - 2.0 * half * np.arange(k_axis) / k_axis
    axis = np.stack([np.zeros(k_axis), np.zeros(k_axis), z], axis=1)
    # Bottom cap: the same half circle continued, from (0, -half) back to (a, -half) at φ = 0.
    b = b + np.pi
    w = 2.0 * np.pi - b
    turn = -omega * (a / 2.0) * (w - w**2 / (2.0 * np.pi))
    bottom = _cyl(a / 2.0 * (1.0 + np.cos(b)), turn, -half + a / 2.0 * np.sin(b))
    return _finish([np.concatenate([helix, top, axis, bottom])], n)


def random_unknot(n: int = 400, seed: int = 0, laps: int = 4) -> np.ndarray:
    """A seeded random tangle that is an unknot: a crumpled loop drawn as a descending diagram.

    The projection is a random closed curve whose tangent turns ``laps`` times plus a random
    smooth wiggle (bounded curvature, about ``3 * laps`` crossings, more for more laps). Its
    height falls steadily from a base point, so that every crossing is first met from above
    (a descending diagram: an unknot however tangled it looks), climbs back on a stretch that
    crosses nothing, and is then crumpled by random smooth heights as far as every crossing
    keeps half of its vertical gap. Draws that come closer to themselves than 2 edge lengths
    or bend by more than 0.35 rad per edge at 400 vertices are redrawn. Everything comes from
    ``numpy.random.default_rng(seed)``, so the curve depends on ``seed`` and ``laps`` only (not
    on ``n``). A final random rotation hides the vertical layering.
    """
    n = _check_n(n, 1)
    laps = int(laps)
    if laps < 2:
        raise ValueError(f"random_unknot needs at least 2 laps, got {laps}")
    rng = np.random.default_rng(seed)
    for _ in range(1000):
        curve = _descending_loop(rng, laps)
        if curve is not None:
            return _finish([curve @ _random_rotation(rng).T], n)
    raise RuntimeError(f"random_unknot(seed={seed}, laps={laps}) found no valid draw")


# --------------------------------------------------------------------------------------------
# Helpers


def _check_n(n, components: int) -> int:
    if isinstance(n, bool) or not isinstance(n, int | np.integer):
        raise TypeError(f"n must be an int, got {n!r}")
    n = int(n)
    if n < 4 * components:
        raise ValueError(f"n = {n} is too small: need at least 4 vertices per component")
    check_memory(n * _BYTES_PER_VERTEX, f"a curve of n = {n} vertices",
                 "ask for fewer: a few hundred untangle most knots, and Blender takes at "
                 "most 100 000")
    return n


def _whole(name: str, value) -> int:
    """``value`` as an int, or TypeError: 2.5 used to become 2 silently."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, int | np.integer):
        raise TypeError(f"{name} must be a whole number (int), got {value!r}")
    return int(value)


def _check_dense(samples: int, what: str) -> None:
    """Refuse, before they are made, dense samples that would not fit in memory."""
    check_memory(samples * _BYTES_PER_SAMPLE, f"{what} ({samples} dense samples)",
                 "use fewer strands, turns or vertices")


def _dense_count(n: int) -> int:
    """Samples of the smooth curve before resampling to ``n``: fine enough that the resampled
    vertices lie on the curve to well below an edge length."""
    return max(16 * n, 4096)


def _length(c: np.ndarray) -> float:
    return float(np.linalg.norm(np.roll(c, -1, axis=0) - c, axis=1).sum())


def _split(n: int, lengths: list[float]) -> list[int]:
    """``n`` vertices split in proportion to ``lengths``, each >= 4, summing to ``n``."""
    share = np.asarray(lengths) / sum(lengths) * n
    counts = np.maximum(np.floor(share).astype(int), 4)
    while counts.sum() != n:  # a few rounds: give to the most short-changed, take from the most
        excess = counts - share  # over-served that can spare a vertex
        if counts.sum() < n:
            counts[np.argmin(excess)] += 1
        else:
            counts[np.argmax(np.where(counts > 4, excess, -np.inf))] -= 1
    return counts.tolist()


def _finish(curves: list[np.ndarray], n: int, diagram=None) -> Curve:
    """Resample dense closed curves to ``n`` vertices in all, centre, scale into the unit ball.

    Fewer than ``MIN_CHECKED_VERTICES`` per component are refused, naming a count that passes
    the start check: below it the check has no vertex pair to compare, and the polygon need not
    have the curve's knot type (T(2, 3) at 5, 6 and 7 vertices passed it as unknots, checked
    with topoly; a coarse polygon of a tangled unknot could as well be knotted). With
    ``diagram`` (a function returning the :class:`.pd.PlanarDiagram` the curve draws: braids,
    torus knots, PD codes) a polygon that fails the start check's coarseness test is compared
    with it, and refused unless it has the diagram's Jones polynomial (Alexander's when that
    is too costly), naming the count that passes the start check: 4_1 at 9 vertices came out
    as the trefoil m3_1, 5_2 at 9 to 18 as an unknot, a trefoil or 4_1. A coarse polygon of
    the right knot stays (``relax`` refines it: 3_1 at 24, where 27 passes)."""
    counts = [n] if len(curves) == 1 else _split(n, [_length(c) for c in curves])
    if min(counts) < MIN_CHECKED_VERTICES:
        k = suggest_edge_count(curves[0] if len(curves) == 1 else curves,
                               start=MIN_CHECKED_VERTICES * len(curves))
        raise ValueError(
            f"n = {n} is too few vertices for this curve: below {MIN_CHECKED_VERTICES} per "
            f"component the start check cannot see strands that come too close, and the "
            f"polygon may not have the curve's knot type; use n >= {k or MIN_CHECKED_VERTICES}"
        )
    polys = resample(curves, counts, closed=True)
    if diagram is not None and contact_ratio(polys[0] if len(polys) == 1 else polys
                                             ) < CONTACT_RATIO and not _draws(diagram(), polys):
        k = suggest_edge_count(curves[0] if len(curves) == 1 else curves, start=n + 1)
        raise ValueError(
            f"n = {n} is too coarse for this curve: strands far apart along it come closer "
            f"than one edge length, and its polygon is not the curve's knot (a chord cuts "
            f"across another strand); " + (f"use n >= {k}" if k is not None else
                                           "use many more vertices"))
    allv = np.concatenate(polys)
    centre = allv.mean(axis=0)
    scale = np.linalg.norm(allv - centre, axis=1).max()
    polys = [(P - centre) / scale for P in polys]
    return polys[0] if len(polys) == 1 else polys


def _draws(d: pd.PlanarDiagram, polys: list[np.ndarray]) -> bool:
    """Whether the polygons have the invariants of ``d`` (:func:`.drawing.check_same`); False
    for polygons that touch themselves or cannot be read."""
    try:
        drawing.check_same(d, polys[0] if len(polys) == 1 else polys)
    except (RuntimeError, ValueError):
        return False
    return True


def _cyl(rho, phi, z) -> np.ndarray:
    return np.stack([rho * np.cos(phi), rho * np.sin(phi), np.broadcast_to(z, np.shape(phi))], 1)


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


_SAMPLES_PER_LAP = 200  # dense samples per lap of random_unknot's projection
_WIGGLE = 0.6  # amplitude (radians, per lap) of the random part of its turning angle
_CLEAR = 2.0  # its smallest clearance (in edge lengths) at 400 vertices
_BEND = 0.35  # and its largest turning angle per edge there (radians)


def _descending_loop(rng: np.random.Generator, laps: int) -> np.ndarray | None:
    """One draw of :func:`random_unknot` before rotation and scaling, or None if rejected."""
    m = _SAMPLES_PER_LAP * laps
    s = np.arange(m) / m
    # Projection: a closed curve whose tangent turns `laps` times plus a random smooth wiggle,
    # so that its curvature is bounded (no cusps) while the laps cross each other.
    theta = 2.0 * np.pi * laps * s + _random_wave(rng, s, 3, _WIGGLE * laps)
    velocity = np.exp(1j * theta)
    if abs(velocity.mean()) > 0.5:  # closing it would slow it down too much somewhere
        return None
    xy = np.cumsum(velocity - velocity.mean()) / m
    xy = np.column_stack([xy.real, xy.imag])
    seg = np.linalg.norm(np.roll(xy, -1, axis=0) - xy, axis=1)
    arc = np.concatenate(([0.0], np.cumsum(seg[:-1])))
    length = arc[-1] + seg[-1]
    cross = _planar_crossings(xy)  # (c, 2) sample indices of the two passes
    if len(cross) < 2 * laps:
        return None
    # Descend from the end of the longest stretch without a crossing and climb back on it:
    # every crossing is first met from above (a descending diagram), hence an unknot.
    passes = np.sort(arc[cross].ravel())
    gaps = np.diff(np.append(passes, passes[0] + length))
    g = int(np.argmax(gaps))
    u = (arc - passes[(g + 1) % len(passes)] + 0.25 * gaps[g]) % length  # descent from u = 0
    down = length - 0.5 * gaps[g]  # the climb takes the middle half of the stretch
    top = np.ptp(xy, axis=0).max()  # about as tall as wide
    z = top * (1.0 - u / down)
    w = (u[u >= down] - down) / (length - down)  # climb: cubic Hermite matching the slopes
    z[u >= down] = top * (3 * w**2 - 2 * w**3 - (length - down) / down * (2 * w**3 - 3 * w**2 + w))
    # Crumple the staircase with random smooth heights, as far as every crossing keeps half of
    # its vertical gap: only the order of the strands at the crossings decides the knot type.
    noise = top * _random_wave(rng, s, 4, 1.0)
    first = np.where(u[cross[:, 0]] < u[cross[:, 1]], cross[:, 0], cross[:, 1])
    second = cross.sum(axis=1) - first
    gap, gap_noise = z[first] - z[second], noise[first] - noise[second]
    worse = gap_noise < gap
    mix = min(0.6, float(np.min(0.5 * gap[worse] / (gap[worse] - gap_noise[worse]), initial=1)))
    curve = np.column_stack([xy, (1.0 - mix) * z + mix * noise])
    # Keep the draw only if it is clear of itself and bends gently at 400 vertices.
    P = resample(curve, 400, closed=True)
    if contact_ratio(P) < _CLEAR or _max_turn(P) > _BEND:
        return None
    return curve


def _random_wave(rng: np.random.Generator, s: np.ndarray, terms: int, scale: float) -> np.ndarray:
    """Random 1-periodic smooth function of ``s``: ``terms`` sines with amplitudes ~ scale/k."""
    k = np.arange(1, terms + 1)[:, None]
    amp = rng.normal(size=(terms, 1)) * scale / k
    phase = rng.uniform(0.0, 2.0 * np.pi, size=(terms, 1))
    return (amp * np.sin(2.0 * np.pi * k * s + phase)).sum(axis=0)


@nb.njit(cache=True)
def _planar_crossings(xy: np.ndarray) -> np.ndarray:
    """Self-crossings of a closed planar polygon: ``(c, 2)`` int array, the indices of the two
    crossing edges (edge ``i`` joins vertex ``i`` to ``i + 1``), one row per crossing."""
    m = xy.shape[0]
    found = [(0, 0) for _ in range(0)]
    for i in range(m):
        ax, ay = xy[i, 0], xy[i, 1]
        dx, dy = xy[(i + 1) % m, 0] - ax, xy[(i + 1) % m, 1] - ay
        for j in range(i + 2, m if i > 0 else m - 1):  # skip neighbours (edge m-1 touches 0)
            bx, by = xy[j, 0], xy[j, 1]
            ex, ey = xy[(j + 1) % m, 0] - bx, xy[(j + 1) % m, 1] - by
            den = dx * ey - dy * ex
            if den == 0.0:
                continue
            qx, qy = bx - ax, by - ay
            a = (qx * ey - qy * ex) / den
            b = (qx * dy - qy * dx) / den
            if 0.0 <= a < 1.0 and 0.0 <= b < 1.0:
                found.append((i, j))
    out = np.empty((len(found), 2), dtype=np.int64)
    for k, (i, j) in enumerate(found):
        out[k, 0], out[k, 1] = i, j
    return out


def _max_turn(P: np.ndarray) -> float:
    """Largest angle (radians) between consecutive edges of the closed polygon ``P``."""
    e = np.roll(P, -1, axis=0) - P
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    return float(np.arccos(np.clip((e * np.roll(e, 1, axis=0)).sum(axis=1), -1.0, 1.0)).max())
