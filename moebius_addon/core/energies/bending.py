"""Bending stiffness: the discrete elastic rod's bending energy (Bergou, Wardetzky, Robinson,
Audoly and Grinspun, *Discrete Elastic Rods*, 2008, §4.2), added to a repulsive energy with a
weight ``stiffness=`` so that cables and ropes hold their curvature instead of kinking (as
KNOTEVOLVE adds bending to the tangent-point energy).

At an interior vertex ``i`` with edges ``a = x_i − x_{i−1}``, ``b = x_{i+1} − x_i``, turning
angle ``φ_i`` and dual length ``ℓ_i = (|a| + |b|)/2``, the curvature is
``κ_i = 2 tan(φ_i/2) / ℓ_i`` (the length of the curvature binormal ``2 a × b / (|a||b| + a·b)``
per dual length) and::

    E_b = Σ_i κ_i² ℓ_i = Σ_i 4 tan²(φ_i/2) / ℓ_i,   tan²(φ/2) = |a × b|² / (|a||b| + a·b)²

the midpoint rule for ``∫ κ² ds`` (a regular N-gon of radius R: ``N·4 tan²(π/N)/(2R sin(π/N))
→ 2π/R``). ``|a × b|``, not ``|a||b| − a·b``: no cancellation along nearly straight strands.
The sum is over interior vertices: every vertex of a closed component, all but the two ends of
an open one (free ends carry no moment); components are summed apart (links).

Scaling: ``E_b(λP) = E_b(P)/λ``. A run works at total length 1, so ``stiffness = w`` on a
curve of total length ``L`` minimizes ``E + w · L · E_b(P)``: ``L · E_b`` is scale-free (the
circle's is 4π² at any size), and so is the weight. Local: O(N), one serial loop (the same bits
for every thread count); no tree.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .record import Energy, Parameter

#: The name of the energy (``energies.ENERGIES``).
NAME = "bending"
#: ``E(λP) = λ^SCALING E(P)``.
SCALING = -1.0


@nb.njit(cache=True, inline="always")
def vertex(ax, ay, az, bx, by, bz):
    """The term ``4 tan²(φ/2) / ℓ`` of the vertex between the edges ``a`` and ``b``.

    Returns ``(f, ∂f/∂a (3), ∂f/∂b (3))``."""
    la = math.sqrt(ax * ax + ay * ay + az * az)
    lb = math.sqrt(bx * bx + by * by + bz * bz)
    ux = ay * bz - az * by
    uy = az * bx - ax * bz
    uz = ax * by - ay * bx
    s = ux * ux + uy * uy + uz * uz  # |a × b|²
    iq = 1.0 / (la * lb + ax * bx + ay * by + az * bz)
    idl = 2.0 / (la + lb)  # 1 / ℓ
    f = 4.0 * s * iq * iq * idl
    # ∂f/∂a = cs ∂s/∂a − cq ∂q/∂a − cl ∂ℓ/∂a, with ∂s/∂a = 2 b × u, ∂s/∂b = 2 u × a,
    # ∂q/∂a = (|b|/|a|) a + b, ∂q/∂b = (|a|/|b|) b + a, ∂ℓ/∂a = a / (2|a|)
    cs = 8.0 * iq * iq * idl
    cq = 2.0 * f * iq
    cl = 0.5 * f * idl
    ka = cq * lb / la + cl / la
    kb = cq * la / lb + cl / lb
    fax = cs * (by * uz - bz * uy) - ka * ax - cq * bx
    fay = cs * (bz * ux - bx * uz) - ka * ay - cq * by
    faz = cs * (bx * uy - by * ux) - ka * az - cq * bz
    fbx = cs * (uy * az - uz * ay) - kb * bx - cq * ax
    fby = cs * (uz * ax - ux * az) - kb * by - cq * ay
    fbz = cs * (ux * ay - uy * ax) - kb * bz - cq * az
    return f, fax, fay, faz, fbx, fby, fbz


@nb.njit(cache=True)
def _sum(X, nxt, prv, grad):
    """``(E_b, ∇E_b)`` over the interior vertices (``∇E_b`` (0, 3) unless ``grad``); an open
    component's ends are the vertices whose next or previous edge is the dummy (``nxt[i] ==
    i``, geometry.layout)."""
    n = X.shape[0]
    G = np.zeros((n if grad else 0, 3))
    E = 0.0
    for i in range(n):
        h = prv[i]
        j = nxt[i]
        if j == i or nxt[h] == h:
            continue
        f, fax, fay, faz, fbx, fby, fbz = vertex(
            X[i, 0] - X[h, 0], X[i, 1] - X[h, 1], X[i, 2] - X[h, 2],
            X[j, 0] - X[i, 0], X[j, 1] - X[i, 1], X[j, 2] - X[i, 2])
        E += f
        if grad:
            G[h, 0] -= fax
            G[h, 1] -= fay
            G[h, 2] -= faz
            G[i, 0] += fax - fbx
            G[i, 1] += fay - fby
            G[i, 2] += faz - fbz
            G[j, 0] += fbx
            G[j, 1] += fby
            G[j, 2] += fbz
    return E, G


def bending_x(X: np.ndarray, layout) -> float:
    """``E_b`` of the stacked vertices ``X`` (N, 3) of ``layout``."""
    return _sum(np.ascontiguousarray(X, dtype=np.float64), layout.nxt, layout.prv, False)[0]


def bending_gradient_x(X: np.ndarray, layout) -> tuple[float, np.ndarray]:
    """``(E_b, ∇E_b)``, ``∇E_b`` (N, 3)."""
    return _sum(np.ascontiguousarray(X, dtype=np.float64), layout.nxt, layout.prv, True)


RECORD = Energy(
    name=NAME,
    short='bend',
    label="Bending",
    help="Bending stiffness of a rod (∫ κ² ds), added to the repulsive energy",
    exact=bending_x,
    exact_gradient=bending_gradient_x,
    scaling=lambda: SCALING,
    words=lambda: "Bending energy ∫ κ² ds of the curve at this frame",
    repulsive=False,
    weight=Parameter(
        "stiffness", "Stiffness",
        "Bending stiffness added to the energy: the curve holds its curvature instead of "
        "kinking, as a cable or rope does (0: none; relative to the curve's length, so the "
        "same at any size)",
        0.0, "stiffness", minimum=0.0, soft_max=1.0, precision=3),
    warmup=({"stiffness": 0.1},),
)
