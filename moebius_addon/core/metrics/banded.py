"""O(N) saddle-point solves for the banded metrics (``l2``, ``h1``, ``h2``): nothing dense.

The saddle-point system of an iterate (docs/design.md, step 2; the paper's "Computational
treatment") is

    [[A ⊗ I₃, C_eᵀ, C_bᵀ], [C_e, 0, 0], [C_b, 0, 0]] [u; λ_e; λ_b] = [g; r_e; r_b]

with ``A = A_band + B`` (``A_band`` the metric's banded part, at most two neighbours away along
each component; ``B = Σ_c β_c β_cᵀ`` its barycenter term, rank one per component), ``C_e``
the edge-length rows (row I touches the two vertices of edge I) and ``C_b`` the three dense
barycenter rows of every component. Ordered vertex by vertex, each vertex's three coordinates
followed by the multiplier of the edge that starts there, and the vertices of a component in
the zigzag order ``s, e−1, s+1, e−2, …`` (a closed loop becomes a band: neighbours along the
curve are at most two places apart, the closing edge one), the blocks of ``A_band`` and
``C_e`` form one band matrix of half-bandwidth 11 (``l2``, ``h1``) or 19 (``h2``). Its LU
factorization with partial pivoting costs O(N), one solve O(N).

That band alone is singular: translations move no edge length and cost nothing in
``A_band``. It is made regular by a stiff spring ``μ e₀ e₀ᵀ`` at the first vertex of every
component, and the exact system is recovered by the Sherman–Morrison–Woodbury formula with a
correction of rank 12 per component (the spring removed, the barycenter term added, the
barycenter rows and their multipliers bordered on). The correction is supported on its
component and the band is block diagonal by component, so its capacitance matrix is a 12 × 12
block per component: memory and work stay O(N) for links too. ``B``'s range (multiples of
``β``, proportional to the barycenter rows' vertex weights) lies in ``Cᵀ``'s, so it moves the
multipliers only: a preconditioner leaves it out (rank 9, six band solves per iterate).

A preconditioner may project the barycenter rows instead (``projected``): the right-hand
side's translations taken out, the band solved with a weak spring, the solution translated onto
the rows. That is the exact solve of the band's metric with its translations minimized out
(its Schur complement), no correction and no column solves; the Laplacians of the hs operator
that the band preconditions charge nothing for a translation either.

A long block (:data:`SPLIT_FROM`) is factored and solved as two halves side by side, joined by
a separator of a few rows eliminated last (:func:`_split_band`), so that a curve of one piece
has two cores for its band solves.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from ..geometry.constraints import Jacobian
from ..geometry.layout import Layout
from .records import served_by

#: Metrics whose Gram matrix is banded along the curve (plus the barycenter term):
#: :mod:`.records`.
BANDED_METRICS = served_by("banded")
# The band of several components is factored and solved in up to this many blocks of whole
# components, in parallel (the same bits: no entry crosses a block's edge).
_BLOCKS = 64
#: From this many vertices on, a solver's band keeps only its packed factors (:func:`pack_factors`)
#: and is not taken over by the next iterate's: the fine band of the hs preconditioner holds
#: 0.70 GB at 10⁶ vertices, its packed U 0.31 GB; below, the reuse saves a fresh array's page
#: faults (docs/lab/repulsor.md, "A new machine, the bench's warm-up, unsigned places, the band
#: compacted").
COMPACT_FROM = 200_000
# Vertices per piece of the low-rank correction's parallel sums (:func:`_correction`).
_CHUNK = 4096
#: The spring of a band whose barycenter rows are projected (``BandedSaddle(projected=True)``),
#: as a fraction of the metric's diagonal at the anchor: the spring stays in that metric, and
#: with the whole diagonal the hs flow's Krylov solves took 56 iterations where the bordered
#: preconditioner took 47 (FHW at 20 000 edges, eight iterations of the flow); with a
#: thousandth of it 47.
PROJECTED_SPRING = 1e-3
#: A block of the band (a component, or components merged by :func:`block_cuts`) of this
#: many vertices or more is factored and solved as two halves side by side, joined by a
#: separator of a few rows (:func:`_split_band`): a curve of one piece used one core for its
#: band solves. By size alone, so the same bits for any thread count.
SPLIT_FROM = 20_000


class EdgeParts(NamedTuple):
    """A banded metric of closed components made of one symmetric 2 × 2 block per edge ``I``
    on its two vertices, ``[[p_I, q_I], [q_I, p_I]]``, plus the barycenter term ``β βᵀ`` per
    component: the parts of :class:`BandedSaddle` without triplets (the hs preconditioner's,
    :meth:`.hs_tree.HsOperator.preconditioner_edges`), its band filled by vertices in
    parallel (:func:`_fill_edges`)."""
    p: np.ndarray
    q: np.ndarray
    beta: np.ndarray


@nb.njit(cache=True)
def band_lu(ab, kl, ku):
    """LU factorization with partial pivoting of a band matrix, in place (LAPACK's ``gbtrf``
    scheme). Row ``r`` of ``ab`` (shape ``(n, kl + ku + 1)``) holds the columns
    ``r − kl … r + ku`` of the matrix (``A[r, j]`` at ``ab[r, j − r + kl]``); on return it
    holds row ``r`` of ``U``, the columns ``r … r + kl + ku`` (the row exchanges' fill-in
    widens ``U`` by ``kl``; ``U[r, j]`` at ``ab[r, j − r]``). Returns the pivot rows, the
    multipliers of every column (``(n, kl)``, contiguous for the solves) and the first zero
    pivot's index (−1: none)."""
    n = ab.shape[0]
    piv = np.empty(n, np.int64)
    mult = np.zeros((n, max(kl, 1)))
    return piv, mult, _lu_range(ab, kl, ku, piv, mult, 0, n)


@nb.njit(cache=True, parallel=True)
def band_lu_blocks(ab, kl, ku, cuts):
    """:func:`band_lu` of a block-diagonal band whose blocks are the rows ``cuts[b] …
    cuts[b + 1]`` (:func:`block_cuts`), the blocks in parallel: no pivot, multiplier or fill-in
    crosses a block's edge (the rows beyond it hold zeros in its columns), so the factors are
    the same bits as :func:`band_lu`'s. The first zero pivot is the least one found."""
    n = ab.shape[0]
    piv = np.empty(n, np.int64)
    mult = np.zeros((n, max(kl, 1)))
    nb_ = cuts.shape[0] - 1
    bad = np.full(nb_, -1, np.int64)
    for b in nb.prange(nb_):
        bad[b] = _lu_range(ab, kl, ku, piv, mult, cuts[b], cuts[b + 1])
    for b in range(nb_):
        if bad[b] >= 0:
            return piv, mult, bad[b]
    return piv, mult, -1


@nb.njit(cache=True, inline="always")
def _load_row(win, ab, r, kl, ku):
    """Row ``r`` of the band (``ab``'s input layout) into its place of the working window
    (``2 kl + ku + 1`` wide, the columns ``r − kl … r + kl + ku``; the fill-in's zero)."""
    w = win[r % win.shape[0]]
    for t in range(kl + ku + 1):
        w[t] = ab[r, t]
    for t in range(kl + ku + 1, w.shape[0]):
        w[t] = 0.0


@nb.njit(cache=True)
def _lu_range(ab, kl, ku, piv, mult, lo, n):
    """:func:`band_lu`'s elimination for the columns ``lo … n − 1``, with no row beyond
    ``n − 1``; the first zero pivot's index (−1: none). The ``kl + 1`` rows a column's
    elimination touches live in a small window (in the cache, with room for the fill-in), and
    a row goes back to ``ab`` as a row of ``U`` when its column is done, so ``ab`` needs no
    room for the fill-in (a third less memory than LAPACK's layout, whose rows are ``kl``
    wider); the same operations in the same order as on the wide layout, the same bits."""
    h = kl + 1
    win = np.empty((h, 2 * kl + ku + 1))
    for r in range(lo, min(n, lo + h)):
        _load_row(win, ab, r, kl, ku)
    # row r lives in win[r % h]; the place of row k + i is kh + i, less h past the end (a
    # division per row touched cost more than the elimination's products at 10⁴ vertices)
    kh = lo % h
    for k in range(lo, n):
        last = min(n - 1, k + kl)
        p = k
        ph = kh
        best = abs(win[kh, kl])
        i = kh
        for r in range(k + 1, last + 1):
            i += 1
            if i == h:
                i = 0
            v = abs(win[i, k - r + kl])
            if v > best:
                best = v
                p = r
                ph = i
        piv[k] = p
        if best == 0.0:
            return k
        jmax = min(n - 1, k + kl + ku)
        wk = win[kh]
        if p != k:
            wp = win[ph]
            for j in range(k, jmax + 1):
                a = wk[j - k + kl]
                wk[j - k + kl] = wp[j - p + kl]
                wp[j - p + kl] = a
        d = wk[kl]
        i = kh
        for r in range(k + 1, last + 1):
            i += 1
            if i == h:
                i = 0
            wr = win[i]
            f = wr[k - r + kl] / d
            mult[k, r - k - 1] = f
            if f != 0.0:
                # unsigned places: no wraparound test per entry, so the loop vectorizes
                a = np.uint64(k + 1 - r + kl)
                b = np.uint64(1 + kl)
                for t in range(np.uint64(jmax - k)):
                    wr[a + t] -= f * wk[b + t]
        for t in range(kl + ku + 1):  # row k of U, done: back to ab (its input was read)
            ab[k, t] = wk[t + kl]
        kh += 1
        if kh == h:
            kh = 0
        if k + h < n:
            _load_row(win, ab, k + h, kl, ku)
    return -1


def pack_factors(ab, mult, kl, ku, cuts):
    """The factors of :func:`band_lu_blocks` packed for the solves, in the memory of ``ab``
    and ``mult`` (overwritten; ``ab`` stays fit to be filled again by :func:`_fill`): every
    row keeps its entries up to its last nonzero, and ends at its block's end. Returns
    ``(U, L, uw, lw, uoff, loff)``: the packed rows of U (from the diagonal on) and of the
    multipliers, the rows' kept widths, and where each block's rows begin (then the end).
    FHW at 100 000 edges (hs, kl = ku = 11): U's rows keep 10.1 of 23 entries on average, the
    multipliers 8.6 of 11, so the solves, which stream the factors from memory, read 55 % of
    the bytes (docs/lab/repulsor.md, "Fewer bytes per band solve, fewer contact searches")."""
    nb_ = cuts.shape[0] - 1
    wide = kl + ku + 1 >= 65536
    uw = np.empty(ab.shape[0], np.int64 if wide else np.uint16)
    lw = np.empty(ab.shape[0], np.int64 if wide else np.uint16)
    uoff = np.empty(nb_ + 1, np.int64)
    loff = np.empty(nb_ + 1, np.int64)
    U, L = ab.reshape(-1), mult.reshape(-1)
    _pack(U, L, ab.shape[1], mult.shape[1], kl, ku, cuts, uw, lw, uoff, loff)
    return U[:uoff[-1]], L[:loff[-1]], uw, lw, uoff, loff


@nb.njit(cache=True)
def _pack(U, L, wu_, wl_, kl, ku, cuts, uw, lw, uoff, loff):
    """:func:`pack_factors`' copy, row after row (a row's packed place is never after its
    place in the band, so it reads nothing already overwritten)."""
    pu = pl = 0
    for b in range(cuts.shape[0] - 1):
        lo, hi = cuts[b], cuts[b + 1]
        uoff[b] = pu
        loff[b] = pl
        for k in range(lo, hi):
            uw[k] = _pack_row(U, k * wu_, min(kl + ku + 1, hi - k), 1, pu)
            pu += uw[k]
            lw[k] = _pack_row(L, k * wl_, min(kl, hi - 1 - k), 0, pl)
            pl += lw[k]
    uoff[cuts.shape[0] - 1] = pu
    loff[cuts.shape[0] - 1] = pl


@nb.njit(cache=True, inline="always")
def _pack_row(A, start, w, least, to):
    """The row of ``w`` entries at ``A[start]`` without its trailing zeros (at least
    ``least`` entries kept), copied to ``A[to]``; its kept width."""
    while w > least and A[start + w - 1] == 0.0:
        w -= 1
    for t in range(w):
        A[to + t] = A[start + t]
    return w


@nb.njit(cache=True)
def _solve_range(U, L, uw, lw, uo, lo_, piv, x, lo, n):
    """Solve with the packed factors (:func:`pack_factors`) of the block of unknowns
    ``lo … n − 1`` (its rows of U ending at ``uo``, its multipliers from ``lo_`` on), ``x``
    holding just those (``x[k − lo]``), in place. The operations of the solve on the band but
    for the products with the zeros past a row's last nonzero: the same values."""
    _forward_range(L, lw, lo_, piv, x, lo, n)
    _back_range(U, uw, uo, x, lo, n)


@nb.njit(cache=True)
def _forward_range(L, lw, lo_, piv, x, lo, n):
    """The row exchanges and multipliers of :func:`_solve_range` (``L⁻¹ P``)."""
    for k in range(lo, n):
        p = piv[k]
        if p != k:
            a = x[k - lo]
            x[k - lo] = x[p - lo]
            x[p - lo] = a
        xk = x[k - lo]
        w = lw[k]
        if xk != 0.0:
            a = np.uint64(k + 1 - lo)  # unsigned places: no wraparound test per entry
            b = np.uint64(lo_)
            for t in range(np.uint64(w)):
                x[a + t] -= L[b + t] * xk
        lo_ += w


@nb.njit(cache=True)
def _back_range(U, uw, uo, x, lo, n):
    """The back substitution of :func:`_solve_range` (``U⁻¹``)."""
    # back substitution: row k's products with the columns k + 2 … in eight running sums
    # (column k + 2 + 8 i + c always in sum c), added pairwise, and the column k + 1, solved just
    # before, subtracted last. One running sum is a chain of dependent additions whose latency
    # bounded the solve; with eight the row waits only for its neighbour's result. Other
    # rounding than one sum in column order (5.96e-16 of the solution's largest entry on a
    # random band); measured in docs/lab/repulsor.md, "Vectorized masking, faster band solves"
    for k in range(n - 1, lo - 1, -1):
        uo -= uw[k]
        w = uw[k] - 1  # the columns k + 1 … k + w
        o = k - lo  # (places as unsigned below: no wraparound test per read)
        s0 = s1 = s2 = s3 = s4 = s5 = s6 = s7 = 0.0
        j = 2
        while j + 7 <= w:
            s0 += U[np.uint64(uo + j)] * x[np.uint64(o + j)]
            s1 += U[np.uint64(uo + j + 1)] * x[np.uint64(o + j + 1)]
            s2 += U[np.uint64(uo + j + 2)] * x[np.uint64(o + j + 2)]
            s3 += U[np.uint64(uo + j + 3)] * x[np.uint64(o + j + 3)]
            s4 += U[np.uint64(uo + j + 4)] * x[np.uint64(o + j + 4)]
            s5 += U[np.uint64(uo + j + 5)] * x[np.uint64(o + j + 5)]
            s6 += U[np.uint64(uo + j + 6)] * x[np.uint64(o + j + 6)]
            s7 += U[np.uint64(uo + j + 7)] * x[np.uint64(o + j + 7)]
            j += 8
        # the rest in the same sums by column (a block's rows end where one band's go on with
        # zeros: the same bits, test_open_tree_runs)
        if j <= w:
            s0 += U[np.uint64(uo + j)] * x[np.uint64(o + j)]
        if j + 1 <= w:
            s1 += U[np.uint64(uo + j + 1)] * x[np.uint64(o + j + 1)]
        if j + 2 <= w:
            s2 += U[np.uint64(uo + j + 2)] * x[np.uint64(o + j + 2)]
        if j + 3 <= w:
            s3 += U[np.uint64(uo + j + 3)] * x[np.uint64(o + j + 3)]
        if j + 4 <= w:
            s4 += U[np.uint64(uo + j + 4)] * x[np.uint64(o + j + 4)]
        if j + 5 <= w:
            s5 += U[np.uint64(uo + j + 5)] * x[np.uint64(o + j + 5)]
        if j + 6 <= w:
            s6 += U[np.uint64(uo + j + 6)] * x[np.uint64(o + j + 6)]
        t = x[np.uint64(o)] - (((s0 + s1) + (s2 + s3)) + ((s4 + s5) + (s6 + s7)))
        if w >= 1:
            t -= U[np.uint64(uo + 1)] * x[np.uint64(o + 1)]
        x[np.uint64(o)] = t / U[np.uint64(uo)]


def band_solve(ab, mult, piv, kl, ku, b):
    """Solve with the factors of :func:`band_lu` for the columns of ``b`` (n, m), in place
    (the factors stay as they are: the solve packs copies)."""
    cuts = np.array([0, ab.shape[0]], np.int64)
    _band_solve(pack_factors(ab.copy(), mult.copy(), kl, ku, cuts) + (piv,), b)


@nb.njit(cache=True, parallel=True)
def _band_solve(F, b):
    """:func:`band_solve`'s columns in parallel, each alone: the same bits for any thread
    count."""
    U, L, uw, lw, uoff, loff, piv = F
    for c in nb.prange(b.shape[1]):
        x = np.ascontiguousarray(b[:, c])
        _solve_range(U, L, uw, lw, uoff[1], loff[0], piv, x, 0, x.shape[0])
        b[:, c] = x


@nb.njit(cache=True, parallel=True)
def _solve_fields(F, D, vert, G, lam, cuts, part, rev, work, sep, shift, bw, comp):
    """Band solves for right-hand sides given as fields ``G`` (m, N, 3) and edge values
    ``lam`` (m, N) (or (0, N): none), scaled by ``D`` on both sides, with the packed factors
    ``F`` (:func:`pack_factors`, then the pivots); the solutions' fields and edge multipliers
    (``G`` of shape (m, 0, 3): zero fields, without their memory). In parallel over the
    right-hand sides and the blocks of the band (``cuts``, :func:`block_cuts`: whole
    components, whose vertices are the places ``cuts / 4`` of ``vert``, the vertex at each
    place): each block's unknowns are solved alone, the same bits for any thread count.
    A split block's three parts (``part`` ≥ 0: its split, ``rev`` ≥ 0: the reversed half,
    row ``i`` at ``rev − i``) are joined by their separator (``sep``,
    :meth:`BandedSaddle._join_blocks`) between the two sweeps. ``work`` (m, 4N): room for
    the unknowns, every entry written before it is read (right-hand side ``q``, block ``b``
    in ``work[q, cuts[b] : cuts[b + 1]]``). ``shift`` (m, K, 3) (or (0, K, 3): none): the
    fields less ``bw[v] shift[q, comp[v]]`` as they are read (the projected barycenter rows,
    :meth:`BandedSaddle._solve_projected`)."""
    U, L, uw, lw, uoff, loff, piv = F
    m, n = G.shape[0], vert.shape[0]
    zero = G.shape[1] == 0
    shifted = shift.shape[0] > 0 and not zero
    X = np.empty((m, n, 3))
    Lm = np.empty((m, n))
    nblocks = cuts.shape[0] - 1
    for t in nb.prange(m * nblocks):
        q = t // nblocks
        b = t - q * nblocks
        lo, hi = cuts[b], cuts[b + 1]
        x = work[q, lo:hi]
        r = rev[b]
        for p in range(lo // 4, hi // 4):
            v = vert[p]
            for d in range(4):
                i = 4 * p + d
                if d < 3:
                    y = 0.0 if zero else G[q, v, d]
                    if shifted:
                        y -= bw[v] * shift[q, comp[v], d]
                    y *= D[i]
                else:
                    y = lam[q, v] * D[i] if lam.shape[0] > 0 else 0.0
                x[(i if r < 0 else r - i) - lo] = y
        _forward_range(L, lw, loff[b], piv, x, lo, hi)
        if part[b] < 0:
            _back_range(U, uw, uoff[b + 1], x, lo, hi)
            _unload(X, Lm, q, x, D, vert, lo, hi, r)
    nsplit = sep[0].shape[0]
    if nsplit == 0:
        return X, Lm
    for t in nb.prange(m * nsplit):
        q = t // nsplit
        _join(work[q], sep, t - q * nsplit)
    for t in nb.prange(m * nblocks):
        q = t // nblocks
        b = t - q * nblocks
        if part[b] >= 0:
            lo, hi = cuts[b], cuts[b + 1]
            x = work[q, lo:hi]
            _back_range(U, uw, uoff[b + 1], x, lo, hi)
            _unload(X, Lm, q, x, D, vert, lo, hi, rev[b])
    return X, Lm


@nb.njit(cache=True)
def _unload(X, Lm, q, x, D, vert, lo, hi, r):
    """The solved unknowns of a block (``x``, rows ``lo … hi − 1``, reversed from ``r`` ≥ 0)
    back to fields and edge values, unscaled."""
    for p in range(lo // 4, hi // 4):
        v = vert[p]
        for d in range(4):
            i = 4 * p + d
            y = x[(i if r < 0 else r - i) - lo] * D[i]
            if d < 3:
                X[q, v, d] = y
            else:
                Lm[q, v] = y


@nb.njit(cache=True)
def _join(x, sep, k):
    """Split ``k``'s separator between the sweeps (``x`` after the forward sweeps, the rows'
    own places): its unknowns ``σ = S̃⁻¹ (f_S − G_A y_A − G_B y_B)`` from the last rows of the
    two halves, then those rows less ``H σ``, ready for the back substitution (the names of
    :func:`_split_band`)."""
    splits, Sinv, GA, HA, GB, HB = sep
    c, e, a, b = splits[k, 0], splits[k, 1], splits[k, 2], splits[k, 3]
    s = e - c
    w = GA.shape[2]
    f = np.empty(s)
    for i in range(s):
        y = x[c + i]
        for t in range(w):
            y -= GA[k, i, t] * x[a + t] + GB[k, i, t] * x[b + t]
        f[i] = y
    for i in range(s):
        y = 0.0
        for j in range(s):
            y += Sinv[k, i, j] * f[j]
        x[c + i] = y
    for t in range(w):
        ya = yb = 0.0
        for j in range(s):
            ya += HA[k, t, j] * x[c + j]
            yb += HB[k, t, j] * x[c + j]
        x[a + t] -= ya
        x[b + t] -= yb


def _separator_shape(kl: int) -> tuple[int, int]:
    """``(s, w)`` of a split band of half-bandwidth ``kl``: the separator's rows (whole
    vertices, more than ``kl``) and the halves' windows next to it (``2 kl`` rows)."""
    return 4 * ((kl + 4) // 4), 2 * kl


@nb.njit(cache=True)
def _split_band(ab, kl, c, e, hi, w):
    """Cut the block of the band (``kl`` = ``ku``) that ends at row ``hi`` at its rows
    ``c … e − 1`` (the separator ``S``, more than ``kl`` rows, so that no entry joins the half
    before, ``A``, to the half after, ``B``), in place: the separator's rows become the
    identity (a block of their own), the entries that join it to the halves are taken out,
    and ``B`` is reversed (row and column ``i`` at ``e + hi − 1 − i``, a band again), so that
    both halves meet the separator in their last ``w`` = 2 ``kl`` rows, where the elimination
    ends: what the separator asks of a factored half is there alone (nested dissection of a
    chain). Returns ``S`` (s, s) and the couplings over those windows, ``F_A``, ``F_B``
    (separator rows × window columns) and ``E_A``, ``E_B`` (window rows × separator columns),
    the windows' places counted from their first row."""
    s = e - c
    kk = 2 * kl
    S = np.zeros((s, s))
    FA = np.zeros((s, w))
    EA = np.zeros((w, s))
    FB = np.zeros((s, w))
    EB = np.zeros((w, s))
    for i in range(s):
        r = c + i
        for t in range(kk + 1):
            j = r + t - kl
            y = ab[r, t]
            ab[r, t] = 0.0
            if c <= j < e:
                S[i, j - c] = y
            elif c - w <= j < c:
                FA[i, j - c + w] = y
            elif e <= j < e + w:
                FB[i, e + w - 1 - j] = y  # column j of B at e + hi − 1 − j, window hi − w …
        ab[r, kl] = 1.0
    for r in range(c - kl, c):
        for t in range(kk + 1):
            j = r + t - kl
            if j >= c:
                EA[r - c + w, j - c] = ab[r, t]
                ab[r, t] = 0.0
    for r in range(e, e + kl):
        for t in range(kk + 1):
            j = r + t - kl
            if j < e:
                EB[e + w - 1 - r, j - c] = ab[r, t]
                ab[r, t] = 0.0
    _reverse_rows(ab, e, hi, kk)
    return S, FA, EA, FB, EB


@nb.njit(cache=True, parallel=True)
def _reverse_rows(ab, e, hi, kk):
    """Rows ``e … hi − 1`` of the band (``kk + 1`` wide) in reverse order, each row's entries
    too: the band of the reversed unknowns (:func:`_split_band`; ``hi − e`` even)."""
    for k in nb.prange((hi - e) // 2):
        i, j = e + k, hi - 1 - k
        for t in range(kk + 1):
            y = ab[i, t]
            ab[i, t] = ab[j, kk - t]
            ab[j, kk - t] = y


@nb.njit(cache=True)
def _window(ab, mult, piv, kl, a, b, F, E):
    """For the factored half ending at row ``b`` (:func:`band_lu_blocks`, ``ab`` holding U)
    and its couplings over the window ``a … b − 1`` (:func:`_split_band`): ``G = F U⁻¹`` and
    ``H = L⁻¹ P E``, exact on the window alone (F's columns and E's rows lie within ``kl``
    of its end, and neither sweep carries them further than ``kl`` back)."""
    w = b - a
    s = E.shape[1]
    H = E.copy()
    for k in range(a, b):
        p = piv[k]
        if p != k:
            for j in range(s):
                y = H[k - a, j]
                H[k - a, j] = H[p - a, j]
                H[p - a, j] = y
        for r in range(k + 1, min(b, k + kl + 1)):
            f = mult[k, r - k - 1]
            if f != 0.0:
                for j in range(s):
                    H[r - a, j] -= f * H[k - a, j]
    G = np.empty((s, w))
    for j in range(w):
        for q in range(s):
            y = F[q, j]
            for i in range(max(0, j - 2 * kl), j):
                y -= G[q, i] * ab[a + i, j - i]
            G[q, j] = y / ab[a + j, 0]
    return G, H


@nb.njit(cache=True)
def _band_clear_at(ab, kl, ku, b):
    """Whether the band holds only zeros across row and column ``b``: nothing in the rows
    above in columns ≥ ``b``, nothing in the rows below in columns < ``b``."""
    n = ab.shape[0]
    for r in range(max(0, b - ku), b):
        for j in range(b, min(n - 1, r + ku) + 1):
            if ab[r, j - r + kl] != 0.0:
                return False
    for r in range(b, min(n, b + kl)):
        for j in range(max(0, r - kl), b):
            if ab[r, j - r + kl] != 0.0:
                return False
    return True


@nb.njit(cache=True)
def block_cuts(ab, kl, ku, starts, least):
    """The rows where the band splits into blocks that share no entry: of the components'
    first rows ``4 starts`` those where the band holds only zeros across (checked), merged
    into blocks of at least ``least`` rows; ``[0, …, n]``."""
    n = ab.shape[0]
    cuts = np.empty(starts.shape[0] + 1, np.int64)
    cuts[0] = 0
    nc = 1
    for c in range(1, starts.shape[0]):
        b = 4 * starts[c]
        if b <= 0 or b >= n or b - cuts[nc - 1] < least:
            continue
        if _band_clear_at(ab, kl, ku, b):
            cuts[nc] = b
            nc += 1
    if n - cuts[nc - 1] < least and nc > 1:
        nc -= 1  # the last block too small: merged with the one before
    cuts[nc] = n
    return cuts[:nc + 1].copy()


def zigzag_positions(layout: Layout) -> np.ndarray:
    """Place of every vertex in the band ordering: per component ``s, e−1, s+1, e−2, …``."""
    pos = np.empty(layout.n, np.int64)
    for c in range(layout.k):
        s, e = int(layout.starts[c]), int(layout.starts[c + 1])
        a = np.arange(e - s)
        v = np.where(a % 2 == 0, s + a // 2, e - 1 - a // 2)
        pos[v] = s + a
    return pos


@nb.njit(cache=True)
def _fill(rows, cols, vals, pos, anchors, mu, T, ln, nxt, has_row, fixed, kl, ku, ab):
    """The band of ``D [[A_band ⊗ I₃ + μ springs, C_eᵀ], [C_e, 0]] D`` in the storage of
    :func:`band_lu` (4 unknowns per vertex: x, y, z and the multiplier of its edge) and the
    diagonal ``D`` (4N,). ``D`` balances the blocks: h2's entries grow like N³ and C_e's like
    N, and without it pivoting on the unscaled band lost the constraints at 100 000 edges.
    ``ab``: the memory of the band (4N, kl + ku + 1), zeros (:func:`_zero`).

    Edge slots without a row (``has_row`` False: an open component's dummy edge, an edge
    between two pins) and pinned vertices (``fixed``) are eliminated: their unknowns get the
    row ``x = 0`` (identity, nothing coupled), so that the band is the system of the free
    unknowns. With every slot a row and nothing fixed it adds the same terms in the same
    order as before the two cases shared this function (closed iterates unchanged to the bit).
    """
    n = pos.shape[0]
    diag = np.zeros(n)
    for t in range(rows.shape[0]):
        if rows[t] == cols[t]:
            diag[rows[t]] += vals[t]
    for c in range(anchors.shape[0]):
        diag[anchors[c]] += mu[c]
    D = np.empty(4 * n)
    for v in range(n):
        for d in range(3):
            D[4 * pos[v] + d] = 1.0 if fixed[v] else 1.0 / np.sqrt(diag[v])
    for i in range(n):
        if has_row[i]:
            j = nxt[i]
            s = (diag[i] ** -1.0 + diag[j] ** -1.0) / (ln[i] * ln[i])
            D[4 * pos[i] + 3] = 1.0 / np.sqrt(s)
        else:
            D[4 * pos[i] + 3] = 1.0
    for t in range(rows.shape[0]):
        if fixed[rows[t]] or fixed[cols[t]]:
            continue
        r0 = 4 * pos[rows[t]]
        c0 = 4 * pos[cols[t]]
        for d in range(3):
            ab[r0 + d, c0 - r0 + kl] += vals[t] * D[r0 + d] * D[c0 + d]
    for c in range(anchors.shape[0]):
        r0 = 4 * pos[anchors[c]]
        for d in range(3):
            ab[r0 + d, kl] += mu[c] * D[r0 + d] * D[r0 + d]
    for v in range(n):
        if fixed[v]:
            for d in range(3):
                ab[4 * pos[v] + d, kl] = 1.0
    for i in range(n):
        lam = 4 * pos[i] + 3
        if not has_row[i]:
            ab[lam, kl] = 1.0
            continue
        xi = 4 * pos[i]
        j = nxt[i]
        xj = 4 * pos[j]
        for d in range(3):
            t = T[i, d] / ln[i] * D[lam]
            if not fixed[i]:
                a = -t * D[xi + d]  # d(log l_i)/d(x_i)
                ab[lam, xi + d - lam + kl] += a
                ab[xi + d, lam - xi - d + kl] += a
            if not fixed[j]:
                b = t * D[xj + d]  # d(log l_i)/d(x_{i+1})
                ab[lam, xj + d - lam + kl] += b
                ab[xj + d, lam - xj - d + kl] += b
    return D


@nb.njit(cache=True, parallel=True)
def _fill_edges(p, q, pos, spring, T, ln, nxt, prv, kl, ku, ab):
    """:func:`_fill` for :class:`EdgeParts` (closed components, every edge a row, nothing
    fixed; ``spring`` (N,): the spring's stiffness at each vertex, 0 but at the anchors):
    every vertex's four rows written by one thread from its two edges, the vertices in
    parallel. The band's entries are the same sums as :func:`_fill`'s of the same metric's
    triplets, added in another order. ``ab`` zeros (:func:`_zero`)."""
    n = pos.shape[0]
    diag = np.empty(n)
    for v in nb.prange(n):
        diag[v] = p[prv[v]] + p[v] + spring[v]
    D = np.empty(4 * n)
    for v in nb.prange(n):
        r0 = 4 * pos[v]
        w = 1.0 / np.sqrt(diag[v])
        for d in range(3):
            D[r0 + d] = w
        s = (diag[v] ** -1.0 + diag[nxt[v]] ** -1.0) / (ln[v] * ln[v])
        D[r0 + 3] = 1.0 / np.sqrt(s)
    for v in nb.prange(n):
        a = prv[v]
        b = nxt[v]
        r0 = 4 * pos[v]
        ra = 4 * pos[a]
        rb = 4 * pos[b]
        lam = r0 + 3  # the multiplier of edge v (from v to b)
        for d in range(3):
            x = r0 + d
            ab[x, kl] += (p[a] + p[v] + spring[v]) * D[x] * D[x]
            ab[x, ra + d - x + kl] += q[a] * D[x] * D[ra + d]
            ab[x, rb + d - x + kl] += q[v] * D[x] * D[rb + d]
            # d(log l_v)/d(x_v) = −T_v / l_v, d(log l_a)/d(x_v) = T_a / l_a
            ab[x, lam - x + kl] += -T[v, d] / ln[v] * D[lam] * D[x]
            ab[x, ra + 3 - x + kl] += T[a, d] / ln[a] * D[ra + 3] * D[x]
            t = T[v, d] / ln[v] * D[lam]
            ab[lam, x - lam + kl] += -t * D[x]
            ab[lam, rb + d - lam + kl] += t * D[rb + d]
    return D


@nb.njit(cache=True, parallel=True)
def _zero(ab):
    """``ab[:] = 0`` by rows in parallel: a fresh array's first touch (its page faults, the
    kernel clearing the pages) on every thread. FHW at 10⁶ vertices, 2 threads: the fine band's
    736 MB took 0.9-1.3 s to clear in one thread, 0.6-1.0 s in two (docs/lab/repulsor.md,
    "The band solver's correction without BLAS, its band filled in parallel")."""
    for r in nb.prange(ab.shape[0]):
        for t in range(ab.shape[1]):
            ab[r, t] = 0.0


@nb.njit(cache=True)
def _band_product(rows, cols, vals, V):
    """``A_band V`` for an (N, 3) field."""
    out = np.zeros_like(V)
    for t in range(rows.shape[0]):
        i = rows[t]
        j = cols[t]
        for d in range(3):
            out[i, d] += vals[t] * V[j, d]
    return out


def _capacitance(W: np.ndarray, mu: float) -> np.ndarray:
    """The inverse of one component's 12 × 12 capacitance matrix (spring ``mu``, barycenter
    term, barycenter rows, their multipliers) given ``W = Uᵀ A⁻¹ U`` (9, 9) of its columns."""
    Sinv = np.zeros((12, 12))
    Sinv[0:3, 0:3] = -np.eye(3) / mu
    Sinv[3:6, 3:6] = np.eye(3)
    Sinv[6:9, 6:9] = np.eye(3)
    Sinv[6:9, 9:12] = np.eye(3)
    Sinv[9:12, 6:9] = np.eye(3)
    Sinv[0:9, 0:9] += W
    Sinv[9:12, 9:12] += np.eye(3)
    return np.linalg.inv(Sinv)


class BandedSaddle:
    """The saddle-point solver of a banded metric at one iterate (see the module's text).

    ``parts``: the metric's banded part as triplets ``(rows, cols, vals)`` over vertices and
    its barycenter weights ``beta`` (N,) (``B = β βᵀ`` per component), from
    :func:`metrics.banded_parts`; ``jac``: the constraint Jacobian (edge and barycenter rows);
    ``recycle``: the previous iterate's solver, whose memory this one takes over (it must
    not be used afterwards); ``product=False``: only the factors are kept (:meth:`_solve`,
    :meth:`solve_many`, :meth:`pseudo_inverse`), not the metric's triplets that
    :meth:`metric_product` and the refinement of :meth:`solve` need: a preconditioner's use
    (the hs solver's, whose triplets were 0.29 GB at 10⁶ vertices). ``barycenter_term=False``
    (with ``product=False``): the band's metric without ``B``, a correction of rank 9 per
    component and six band solves per iterate instead of nine: the same fields ``u`` for any
    right-hand side, the same multipliers where ``r = 0`` (``B``'s range lies in ``Cᵀ``'s;
    module text); with ``B`` only for a metric whose products include it.
    ``projected=True`` (with ``barycenter_term=False``): the barycenter rows by projection,
    no correction (:meth:`_solve_projected`): the exact saddle-point solve of the band's
    metric with its translations minimized out, for which the hs operator's Laplacians do not
    charge either; no column solves at the build, none of their fields read per solve.
    """

    #: Whether the barycenter rows are projected (:meth:`_solve_projected`), not bordered.
    projected = False

    def __init__(self, parts, jac: Jacobian, recycle: BandedSaddle | None = None,
                 product: bool = True, barycenter_term: bool = True, projected: bool = False):
        if isinstance(parts, EdgeParts) and (product or jac.con.layout.has_open):
            raise ValueError("edge parts are for a preconditioner of closed components "
                             "(product=False)")
        if product and not barycenter_term:
            raise ValueError("the barycenter term can be left out of a preconditioner only "
                             "(product=False)")
        con = jac.con
        if not (con.edge_lengths and con.barycenter) or con.pinned is not None:
            raise ValueError("the banded saddle-point solver needs the edge-length and "
                             "barycenter constraints and no pinned vertices")
        if projected and barycenter_term:
            raise ValueError("projected barycenter rows are for a preconditioner without the "
                             "barycenter term")
        lay = con.layout
        self.layout, self.jac = lay, jac
        self.projected = projected
        self.rows, self.cols, self.vals = parts[:3] if product else (None, None, None)
        T, inv_l = jac.edge_fields()
        n = lay.n
        self._factor(parts, np.asarray(lay.starts[:-1], np.int64), T, 1.0 / inv_l,
                     np.ones(n, np.bool_), np.zeros(n, np.bool_), recycle)
        recycle = None  # its band is overwritten now: it must not be used again
        if projected:
            starts = np.asarray(lay.starts, np.int64)
            self.chunks = _chunks(starts)
            self.bsum = _component_sums(jac.b[:, None], self.chunks, lay.k)[:, 0]
            return
        U = self._columns(parts[-1] if barycenter_term else None, jac.barycenter_fields(),
                          np.arange(lay.k, dtype=np.int64))
        for c in range(lay.k):
            self.cap[c] = _capacitance(self._gram(U, c), self.mu[c])

    def _columns(self, beta, F, brow):
        """The correction's columns, every component's in one field per column (the
        components are independent blocks of the band: nine band solves per iterate for any
        number of them): spring at each component's first vertex (3), barycenter term (3),
        barycenter rows (3; ``F`` their rows as fields, of the components ``c`` with
        ``brow[c]`` ≥ 0 in order), and their band
        solves ``Z``, ``Zlam``; ``beta`` None: no barycenter term, its three columns left
        out (``zcol``: the places of the columns built among the nine). Only what
        :func:`_correction` reads of the columns is kept: ``beta`` and the barycenter rows'
        fields (a third of the columns' memory); returns the columns built (6 or 9, N, 3) for
        the capacitances (:meth:`_gram`)."""
        lay = self.layout
        n = lay.n
        self.zcol = np.array([0, 1, 2, 6, 7, 8] if beta is None else range(9), np.int64)
        U = np.zeros((self.zcol.size, n, 3))
        f = U.shape[0] - 3  # the barycenter rows' first column
        for d in range(3):
            U[d, lay.starts[:-1][brow >= 0], d] = 1.0
            if beta is not None:
                U[3 + d, :, d] = beta
        for c in np.flatnonzero(brow >= 0):
            s = slice(lay.starts[c], lay.starts[c + 1])
            for d in range(3):
                U[f + d, s] += F[3 * brow[c] + d, s]
        self.Z, self.Zlam = self._band_inverse(U)
        self.beta = np.ascontiguousarray(np.zeros(0) if beta is None else beta, float)
        self.F = U[f:].copy()
        self.brow = brow
        self.cap = np.zeros((lay.k, 12, 12))
        self.chunks = _chunks(np.asarray(lay.starts, np.int64))
        return U

    def _gram(self, U: np.ndarray, c: int) -> np.ndarray:
        """``Uᵀ A⁻¹ U`` (9, 9) of component ``c``'s columns ``U`` (:meth:`_columns`), zero
        where a column was left out."""
        s = slice(int(self.layout.starts[c]), int(self.layout.starts[c + 1]))
        W = np.zeros((9, 9))
        q = self.zcol.size
        W[np.ix_(self.zcol, self.zcol)] = U[:, s].reshape(q, -1) @ self.Z[:, s].reshape(q, -1).T
        return W

    def _factor(self, parts, anchors, T, ln, has_row, fixed, recycle):
        """The band of the iterate from ``parts``, the metric's triplets ``(rows, cols, vals,
        beta)`` (:func:`_fill`: ``has_row``, ``fixed`` as there) or an :class:`EdgeParts`
        (:func:`_fill_edges`), with a
        spring at each of ``anchors`` as stiff as the metric's own diagonal there, in the
        memory of ``recycle``'s band when it fits (125 MB at 100 000 edges with h2: a fresh
        array costs its page faults again), and its LU factors, the band shrunk to them from
        :data:`COMPACT_FROM` vertices on (``ab`` None then); returns the metric's diagonal
        (N,)."""
        lay = self.layout
        pos = zigzag_positions(lay)
        self.pos = pos
        self.vert = np.empty_like(pos)  # the vertex at each place (the solves' loop order)
        self.vert[pos] = np.arange(lay.n)
        edges = parts if isinstance(parts, EdgeParts) else None
        rows, cols, vals = (None, None, None) if edges else parts[:3]
        width = 0 if edges else int(np.max(np.abs(pos[rows] - pos[cols]), initial=0))
        width = max(width, int(np.max(np.abs(pos[lay.nxt] - pos), initial=0)))
        self.kl = self.ku = 4 * width + 3
        if edges:
            diag = edges.p[lay.prv] + edges.p
        else:
            diag = np.zeros(lay.n)
            np.add.at(diag, rows[rows == cols], vals[rows == cols])
        self.anchors, self.mu = anchors, diag[anchors]
        if self.projected:
            self.mu = self.mu * PROJECTED_SPRING
        shape = (4 * lay.n, self.kl + self.ku + 1)
        reuse = recycle is not None and recycle.ab is not None and recycle.ab.shape == shape
        ab = recycle.ab if reuse else np.empty(shape)
        _zero(ab)
        if edges:
            spring = np.zeros(lay.n)
            spring[anchors] = self.mu
            self.D = _fill_edges(edges.p, edges.q, pos, spring, T, ln, lay.nxt, lay.prv,
                                 self.kl, self.ku, ab)
        else:
            self.D = _fill(rows, cols, vals, pos, anchors, self.mu, T, ln, lay.nxt, has_row,
                           fixed, self.kl, self.ku, ab)
        # blocks of whole components, some 64 at most (none for one component)
        cuts = block_cuts(ab, self.kl, self.ku, np.asarray(lay.starts[:-1], np.int64),
                          max(4 * lay.n // _BLOCKS, 1))
        plain = bool(has_row.all()) and not fixed.any()
        raw = self._split_blocks(ab, cuts, plain)
        piv, mult, bad = band_lu_blocks(ab, self.kl, self.ku, self.cuts)
        if bad >= 0:
            raise np.linalg.LinAlgError(f"singular band at unknown {bad}")
        self._join_blocks(ab, mult, piv, raw)
        self.ab = ab
        U, *rest = pack_factors(ab, mult, self.kl, self.ku, self.cuts)
        if lay.n >= COMPACT_FROM:
            # U is packed at the start of ab: the rest goes back to the system (a realloc to
            # the smaller size, no copy), and the next iterate's band is a fresh array
            size = U.shape[0]
            del U  # no view of ab may outlive the resize
            ab.resize(size, refcheck=False)
            U, self.ab = ab, None
        self.factors = (U, *rest, piv)
        return diag

    def _split_blocks(self, ab, cuts, plain: bool):
        """Cut every block of :data:`SPLIT_FROM` vertices or more in two halves and a
        separator (:func:`_split_band`, in place on the filled band ``ab``): sets ``cuts``
        (the halves and the separator blocks of their own), ``part`` (per block its split or
        −1) and ``rev`` (the reversed halves' ``e + hi − 1``, else −1); returns per
        split ``(c, e, hi, S, F_A, E_A, F_B, E_B)``. Only bands of closed components with
        every row (``plain``): an eliminated unknown's row could leave a half without a
        multiplier's vertex."""
        kl = self.kl
        s, w = _separator_shape(kl)
        new, part, rev, raw = [0], [], [], []
        for b in range(cuts.shape[0] - 1):
            lo, hi = int(cuts[b]), int(cuts[b + 1])
            if not (plain and kl == self.ku and hi - lo >= 4 * SPLIT_FROM):
                new.append(hi)
                part.append(-1)
                rev.append(-1)
                continue
            c = lo + 4 * ((hi - lo) // 8)
            e = c + s
            raw.append((c, e, hi, *_split_band(ab, kl, c, e, hi, w)))
            new += [c, e, hi]
            part += [len(raw) - 1] * 3
            rev += [-1, -1, e + hi - 1]
        self.cuts = np.array(new, np.int64)
        self.part = np.array(part, np.int64)
        self.rev = np.array(rev, np.int64)
        return raw

    def _join_blocks(self, ab, mult, piv, raw) -> None:
        """What each split's separator needs between the sweeps (:func:`_join`), from the
        factored halves: ``(splits, S̃⁻¹, G_A, H_A, G_B, H_B)`` with ``S̃ = S − G_A H_A −
        G_B H_B`` the separator's Schur complement (s × s, inverted by numpy: a few rows)."""
        kl = self.kl
        s, w = _separator_shape(kl)
        k = len(raw)
        splits = np.empty((k, 4), np.int64)
        Sinv = np.empty((k, s, s))
        GA, GB = np.empty((k, s, w)), np.empty((k, s, w))
        HA, HB = np.empty((k, w, s)), np.empty((k, w, s))
        for t, (c, e, hi, S, FA, EA, FB, EB) in enumerate(raw):
            GA[t], HA[t] = _window(ab, mult, piv, kl, c - w, c, FA, EA)
            GB[t], HB[t] = _window(ab, mult, piv, kl, hi - w, hi, FB, EB)
            Sinv[t] = np.linalg.inv(S - GA[t] @ HA[t] - GB[t] @ HB[t])
            splits[t] = (c, e, c - w, hi - w)
        self.sep = (splits, Sinv, GA, HA, GB, HB)

    def release(self) -> None:
        """Let go of everything but the band's memory, which the next iterate's solver takes
        over (``recycle``): built while this one was still whole, the hs solver of a 7_2 at
        100 000 edges held two iterates' operators, coarse levels and band fields at once,
        about 240 MB more at the peak. The solver is unusable afterwards."""
        self.__dict__ = {"ab": self.ab}  # None when compacted (COMPACT_FROM)

    def _band_inverse(self, G, lam=None, shift=None):
        """Band solve for right-hand sides given as fields ``G`` (m, N, 3) and edge values
        ``lam`` (m, N): the core solution's fields and edge multipliers (``shift`` (m, K, 3):
        the fields less ``b ⊗ shift`` per component, :func:`_solve_fields`)."""
        G = np.ascontiguousarray(G, dtype=np.float64)
        lam = np.zeros((0, G.shape[1])) if lam is None else np.ascontiguousarray(lam, float)
        m, rows = G.shape[0], self.D.shape[0]
        if m != 1:
            work = np.empty((m, rows))
        else:
            # one right-hand side (every Krylov iteration's): the same room every time. A fresh
            # array of the 4N unknowns (32 MB at 10⁶ vertices, past glibc's mmap threshold)
            # came as new pages from the kernel at every solve: 616 000-646 000 page faults in
            # the 158 solves of relax(max_iter=1) at 10⁶, 268 000-283 000 with this, and
            # 3-4 % less time in them (docs/lab/repulsor.md, "The same machine with transparent
            # huge pages on `madvise`, …")
            work = getattr(self, "_work", None)
            if work is None:
                work = self._work = np.empty((1, rows))
        if shift is None:
            shift, bw, comp = _NO_SHIFT, np.zeros(0), np.zeros(0, np.int64)
        else:
            bw, comp = self.jac.b, self.layout.comp
        return _solve_fields(self.factors, self.D, self.vert, G, lam, self.cuts, self.part,
                             self.rev, work, self.sep, shift, bw, comp)

    def solve(self, g: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(u, λ)`` of ``[[G, Cᵀ], [C, 0]] [u; λ] = [g; r]`` (λ: edge rows, then three
        barycenter rows per component, the order of ``constraints.residual``), with one step
        of iterative refinement against the products with ``A`` and ``C``: on random systems
        of a 200-edge trefoil, a 300-edge FHW unknot and a three-ring link (l2, h1, h2) it
        took the worst relative residuals (first rows / constraint rows) from 2.2e-10 /
        8.6e-9 to 5.4e-11 / 1.6e-8, the dense solver's being 8.5e-7 / 2.6e-7."""
        u, lam = self._solve(g, r)
        du, dlam = self._solve(g - self.metric_product(u) - self.jac.rmatvec(lam),
                               r - self.jac.matvec(u))
        return u + du, lam + dlam

    def _solve(self, g: np.ndarray | None, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`solve` without its refinement; ``g`` None: zero."""
        if self.projected:
            return self._solve_projected(g, r)
        n = self.layout.n
        G = np.empty((1, 0, 3)) if g is None else g[None]
        (u,), (lam_e,) = self._band_inverse(G, r[None, :n])  # fresh arrays: corrected in place
        lam_b = np.asarray(r[n:], float).reshape(-1, 3).copy()
        self._correct(u, lam_b, u, lam_e, lam_b)
        return u, np.concatenate([lam_e, lam_b.ravel()])

    def _correct(self, y, yb, u, lam_e, lam_b) -> None:
        """The low-rank correction of a band solve ``y`` (barycenter rows' right-hand sides
        ``yb``) onto ``u``, ``lam_e``, ``lam_b``, in place (:func:`_correction`)."""
        _correction(y, yb, self.beta, self.F, self.Z, self.Zlam, self.zcol,
                    self.layout.starts, self.brow, self.cap, self.chunks, u, lam_e, lam_b)

    def _solve_projected(self, g: np.ndarray | None, r: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_solve` with projected barycenter rows (``projected``). On ``ker C_e``
        a barycenter row is ``Σ b_v u_v`` (over ``scale``), and translations keep every edge
        length, so: the fields' translations are taken out (``g − b Σg / Σb``, no ``Cᵀ`` of
        an edge row has one), the band solves with the edge rows, the solution is translated
        onto the barycenter rows, and ``Σg`` goes to their multipliers (less its part along
        the edge rows). That is the saddle-point solve of ``H′ = min over translations of the
        band's metric`` (spring included), symmetric, into ``ker C``."""
        lay, jac = self.layout, self.jac
        n, k = lay.n, lay.k
        scale = jac.con.scale
        if g is None:
            G, shift, s = np.empty((1, 0, 3)), None, None
        else:
            s = _component_sums(g, self.chunks, k)
            G, shift = g[None], (s / self.bsum[:, None])[None]
        (u,), (lam_e,) = self._band_inverse(G, r[None, :n], shift)
        r_b = np.asarray(r[n:], float).reshape(k, 3)
        mu_b = np.zeros((k, 3)) if s is None else s * (scale / self.bsum[:, None])
        _translate(u, lam_e, jac.b, jac.M, jac.ln, np.ascontiguousarray(r[:n], float), r_b,
                   mu_b, self.bsum, scale, lay.comp, self.chunks, s is not None)
        return u, np.concatenate([lam_e, mu_b.ravel()])

    def solve_many(self, G: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_solve` (no refinement) for many right-hand sides at once: fields ``G``
        (m, N, 3) and rows ``R`` (m, N + 3K); one parallel band solve for all of them."""
        if self.projected:
            sols = [self._solve(G[q], R[q]) for q in range(G.shape[0])]
            return np.stack([u for u, _ in sols]), np.stack([lam for _, lam in sols])
        n = self.layout.n
        m = G.shape[0]
        U, Le = self._band_inverse(G, R[:, :n])
        Lb = np.asarray(R[:, n:], float).reshape(m, -1, 3).copy()
        for q in range(m):
            self._correct(U[q], Lb[q], U[q], Le[q], Lb[q])
        return U, np.concatenate([Le, Lb.reshape(m, -1)], axis=1)

    def pseudo_inverse(self, phi: np.ndarray) -> np.ndarray:
        """``G⁻¹Cᵀ(CG⁻¹Cᵀ)⁻¹ φ``: the ``u`` of :meth:`solve` with ``g = 0``, without its
        refinement step (the back-projection's Newton iteration corrects what is left, and
        a band solve is most of an iteration's solve time at 100 000 edges)."""
        return self._solve(None, phi)[0]

    def metric_product(self, V: np.ndarray) -> np.ndarray:
        """``A V`` for an (N, 3) field (band and barycenter term)."""
        if self.rows is None:
            raise RuntimeError("this band solver keeps its factors only (product=False)")
        out = _band_product(self.rows, self.cols, self.vals, np.ascontiguousarray(V, float))
        lay = self.layout
        for c in range(lay.k):
            s = slice(lay.starts[c], lay.starts[c + 1])
            out[s] += np.outer(self.beta[s], self.beta[s] @ V[s])
        return out


_NO_SHIFT = np.zeros((0, 1, 3))


def _chunks(starts: np.ndarray) -> np.ndarray:
    """The pieces of the components for the parallel sums (:func:`_correction`,
    :func:`_component_sums`): ``(first, end, component)``, at most ``_CHUNK`` vertices each."""
    return np.array([(a, min(a + _CHUNK, starts[c + 1]), c)
                     for c in range(starts.shape[0] - 1)
                     for a in range(int(starts[c]), int(starts[c + 1]), _CHUNK)],
                    np.int64).reshape(-1, 3)


@nb.njit(cache=True, parallel=True)
def _component_sums(Y, chunks, k):
    """``Σ_v Y[v]`` per component (K, m) over the pieces ``chunks`` in parallel, their sums
    added in order: the same bits for any thread count."""
    nch, m = chunks.shape[0], Y.shape[1]
    part = np.zeros((nch, m))
    for h in nb.prange(nch):
        for v in range(chunks[h, 0], chunks[h, 1]):
            for d in range(m):
                part[h, d] += Y[v, d]
    out = np.zeros((k, m))
    for h in range(nch):
        for d in range(m):
            out[chunks[h, 2], d] += part[h, d]
    return out


@nb.njit(cache=True, parallel=True)
def _translate(u, lam_e, b, M, ln, r_e, r_b, mu_b, bsum, scale, comp, chunks, multipliers):
    """:meth:`BandedSaddle._solve_projected` after the band solve, in place: ``u`` translated
    per component onto its barycenter rows ``r_b`` (each row ``(Σ b_v u_v + Σ_I M_I l_I
    r_e,I) / scale`` with the edge rows ``r_e`` solved), and with ``multipliers`` the edge
    multipliers less the barycenter multipliers' ``mu_b`` part along them (the rows' ``M``
    terms, :func:`constraints._rmatvec`). Sums by pieces in order: any thread count's bits."""
    nch, k = chunks.shape[0], bsum.shape[0]
    part = np.zeros((nch, 3))
    for h in nb.prange(nch):
        for v in range(chunks[h, 0], chunks[h, 1]):
            f = ln[v] * r_e[v]
            for d in range(3):
                part[h, d] += b[v] * u[v, d] + M[v, d] * f
    c = np.zeros((k, 3))
    for h in range(nch):
        for d in range(3):
            c[chunks[h, 2], d] += part[h, d]
    for j in range(k):
        for d in range(3):
            c[j, d] = (r_b[j, d] * scale - c[j, d]) / bsum[j]
    for v in nb.prange(u.shape[0]):
        j = comp[v]
        for d in range(3):
            u[v, d] += c[j, d]
        if multipliers:
            lam_e[v] -= ln[v] * (M[v, 0] * mu_b[j, 0] + M[v, 1] * mu_b[j, 1]
                                 + M[v, 2] * mu_b[j, 2]) / scale


# ------------------------------------------------------------------------------------------------
# layouts with open components, and pins by elimination


@nb.njit(cache=True, parallel=True)
def _correction(y, yb, beta, F, Z, Zlam, zcol, starts, brow, cap, chunks, u, lam_e, lam_b):
    """The low-rank correction of :meth:`BandedSaddle._solve` for the band solve ``y`` (N, 3)
    (``yb``: the barycenter rows' right-hand sides), in place on ``u`` (may be ``y``),
    ``lam_e`` and ``lam_b`` (may be ``yb``: a row is read before it is written). A component
    with barycenter rows (row ``brow[c]`` of ``yb``) takes the nine columns and its 12 × 12
    capacitance, one with a pin (``brow[c]`` −1) the barycenter term's three and a 3 × 3 one
    (``cap[c, :3, :3]``); ``beta`` empty: no barycenter term, ``Z``'s six columns at the
    places ``zcol`` of the nine. The columns' products with
    ``y`` from their structure: the springs read ``y`` at the component's first vertex, the
    barycenter term ``β`` per coordinate, the barycenter rows their fields ``F`` (3, N, 3).
    The pieces of ``chunks`` (first, end, component) in parallel, their sums added in order:
    the same bits for any thread count. (Products with the columns as dense (9, N, 3) fields
    by BLAS before: three times the bytes, and OpenBLAS's threads woke at every solve.)"""
    nch = chunks.shape[0]
    part = np.empty((nch, 6))
    has_b = beta.shape[0] > 0
    for h in nb.prange(nch):
        b0 = b1 = b2 = f0 = f1 = f2 = 0.0
        if brow[chunks[h, 2]] >= 0:
            for v in range(chunks[h, 0], chunks[h, 1]):
                y0, y1, y2 = y[v, 0], y[v, 1], y[v, 2]
                if has_b:
                    b = beta[v]
                    b0 += b * y0
                    b1 += b * y1
                    b2 += b * y2
                f0 += F[0, v, 0] * y0 + F[0, v, 1] * y1 + F[0, v, 2] * y2
                f1 += F[1, v, 0] * y0 + F[1, v, 1] * y1 + F[1, v, 2] * y2
                f2 += F[2, v, 0] * y0 + F[2, v, 1] * y1 + F[2, v, 2] * y2
        else:  # pinned: the barycenter term's columns alone
            for v in range(chunks[h, 0], chunks[h, 1]):
                b = beta[v]
                b0 += b * y[v, 0]
                b1 += b * y[v, 1]
                b2 += b * y[v, 2]
        part[h, 0], part[h, 1], part[h, 2] = b0, b1, b2
        part[h, 3], part[h, 4], part[h, 5] = f0, f1, f2
    k = starts.shape[0] - 1
    W = np.zeros((k, 9))  # each component's coefficients of the columns of Z
    t = np.empty(12)
    h = 0
    for c in range(k):
        t[:] = 0.0
        while h < nch and chunks[h, 2] == c:
            for a in range(6):
                t[3 + a] += part[h, a]
            h += 1
        r = brow[c]
        if r >= 0:
            a0 = starts[c]
            for d in range(3):
                t[d] = y[a0, d]
                t[9 + d] = yb[r, d]
            for i in range(12):
                acc = 0.0
                for j in range(12):
                    acc += cap[c, i, j] * t[j]
                if i < 9:
                    W[c, i] = acc
                else:
                    lam_b[r, i - 9] -= acc
        else:  # the barycenter term alone
            for i in range(3):
                acc = 0.0
                for j in range(3):
                    acc += cap[c, i, j] * t[3 + j]
                W[c, 3 + i] = acc
    q = zcol.shape[0]
    for h in nb.prange(nch):
        c = chunks[h, 2]
        w = W[c]
        # W's other columns are 0 when pinned (never without the barycenter term: q is 9)
        a0, a1 = (0, q) if brow[c] >= 0 else (3, 6)
        for v in range(chunks[h, 0], chunks[h, 1]):
            for d in range(3):
                acc = 0.0
                for a in range(a0, a1):
                    acc += w[zcol[a]] * Z[a, v, d]
                u[v, d] -= acc
            acc = 0.0
            for a in range(a0, a1):
                acc += w[zcol[a]] * Zlam[a, v]
            lam_e[v] -= acc


class OpenBandedSaddle(BandedSaddle):
    """:class:`BandedSaddle` for layouts with open components and any number of pinned
    vertices: the edge slots without a row (dummy edges, edges between two pins) and the
    pinned coordinates are eliminated in the band itself (:func:`_fill`), not bordered
    (:mod:`.pinned_solve`: three solves per pin and iterate). A component with a pin has no
    barycenter rows and needs no spring (the pin holds it): its correction is the barycenter
    term alone (rank 3), without pins the one of :class:`BandedSaddle` (rank 12). The
    components are independent blocks of the band: the correction's columns of all of them
    are solved together, nine band solves per iterate for any number of components."""

    def __init__(self, parts, jac: Jacobian, recycle: BandedSaddle | None = None):
        rows, cols, vals, beta = parts
        con = jac.con
        if not (con.edge_lengths and con.barycenter):
            raise ValueError("the banded saddle-point solver needs the edge-length and "
                             "barycenter constraints")
        lay = con.layout
        n, k = lay.n, lay.k
        self.layout, self.jac = lay, jac
        self.rows, self.cols, self.vals = rows, cols, vals
        fixed = np.zeros(n, bool)
        if con.pinned is not None:
            fixed[con.pinned] = True
        self.fixed = fixed
        beta = np.where(fixed, 0.0, beta)  # the metric of the free coordinates
        self.beta_full = parts[3]
        pinned_comp = np.zeros(k, bool)
        pinned_comp[lay.comp[fixed]] = True
        self.free_comps = np.flatnonzero(~pinned_comp)
        T, inv_l = jac.edge_fields()
        ln = np.where(inv_l > 0, 1.0 / np.where(inv_l > 0, inv_l, 1.0), 0.0)
        diag = self._factor(parts, np.asarray(lay.starts[:-1], np.int64)[self.free_comps], T,
                            ln, con.edge_rows >= 0, fixed, recycle)
        recycle = None
        # per component its row among the barycenter rows (−1: it has none, it is pinned) and
        # its capacitance's inverse: 12 × 12, or 3 × 3 in the corner (:func:`_correction`)
        brow = np.full(k, -1, np.int64)
        brow[np.asarray(con.bary_components, np.int64)] = np.arange(len(con.bary_components))
        U = self._columns(beta, jac.barycenter_fields(), brow)
        self.slices = [slice(int(lay.starts[c]), int(lay.starts[c + 1])) for c in range(k)]
        for c in range(k):
            W = self._gram(U, c)
            if brow[c] >= 0:
                self.cap[c] = _capacitance(W, diag[lay.starts[c]])
            else:  # the barycenter term alone: (K + β βᵀ)⁻¹ by Sherman–Morrison–Woodbury
                self.cap[c, :3, :3] = np.linalg.inv(np.eye(3) + W[3:6, 3:6])

    def _solve(self, g: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        con = self.jac.con
        n = self.layout.n
        ne = con.n_edge_rows
        # g None: zero fields (:func:`_solve_fields`)
        G = np.empty((1, 0, 3)) if g is None else np.where(self.fixed[:, None], 0.0, g)[None]
        lam0 = np.zeros(n)
        lam0[con.edge_index] = r[:ne]
        (y,), (ylam,) = self._band_inverse(G, lam0[None])
        yb = np.asarray(r[ne:], float).reshape(-1, 3)
        u, lam_e, lam_b = y, ylam, yb.copy()  # (fresh arrays of the band solve)
        self._correct(y, yb, u, lam_e, lam_b)
        u[self.fixed] = 0.0
        return u, np.concatenate([lam_e[con.edge_index], lam_b.ravel()])

    def solve(self, g: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`BandedSaddle.solve` (one refinement step); the pinned coordinates'
        equations are not part of the system."""
        u, lam = self._solve(g, r)
        rg = g - self.metric_product(u) - self.jac.rmatvec(lam)
        rg[self.fixed] = 0.0
        du, dlam = self._solve(rg, r - self.jac.matvec(u))
        return u + du, lam + dlam

    def solve_many(self, G: np.ndarray, R: np.ndarray):
        raise NotImplementedError("OpenBandedSaddle eliminates its pins: nothing to border")

    def metric_product(self, V: np.ndarray) -> np.ndarray:
        """``A V`` (band and barycenter term, every coordinate)."""
        out = _band_product(self.rows, self.cols, self.vals, np.ascontiguousarray(V, float))
        for s in self.slices:
            out[s] += np.outer(self.beta_full[s], self.beta_full[s] @ V[s])
        return out
