"""The pair weight of the fractional Sobolev metrics ``hs`` and ``hs_pure`` (docs/design.md,
step 1; Reiter & Schumacher, §2), the only place it is written.

Every sum of the metric (the dense Gram matrices of :mod:`.gram` and :mod:`.open`, the tree's
near and far weights in :mod:`..tree.hs_metric`) reaches it through :func:`hs_weight`, inlined
(``inline="always"``) and so compiled with the caller's own options. Keep its floating-point
order: the matrices of order 3/2 are pinned bit for bit (``w = l_I l_J / |d|²`` by the
arithmetic that order always had). numba's cache is keyed on the caller's file: after editing
this one, delete the callers' cached kernels (``__pycache__/*.nbi``, ``*.nbc`` of gram.py,
open.py, hs_metric.py).
"""

from __future__ import annotations

import numba as nb


@nb.njit(cache=True, inline="always")
def hs_weight(li, lj, r2, expo):
    """``(w, 1/|d|²)`` of two edges of lengths ``li``, ``lj`` whose midpoints are ``|d|² =
    r2`` apart: ``w = l_I l_J / |d|^(2s − 1)``, the kernel of the order-``s`` metric's top
    part. ``expo``: :func:`.gram.kernel_exponent` of the order, None at 3/2 (``w = l_I l_J /
    |d|²``; the branch is pruned at compile time), else ``s − 1/2``. The far field passes unit
    lengths (its weights per unit length of both clusters)."""
    inv = 1.0 / r2
    if expo is None:
        return li * lj * inv, inv
    return li * lj * r2**-expo, inv
