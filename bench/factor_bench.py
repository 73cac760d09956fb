"""Factorization of the saddle-point system: the previous implementation against the current
one, timed alternately in one process (the machine is shared; only ratios within one run mean
something). Prints measurements; not a test.

    python bench/factor_bench.py [N ...]      # default: 1648 3000

"previous" is the code before commit 8a2daaa: A⁻¹ by LAPACK potrf+potri mirrored with
``triu_indices``, the edge Schur block from numpy temporaries, ``np.linalg.cholesky`` of S and
a LAPACK triangular inverse. "current" is ``linalg.Factorization``: tiled numba mirror, one-pass
numba Schur block, LAPACK potrf of S (applied by blocked substitution, whose diagonal-block
inverses are part of the factorization).
"""

from __future__ import annotations

import sys
import time

import numpy as np

from moebius_addon.core.geometry.constraints import jacobian
from moebius_addon.core.metrics import _lapack
from moebius_addon.core.metrics.gram import gram_x
from moebius_addon.core.metrics.saddle import Factorization
from moebius_addon.core.runs.methods import Relaxation
from moebius_addon.core.topology import knots


def previous(A, jac, dtype):
    M = np.array(A, dtype=dtype, order="C")
    Fa = _lapack.cholesky(M, overwrite=True)  # potrf, then potri as before
    import ctypes

    n = Fa.shape[0]
    uplo = ctypes.byref(ctypes.c_char(b"U"))
    nn, lda = _lapack._dims(n)
    _lapack._call("potri", Fa.dtype, uplo, nn, Fa.ctypes.data_as(ctypes.c_void_p), lda)
    iu = np.triu_indices(n, 1)
    Fa[iu] = Fa.T[iu]
    Ainv = Fa
    lay = jac.con.layout
    m = jac.con.size
    S = np.empty((m, m), dtype=dtype)
    ne = lay.n
    T, inv_l = jac.edge_fields()
    T, inv_l = T.astype(dtype), inv_l.astype(dtype)
    Y = (Ainv[lay.nxt] - Ainv) * inv_l[:, None]
    Y = (Y[:, lay.nxt] - Y) * inv_l[None, :]
    S[:ne, :ne] = Y * (T @ T.T)
    F = jac.barycenter_fields()
    cols = np.stack([jac.matvec((Ainv @ F[r].astype(dtype)).astype(float)) for r in range(3)],
                    axis=1)
    S[:, ne:] = cols
    S[ne:, :] = cols.T
    L = _lapack.cholesky(S, overwrite=True)  # then trtri of the factor, as before
    nn, lda = _lapack._dims(m)
    _lapack._call("trtri", L.dtype, uplo, ctypes.byref(ctypes.c_char(b"N")), nn,
                  L.ctypes.data_as(ctypes.c_void_p), lda)
    return np.tril(L)


def main():
    sizes = [int(a) for a in sys.argv[1:]] or [1648, 3000]
    for n in sizes:
        P = knots.freedman_unknot(n) if n < 2000 else knots.named("7_2", n)
        run = Relaxation(P, max_iter=5)
        A = gram_x("hs", run.X, run.layout)
        jac = jacobian(run.X, run.con)
        for dtype in (np.float32, np.float64):
            times = {"previous": [], "current": []}
            previous(A, jac, dtype)
            Factorization(A, jac, dtype)
            for _ in range(3):  # alternate, so both see the same machine load
                t = time.perf_counter()
                previous(A, jac, dtype)
                times["previous"].append(time.perf_counter() - t)
                t = time.perf_counter()
                Factorization(A, jac, dtype)
                times["current"].append(time.perf_counter() - t)
            a, b = min(times["previous"]), min(times["current"])
            print(f"N={n:5d} {np.dtype(dtype).name}: previous {1e3 * a:7.1f} ms, current "
                  f"{1e3 * b:7.1f} ms, ratio {a / b:.2f} (best of 3 each, alternated)",
                  flush=True)


if __name__ == "__main__":
    main()
