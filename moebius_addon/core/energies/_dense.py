"""What the dense pair sums share (private): edge data as contiguous coordinate arrays, the
range of a row's disjoint partners, and the compiler options of the sums. Below both
:mod:`.moebius_dense` (closed curves and links) and :mod:`.open_energy` (open components), which
import it and never each other's internals.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..geometry.layout import Layout

# Partial gradients go to a fixed number of buffers, independent of the thread count, so the
# result is bit-for-bit the same on every machine with the same inputs.
CHUNKS = 8
# Reassociation lets LLVM vectorize the pair sums (results change in the last bits only);
# no 'nnan'/'ninf': non-finite input must stay visible.
FASTMATH = {"reassoc", "contract", "nsz", "arcp"}


def edge_data(X: np.ndarray, layout: Layout):
    """Edge vectors, midpoints and lengths as separate contiguous coordinate arrays."""
    E = X[layout.nxt] - X
    M = 0.5 * (X[layout.nxt] + X)
    lengths = np.sqrt(np.einsum("ij,ij->i", E, E))
    return (
        np.ascontiguousarray(E[:, 0]),
        np.ascontiguousarray(E[:, 1]),
        np.ascontiguousarray(E[:, 2]),
        np.ascontiguousarray(M[:, 0]),
        np.ascontiguousarray(M[:, 1]),
        np.ascontiguousarray(M[:, 2]),
        lengths,
    )


@nb.njit(cache=True, inline="always")
def row_range(i, comp_start, comp_end):
    """Edges J > i of the same component that are disjoint from edge i: [i+2, end)."""
    lo = i + 2
    hi = comp_end
    if i == comp_start:
        hi = comp_end - 1  # the last edge of the component touches vertex comp_start
    return lo, hi
