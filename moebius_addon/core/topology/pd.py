"""Planar diagram (PD) codes of knots and links: from braid words, from projections of polygons,
from what a user types; Reidemeister I and II simplification; faces, components, linking numbers.

Convention (KnotTheory, KnotInfo, LinkInfo and Knoodle write it so): a crossing ``X[i, j, k, l]``
lists the four edges that meet there counter-clockwise, starting with the incoming under-edge
``i``; ``k`` is the outgoing under-edge. At a positive (right-handed) crossing the over-strand
runs ``l → j``, at a negative one ``j → l``. A crossing is positive when
``(t_over × t_under) · ẑ > 0`` (the sign of :mod:`.invariants` and of ``knots.braid_closure``:
``σ_i`` is positive, the closure of ``σ_1³`` is KnotInfo's 3_1, whose PD code
``[[1,5,2,4],[3,1,4,6],[5,3,6,2]]`` has three positive crossings).

A :class:`PlanarDiagram` keeps the sign of every crossing beside the labels, so its labels need
not be consecutive along the components (simplification merges them); :func:`from_rows` infers
the signs of a typed code from the orientation of its edges (the under-edges fix it) or checks
the fifth column of Knoodle's rows (``> 0`` right-handed).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

__all__ = ["PlanarDiagram", "edge_slots", "faces", "from_braid", "from_passages", "from_rows",
           "linking_matrix", "parse_pd", "relabel", "remove_crossings", "simplify"]


@dataclass(frozen=True)
class PlanarDiagram:
    """Crossings of a knot or link diagram.

    ``X`` is a ``(c, 4)`` integer array of edge labels (each label appears exactly twice),
    ``sign`` the ``(c,)`` signs (+1 right-handed), ``loops`` the number of components without
    any crossing (circles apart from the rest of the diagram)."""

    X: np.ndarray
    sign: np.ndarray
    loops: int = 0

    @property
    def crossings(self) -> int:
        return len(self.X)

    @property
    def writhe(self) -> int:
        return int(self.sign.sum())

    def rows(self) -> list[list[int]]:
        """The code as ``[[i, j, k, l], …]`` with the edges relabelled 1, 2, … consecutively
        along each component (KnotInfo's form; the signs then follow from the labels)."""
        d = relabel(self)
        return (d.X + 1).tolist()

    def components(self) -> list[list[int]]:
        """Edge labels of each component with crossings, in the order of travel."""
        nxt = _successor(self)
        seen: set[int] = set()
        comps = []
        for e in sorted(nxt):
            if e in seen:
                continue
            cyc = [e]
            seen.add(e)
            f = nxt[e]
            while f != e:
                cyc.append(f)
                seen.add(f)
                f = nxt[f]
            comps.append(cyc)
        return comps

    def reverse(self, components) -> PlanarDiagram:
        """The diagram with the given components (indices into :meth:`components`) running
        the other way: a crossing whose under-strand turns starts at its old outgoing edge, and
        its sign changes when exactly one of its two strands turns."""
        comp = edge_components(self)
        flip = set(int(k) for k in components)
        X = self.X.copy()
        sign = self.sign.copy()
        for m in range(self.crossings):
            under = comp[int(self.X[m, 0])] in flip
            over = comp[int(self.X[m, 1])] in flip
            if under:
                X[m] = np.roll(self.X[m], 2)
            if under != over:
                sign[m] = -sign[m]
        return PlanarDiagram(X, sign, self.loops)

    def mirror(self) -> PlanarDiagram:
        """The mirror image: every crossing switched (over ↔ under)."""
        X = self.X.copy()
        pos = self.sign > 0
        # positive [i, j, k, l] (over l → j) becomes negative [l, i, j, k]; negative
        # [i, j, k, l] (over j → l) becomes positive [j, k, l, i]
        X[pos] = np.roll(self.X[pos], 1, axis=1)
        X[~pos] = np.roll(self.X[~pos], -1, axis=1)
        return PlanarDiagram(X, -self.sign, self.loops)


class DisjointSets:
    """Union–find over hashable items (path halving); each item is its own set until joined."""

    def __init__(self):
        self.parent: dict = {}

    def find(self, a):
        parent = self.parent
        parent.setdefault(a, a)
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    def union(self, a, b) -> bool:
        """Join the sets of ``a`` and ``b``, ``a``'s root staying the root; False when they
        were one set already."""
        ra, rb = self.find(a), self.find(b)
        if ra == rb:
            return False
        self.parent[rb] = ra
        return True


# --------------------------------------------------------------------------------------------
# Construction


def braid_word(word, strands: int | None = None) -> tuple[list[int], int]:
    """``(word, strands)`` checked: nonzero integer generators, and at least ``max|i| + 1``
    strands (the default)."""
    if isinstance(word, (str, bytes)):
        raise TypeError(f"a braid word is a sequence of nonzero integers, got the text "
                        f"{word!r}: read text with knots.from_braid or notation.parse_braid")
    word = list(word)
    for g in word:  # 1.5 used to become σ1 silently, True σ1 too
        if isinstance(g, (bool, np.bool_)) or not isinstance(g, (int, np.integer)):
            raise TypeError(f"braid word {word}: generators are nonzero integers ±i (σ_i^±1), "
                            f"got {g!r}")
    word = [int(g) for g in word]
    if any(g == 0 for g in word):
        raise ValueError(f"braid word {word}: generators are nonzero integers ±i (σ_i^±1)")
    need = max((abs(g) for g in word), default=0) + 1
    if strands is not None and (isinstance(strands, (bool, np.bool_))
                                or not isinstance(strands, (int, np.integer))):
        raise TypeError(f"strands must be a whole number (int), got {strands!r}")
    strands = need if strands is None else int(strands)
    if strands < need:
        raise ValueError(f"braid word {word} needs at least {need} strands, got {strands}")
    return word, strands


def from_braid(word, strands: int | None = None) -> PlanarDiagram:
    """The closure of a braid (``σ_i`` as ``i``, ``σ_i⁻¹`` as ``-i``, 1-based; ``σ_i`` positive).

    Strands run upwards; at ``σ_i`` the strand from position ``i`` to ``i + 1`` passes over
    (the layout of ``knots.braid_closure``). Strands the word never touches are ``loops``."""
    word, strands = braid_word(word, strands)
    label = list(range(strands))  # the edge now at each position
    fresh = strands
    rows, signs = [], []
    for g in word:
        p = abs(g) - 1
        a, b = label[p], label[p + 1]  # incoming at positions p (left) and p + 1 (right)
        a2, b2 = fresh, fresh + 1  # a continues to p + 1 as a2, b to p as b2
        fresh += 2
        if g > 0:  # a (left → right) over: under b → b2, counter-clockwise from b
            rows.append([b, a2, b2, a])
        else:  # b (right → left) over: under a → a2
            rows.append([a, b, a2, b2])
        signs.append(1 if g > 0 else -1)
        label[p], label[p + 1] = b2, a2
    # closing the braid identifies the top edge at each position with the bottom one
    top = {label[p]: p for p in range(strands)}
    X = np.array(rows, dtype=np.int64).reshape(-1, 4)
    X = np.vectorize(lambda e: top.get(e, e), otypes=[np.int64])(X) if len(X) else X
    used = set(X.ravel().tolist())
    loops = sum(1 for p in range(strands) if p not in used)
    return relabel(PlanarDiagram(X, np.array(signs, dtype=np.int64), loops))


def from_passages(over: np.ndarray, under: np.ndarray, sign: np.ndarray, starts: np.ndarray
                  ) -> tuple[PlanarDiagram, np.ndarray]:
    """The PD code of a projection: crossings at positions ``over`` and ``under`` along the
    curve (vertex index + parameter, vertices numbered through all components, which start at
    ``starts``, then N) with signs ``sign`` (``invariants.Diagram``).

    Returns the diagram (one loop per component without crossings) and, per edge label, the
    component of the curve it lies on."""
    c = len(over)
    K = len(starts) - 1
    pos = np.concatenate([under, over])  # passage m: under of crossing m, c + m: its over
    kind = np.r_[np.zeros(c, np.int64), np.ones(c, np.int64)]
    xing = np.r_[np.arange(c), np.arange(c)]
    comp = np.searchsorted(starts, pos, side="right") - 1
    order = np.lexsort((pos, comp))
    # edge label = rank of the passage it leaves; the edge entering a passage is the one
    # leaving the previous passage of the same component (cyclically)
    out_edge = np.empty(2 * c, np.int64)
    out_edge[order] = np.arange(2 * c)
    in_edge = np.empty(2 * c, np.int64)
    comp_sorted = comp[order]
    first = np.searchsorted(comp_sorted, np.arange(K))
    last = np.searchsorted(comp_sorted, np.arange(K), side="right") - 1
    prev_rank = np.arange(2 * c) - 1
    has = last >= first
    for k in np.flatnonzero(has):
        prev_rank[first[k]] = last[k]
    in_edge[order] = prev_rank
    X = np.empty((c, 4), np.int64)
    u = np.flatnonzero(kind == 0)
    o = np.flatnonzero(kind == 1)
    iu, ou = in_edge[u], out_edge[u]
    io, oo = in_edge[o], out_edge[o]
    m_u, m_o = xing[u], xing[o]
    X[m_u, 0], X[m_u, 2] = iu, ou
    positive = sign > 0
    # positive: [in_u, out_o, out_u, in_o]; negative: [in_u, in_o, out_u, out_o]
    X[m_o, 1] = np.where(positive[m_o], oo, io)
    X[m_o, 3] = np.where(positive[m_o], io, oo)
    edge_comp = comp_sorted.copy()
    loops = int((~has).sum())
    return PlanarDiagram(X, np.asarray(sign, np.int64).copy(), loops), edge_comp


def from_rows(rows, signs=None) -> PlanarDiagram:
    """A PD code as typed: rows of 4 edge labels (``[i, j, k, l]``, counter-clockwise from the
    incoming under-edge), or of 5 with Knoodle's handedness last (``> 0`` right-handed).

    The signs follow from the orientation of the edges, which the under-edges fix (``i`` enters,
    ``k`` leaves) and the over-strands carry on; a component that never passes under is
    oriented by its labels as KnotTheory does (``j = l + 1``: over from ``l`` to ``j``). A fifth
    column that contradicts the orientation, a label that does not appear exactly twice, or a
    code that does not lie in the plane raises ``ValueError`` naming the crossing."""
    rows = [list(r) for r in rows]
    if not rows:
        return PlanarDiagram(np.zeros((0, 4), np.int64), np.zeros(0, np.int64), 1)
    widths = {len(r) for r in rows}
    if not widths <= {4, 5} or len(widths) > 1:
        raise ValueError("a PD code has 4 edge labels per crossing (or 5 with the handedness "
                         f"last, as Knoodle writes it); got rows of {sorted(widths)} numbers")
    try:
        A = np.array(rows, dtype=np.int64)
    except (TypeError, ValueError):
        raise ValueError("PD code entries must be whole numbers") from None
    X = A[:, :4].copy()
    given = A[:, 4] if A.shape[1] == 5 else (np.asarray(signs) if signs is not None else None)
    labels, counts = np.unique(X, return_counts=True)
    bad = labels[counts != 2]
    if len(bad):
        e = int(bad[0])
        n = int(counts[counts != 2][0])
        raise ValueError(f"edge {e} appears {n} time{'s' if n != 1 else ''} in the PD code; "
                         f"every edge joins two crossings, so each label appears exactly twice")
    head = _orient(X)
    sign = np.where(head[:, 3], 1, -1).astype(np.int64)  # over enters at l: positive
    if given is not None:
        want = np.where(np.asarray(given) > 0, 1, -1)
        wrong = np.flatnonzero(want != sign)
        if len(wrong):
            m = int(wrong[0])
            raise ValueError(
                f"crossing {m + 1} {X[m].tolist()}: its handedness {int(np.asarray(given)[m])} "
                f"contradicts the orientation of its edges (the under-edge {X[m, 0]} enters, "
                f"{X[m, 2]} leaves, so the over-strand runs "
                f"{'l → j' if sign[m] > 0 else 'j → l'}: "
                f"{'right' if sign[m] > 0 else 'left'}-handed)")
    d = PlanarDiagram(X, sign, 0)
    _check_planar(d)
    return d


def parse_pd(text: str) -> PlanarDiagram:
    """A PD code from text: KnotInfo's ``[[1,5,2,4],[3,1,4,6],[5,3,6,2]]``, LinkInfo's
    ``{{4, 1, 3, 2}, {2, 3, 1, 4}}``, KnotTheory's ``PD[X[1,5,2,4], X[3,1,4,6], …]`` or rows
    of 5 numbers with Knoodle's handedness last. Anything else in the text (words after the
    code, letters inside a crossing) is refused, not skipped: skipped text may have been part
    of the code."""
    groups = re.findall(r"[\[\{\(]([^\[\]\{\}\(\)]*)[\]\}\)]", text)
    if not any(re.search(r"\d", g) for g in groups):
        raise ValueError(f"no crossings found in the PD code {text!r}: write it as "
                         "[[1,5,2,4],[3,1,4,6],[5,3,6,2]] or PD[X[1,5,2,4], …]")
    for g in groups:
        if g.strip() and not re.fullmatch(r"\s*-?\d+(\s*[,;\s]\s*-?\d+)*\s*,?\s*", g):
            raise ValueError(f"could not read the crossing {g.strip()!r} in the PD code "
                             f"{text!r}: a crossing is 4 whole numbers (5 with Knoodle's "
                             "handedness), e.g. X[1,5,2,4]")
    # the text around the crossings: brackets, separators, a leading PD and an X before each
    skeleton = re.sub(r"[\[\{\(][^\[\]\{\}\(\)]*[\]\}\)]", "#", text)
    skeleton = re.sub(r"X\s*#", "#", re.sub(r"^\s*PD\s*(?=\[)", "", skeleton))
    stray = re.search(r"[^\s,;#\[\]\{\}\(\)]+", skeleton)
    if stray:
        raise ValueError(f"could not read {stray.group(0)!r} in the PD code {text!r}: give the "
                         "crossings alone, e.g. [[1,5,2,4],[3,1,4,6],[5,3,6,2]] or "
                         "PD[X[1,5,2,4], X[3,1,4,6], X[5,3,6,2]]")
    rows = [[int(v) for v in re.findall(r"-?\d+", g)] for g in groups]
    rows = [r for r in rows if r]
    return from_rows(rows)


# --------------------------------------------------------------------------------------------
# Orientation, faces, components


def edge_slots(X: np.ndarray) -> dict[int, list[tuple[int, int]]]:
    """Where each edge label sits: ``{label: [(crossing, position), (crossing, position)]}``."""
    where: dict[int, list[tuple[int, int]]] = {}
    for c, row in enumerate(np.asarray(X).tolist()):  # Python ints: 6x faster than X[c, p]
        for p, e in enumerate(row):
            where.setdefault(e, []).append((c, p))
    return where


def _orient(X: np.ndarray) -> np.ndarray:
    """``(c, 4)`` booleans: True where the edge in that slot enters the crossing."""
    c = len(X)
    where = edge_slots(X)
    head = np.zeros((c, 4), dtype=bool)
    known = np.zeros((c, 4), dtype=bool)

    def set_slot(m, p, enters, todo):
        if known[m, p]:
            if head[m, p] != enters:
                raise ValueError(
                    f"the PD code's edges cannot be oriented consistently at crossing {m + 1} "
                    f"{X[m].tolist()} (edge {X[m, p]}): check that each row starts with the "
                    f"incoming under-edge and goes counter-clockwise")
            return
        known[m, p], head[m, p] = True, enters
        todo.append((m, p))

    todo: list[tuple[int, int]] = []
    for m in range(c):  # the under-strand enters at i and leaves at k
        set_slot(m, 0, True, todo)
        set_slot(m, 2, False, todo)
    while True:
        while todo:
            m, p = todo.pop()
            # the other end of the same edge: entering here means leaving there
            for m2, p2 in where[int(X[m, p])]:
                if (m2, p2) != (m, p):
                    set_slot(m2, p2, not head[m, p], todo)
            # the strand passes straight through: the opposite slot leaves where this enters
            set_slot(m, p ^ 2, not head[m, p], todo)
        rest = np.flatnonzero(~known[:, 1])
        if not len(rest):
            return head
        # a component that never passes under: oriented by its labels (KnotTheory's rule)
        m = int(rest[0])
        j, l = int(X[m, 1]), int(X[m, 3])  # noqa: E741 - the PD code's own names
        set_slot(m, 3, j == l + 1 or l > j + 1, todo)


def _successor(d: PlanarDiagram) -> dict[int, int]:
    """Next edge along the curve after each edge."""
    nxt = {}
    for m in range(d.crossings):
        i, j, k, l = (int(v) for v in d.X[m])  # noqa: E741 - X[i, j, k, l]
        nxt[i] = k
        if d.sign[m] > 0:
            nxt[l] = j
        else:
            nxt[j] = l
    return nxt


def faces(d: PlanarDiagram) -> list[list[tuple[int, int]]]:
    """Faces of the diagram as cycles of slots ``(crossing, position)``: each slot is the
    corner between the edge in that position and the next one counter-clockwise."""
    where = edge_slots(d.X)
    other = {}
    for slots in where.values():
        a, b = slots
        other[a], other[b] = b, a
    seen = set()
    out = []
    for m in range(d.crossings):
        for p in range(4):
            if (m, p) in seen:
                continue
            face = []
            s = (m, p)
            while s not in seen:
                seen.add(s)
                face.append(s)
                m2, p2 = other[s]  # along the edge to its other end
                s = (m2, (p2 - 1) % 4)  # turn to the neighbouring edge (clockwise there)
            out.append(face)
    return out


def _check_planar(d: PlanarDiagram) -> None:
    if d.crossings == 0:
        return
    where = edge_slots(d.X)
    # connected pieces of the diagram (crossings joined by edges)
    sets = DisjointSets()
    for (m1, _), (m2, _) in where.values():
        sets.union(m2, m1)
    pieces = len({sets.find(m) for m in range(d.crossings)})
    f = len(faces(d))
    # Euler: V - E + F = 1 + pieces on the sphere, V = c, E = 2c
    if d.crossings - 2 * d.crossings + f != 1 + pieces:
        raise ValueError(
            "this PD code does not describe a diagram in the plane (its faces do not add up: "
            f"{f} faces for {d.crossings} crossings); check that each row lists the edges "
            "counter-clockwise")


def relabel(d: PlanarDiagram) -> PlanarDiagram:
    """The same diagram with edges labelled 0, 1, … consecutively along each component,
    components ordered by their smallest old label."""
    if d.crossings == 0:
        return d
    new: dict[int, int] = {}
    for comp in d.components():
        for e in comp:
            new[e] = len(new)
    X = np.vectorize(new.__getitem__, otypes=[np.int64])(d.X)
    return PlanarDiagram(X, d.sign.copy(), d.loops)


def edge_components(d: PlanarDiagram) -> dict[int, int]:
    """The component (index into :meth:`PlanarDiagram.components`) of every edge."""
    return {e: k for k, comp in enumerate(d.components()) for e in comp}


def linking_matrix(d: PlanarDiagram) -> np.ndarray:
    """Linking numbers of the components with crossings (in the order of
    :meth:`PlanarDiagram.components`) followed by ``loops`` zero rows."""
    comp = edge_components(d)
    K = len(d.components()) + d.loops
    L = np.zeros((K, K), np.int64)
    for m in range(d.crossings):
        a, b = comp[int(d.X[m, 0])], comp[int(d.X[m, 1])]
        if a != b:
            L[a, b] += d.sign[m]
            L[b, a] += d.sign[m]
    return L // 2


# --------------------------------------------------------------------------------------------
# Simplification


def remove_crossings(d: PlanarDiagram, gone: list[int]) -> PlanarDiagram:
    """The diagram without the crossings ``gone``, the strands joined straight through each
    (under i–k, over j–l); a strand that closes up without any crossing left becomes a loop.
    The same link when the crossings form a kink, a removable bigon or a nugatory crossing."""
    sets = DisjointSets()
    loops = d.loops
    for m in gone:
        i, j, k, l = (int(v) for v in d.X[m])  # noqa: E741 - X[i, j, k, l]
        for a, b in ((i, k), (j, l)):
            if not sets.union(a, b):
                loops += 1
    keep = np.setdiff1d(np.arange(d.crossings), gone)
    X = d.X[keep].copy()
    # only the labels of the removed crossings were joined: each becomes its set's root (a
    # pass over X per such label, not a Python call per entry: simplify removes crossings
    # one or two at a time, so this runs once per removal)
    old = X.copy()
    for e in list(sets.parent):
        root = sets.find(e)
        if root != e:
            X[old == e] = root
    return PlanarDiagram(X.reshape(-1, 4), d.sign[keep].copy(), loops)


def _kink(d: PlanarDiagram) -> int | None:
    """The first crossing with an edge from one of its slots to the next (a kink), or None."""
    X = d.X
    hit = np.flatnonzero((X == np.roll(X, -1, axis=1)).any(axis=1))
    return int(hit[0]) if len(hit) else None


def _bigon(d: PlanarDiagram) -> tuple[int, int] | None:
    """Two crossings bounding a face of two edges with one strand over at both (Reidemeister
    II): removing both leaves the same link. Of such faces the first in the order of
    :func:`faces` (by their smallest slot), found with whole-array operations: this runs once
    per removal in :func:`simplify`."""
    X = d.X
    c = len(X)
    if c < 2:
        return None
    flat = X.ravel()
    order = np.argsort(flat, kind="stable")  # the two slots of every label, side by side
    partner = np.empty(4 * c, np.int64)
    partner[order[0::2]] = order[1::2]
    partner[order[1::2]] = order[0::2]
    # a face's next corner: along the edge to its other end, then turn (faces)
    turn = partner - partner % 4 + (partner % 4 - 1) % 4
    q = np.arange(4 * c)
    two = (turn[turn] == q) & (turn != q) & (q < turn)  # faces of two corners, at their first
    two &= q // 4 != turn // 4  # two different crossings
    two &= (q % 4) % 2 == (partner % 4) % 2  # one strand over at both
    hit = np.flatnonzero(two)
    if not len(hit):
        return None
    return int(hit[0] // 4), int(turn[hit[0]] // 4)


def simplify(d: PlanarDiagram) -> PlanarDiagram:
    """Remove kinks (Reidemeister I) and bigons with one strand over at both crossings
    (Reidemeister II) until none is left. The link is unchanged; the crossing count falls."""
    while d.crossings:
        m = _kink(d)
        if m is not None:
            d = remove_crossings(d, [m])
            continue
        pair = _bigon(d)
        if pair is None:
            break
        d = remove_crossings(d, list(pair))
    return d
