"""The test of one pair of edges, shared by the all-pairs searches of :mod:`collision` and the
hierarchy's of :mod:`tree_contact` (private): the segment distance, and the conservative
advancement of a moving pair (docs/design.md, step 3; the method is described in :mod:`collision`).
"""

from __future__ import annotations

import numba as nb
import numpy as np

_MAX_ADVANCE = 64
#: The advancement stops (a contact) once a pair is within this many times eps.
SLACK = 1.001


@nb.njit(cache=True, inline="always")
def _clamp01(x):
    return 0.0 if x < 0.0 else (1.0 if x > 1.0 else x)


@nb.njit(cache=True)
def segment_distance2(a0x, a0y, a0z, a1x, a1y, a1z, b0x, b0y, b0z, b1x, b1y, b1z):
    """Squared distance of the segments [a0, a1] and [b0, b1] and the closest parameters."""
    d1x, d1y, d1z = a1x - a0x, a1y - a0y, a1z - a0z
    d2x, d2y, d2z = b1x - b0x, b1y - b0y, b1z - b0z
    rx, ry, rz = a0x - b0x, a0y - b0y, a0z - b0z
    a = d1x * d1x + d1y * d1y + d1z * d1z
    e = d2x * d2x + d2y * d2y + d2z * d2z
    f = d2x * rx + d2y * ry + d2z * rz
    c = d1x * rx + d1y * ry + d1z * rz
    b = d1x * d2x + d1y * d2y + d1z * d2z
    if a <= 0.0 and e <= 0.0:
        s = 0.0
        t = 0.0
    elif a <= 0.0:
        s = 0.0
        t = _clamp01(f / e)
    elif e <= 0.0:
        t = 0.0
        s = _clamp01(-c / a)
    else:
        denom = a * e - b * b
        s = _clamp01((b * f - c * e) / denom) if denom > 0.0 else 0.0
        t = (b * s + f) / e
        if t < 0.0:
            t = 0.0
            s = _clamp01(-c / a)
        elif t > 1.0:
            t = 1.0
            s = _clamp01((b - c) / a)
    x = rx + s * d1x - t * d2x
    y = ry + s * d1y - t * d2y
    z = rz + s * d1z - t * d2z
    return x * x + y * y + z * z, s, t


@nb.njit(cache=True)
def _pair_contact(X, U, i, i1, j, j1, tau0, tau_max, eps):
    """First τ in [tau0, tau_max) where edges (i, i1), (j, j1) of X − τU come within eps, or
    tau_max, for a pair known not to touch before tau0. Conservative: the returned τ never
    exceeds the true contact time.

    The relative velocity of any two points on the segments is a convex combination of the
    endpoint differences U_a − U_b, so its norm is at most their largest norm ``v``."""
    v = 0.0
    for a in (i, i1):
        for b in (j, j1):
            w = np.sqrt((U[a, 0] - U[b, 0]) ** 2 + (U[a, 1] - U[b, 1]) ** 2
                        + (U[a, 2] - U[b, 2]) ** 2)
            v = max(v, w)
    if v == 0.0:
        return tau_max
    tau = tau0
    for _ in range(_MAX_ADVANCE):
        d2, _s, _t = segment_distance2(
            X[i, 0] - tau * U[i, 0], X[i, 1] - tau * U[i, 1], X[i, 2] - tau * U[i, 2],
            X[i1, 0] - tau * U[i1, 0], X[i1, 1] - tau * U[i1, 1], X[i1, 2] - tau * U[i1, 2],
            X[j, 0] - tau * U[j, 0], X[j, 1] - tau * U[j, 1], X[j, 2] - tau * U[j, 2],
            X[j1, 0] - tau * U[j1, 0], X[j1, 1] - tau * U[j1, 1], X[j1, 2] - tau * U[j1, 2],
        )
        d = np.sqrt(d2)
        if d <= SLACK * eps:
            return tau
        tau += (d - eps) / v
        if tau >= tau_max:
            return tau_max
    return tau


@nb.njit(cache=True, inline="always")
def tested(i, j, starts, comp, closed, near):
    """Whether the contact tests look at edges ``i < j``: always on different components; on
    one, when they share no vertex and lie more than ``near[c]`` edges apart along it (round a
    closed one the shorter way). ``near`` is 1 without a thickness (the disjoint pairs); a tube
    bends within π times its radius along the strand, so pairs nearer than that are left out
    (:mod:`..thickness`)."""
    c = comp[i]
    if comp[j] != c:
        return True
    if j == i + 1 or (i == starts[c] and j == starts[c + 1] - 1):
        return False
    if near[c] > 1:
        gap = j - i
        if closed[c]:
            gap = min(gap, starts[c + 1] - starts[c] - gap)
        return gap > near[c]
    return True


@nb.njit(cache=True, parallel=True)
def edge_motion(X, U, nxt):
    """Per edge, what the pair test needs so that pruning a pair costs one squared distance:
    midpoint, mean velocity, spread (half the difference of its endpoint velocities), half
    length and the larger endpoint speed."""
    n = X.shape[0]
    mid = np.empty((n, 3))
    vel = np.empty((n, 3))
    spread = np.empty(n)
    half = np.empty(n)
    vmax = np.empty(n)
    for i in nb.prange(n):
        i1 = nxt[i]
        s0 = np.sqrt(U[i, 0] ** 2 + U[i, 1] ** 2 + U[i, 2] ** 2)
        s1 = np.sqrt(U[i1, 0] ** 2 + U[i1, 1] ** 2 + U[i1, 2] ** 2)
        vmax[i] = max(s0, s1)
        spread[i] = 0.5 * np.sqrt(
            (U[i1, 0] - U[i, 0]) ** 2 + (U[i1, 1] - U[i, 1]) ** 2 + (U[i1, 2] - U[i, 2]) ** 2
        )
        for k in range(3):
            mid[i, k] = 0.5 * (X[i, k] + X[i1, k])
            vel[i, k] = 0.5 * (U[i, k] + U[i1, k])
        half[i] = 0.5 * np.sqrt(
            (X[i1, 0] - X[i, 0]) ** 2 + (X[i1, 1] - X[i, 1]) ** 2 + (X[i1, 2] - X[i, 2]) ** 2
        )
    return mid, vel, spread, half, vmax


@nb.njit(cache=True, inline="always")
def pair_time(X, U, nxt, i, j, mid, vel, spread, half, vmax, eps, tb):
    """The contact test of the disjoint edges ``i < j`` against the best time ``tb`` so far:
    their first contact if it comes before ``tb``, else ``tb``. The value depends on the pair
    alone (where it is below ``tb``), so any search that tests every pair that could beat the
    final answer, in any order, returns the same bits."""
    v = vmax[i] + vmax[j]
    # the segments stay eps apart until tb unless the midpoints are closer than the half
    # lengths + eps + the distance both can travel
    reach = half[i] + eps
    r = reach + half[j] + tb * v
    dx = mid[i, 0] - mid[j, 0]
    dy = mid[i, 1] - mid[j, 1]
    dz = mid[i, 2] - mid[j, 2]
    d2 = dx * dx + dy * dy + dz * dz
    if v == 0.0 or d2 >= r * r:
        return tb
    # exact first time at which the midpoint spheres, grown by eps and by the spread of each
    # edge's endpoint velocities, could meet: the root of |Δm − τΔū|² = (cr + τ rr)² (safe
    # forever when there is none)
    wx = vel[i, 0] - vel[j, 0]
    wy = vel[i, 1] - vel[j, 1]
    wz = vel[i, 2] - vel[j, 2]
    cr = reach + half[j]
    rr = spread[i] + spread[j]
    k = d2 - cr * cr
    tau0 = 0.0
    if k > 0.0:
        a = wx * wx + wy * wy + wz * wz - rr * rr
        b = dx * wx + dy * wy + dz * wz + cr * rr
        disc = b * b - a * k
        if disc < 0.0:
            return tb
        den = b + np.sqrt(disc)
        if den <= 0.0:
            return tb
        tau0 = k / den
        if tau0 >= tb:
            return tb
    t = _pair_contact(X, U, i, nxt[i], j, nxt[j], tau0, tb, eps)
    return t if t < tb else tb
