"""LAPACK routines numpy does not expose, taken from the OpenBLAS that numpy itself ships.

numpy has Cholesky (double precision, always a copy) but no inverse from a Cholesky factor;
scipy is not available at run time (Blender ships numpy only). numpy's wheels bundle OpenBLAS
with the whole LAPACK, ILP64 with the ``_64_`` symbol suffix; we call ``potrf``/``potri``
from it through ctypes. Where
the library cannot be found (another numpy build) every function returns None and the callers
fall back to numpy-only code.
"""

from __future__ import annotations

import ctypes
import glob
import os

import numba as nb
import numpy as np

_lib = None
_int = ctypes.c_int64
_suffix = "_64_"


def _load():
    global _lib, _int, _suffix
    root = os.path.dirname(os.path.dirname(np.__file__))
    candidates = []
    for pattern in ("numpy.libs/*openblas*", "numpy/.dylibs/*openblas*", "numpy/.libs/*openblas*",
                    "numpy.libs/*scipy_openblas*"):
        candidates += sorted(glob.glob(os.path.join(root, pattern)))
    for path in candidates:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for suffix, itype in (("_64_", ctypes.c_int64), ("64_", ctypes.c_int64),
                              ("_64", ctypes.c_int64), ("_", ctypes.c_int32),
                              ("", ctypes.c_int32)):
            names = [
                f"{p}{r}{suffix}" for p in "ds" for r in ("potrf", "potri", "trtri")
            ]
            if all(hasattr(lib, n) for n in names):
                _lib, _int, _suffix = lib, itype, suffix
                return


try:
    _load()
except Exception:  # pragma: no cover - any failure means: use the numpy fallback
    _lib = None


def available() -> bool:
    return _lib is not None


def _call(name: str, dtype, *args) -> int:
    prefix = "d" if dtype == np.float64 else "s"
    f = getattr(_lib, f"{prefix}{name}{_suffix}")
    info = _int(0)
    f(*args, ctypes.byref(info))
    return info.value


def _prepare(A):
    if _lib is None or A.dtype not in (np.float64, np.float32) or A.ndim != 2:
        return None
    # Fortran order: the lower triangle in LAPACK's view is the upper triangle in C order of
    # the same buffer; we pass 'U' on a C-ordered copy, which is 'L' of the transpose.
    return np.array(A, order="C", copy=True)


def _dims(n):
    return ctypes.byref(_int(n)), ctypes.byref(_int(n))


def spd_inverse(A: np.ndarray, overwrite: bool = False):
    """Inverse of an SPD matrix (potrf + potri) or None if LAPACK is unavailable;
    ``overwrite=True`` inverts a C-ordered ``A`` in place."""
    M = cholesky(A, overwrite=overwrite)
    if M is None:
        return None
    uplo = ctypes.byref(ctypes.c_char(b"U"))
    nn, lda = _dims(M.shape[0])
    if _call("potri", M.dtype, uplo, nn, M.ctypes.data_as(ctypes.c_void_p), lda) != 0:
        raise np.linalg.LinAlgError("Singular matrix")
    # 'U' in column-major = lower triangle in row-major: mirror it to the full matrix
    _mirror_lower(M)
    return M


@nb.njit(cache=True, parallel=True)
def _mirror_lower(M):
    """Copy the lower triangle of a square C-ordered matrix onto its upper triangle, in
    64 × 64 tiles (30× faster than fancy indexing with ``triu_indices`` at N = 3000)."""
    n = M.shape[0]
    b = 64
    blocks = (n + b - 1) // b
    for bi in nb.prange(blocks):
        i0 = bi * b
        for bj in range(bi + 1):
            j0 = bj * b
            for i in range(i0, min(n, i0 + b)):
                for j in range(j0, min(i, j0 + b)):
                    M[j, i] = M[i, j]


def cholesky(A: np.ndarray, overwrite: bool = False):
    """Cholesky factor of an SPD matrix (potrf; ``linalg.CholeskySolve`` applies it), or None
    if LAPACK is unavailable. Only the lower triangle of the returned C-ordered array is the
    factor ``L``; the strict upper triangle keeps the input's values. ``overwrite=True``
    factors a C-ordered ``A`` in place."""
    if overwrite and _lib is not None and A.flags.c_contiguous and A.dtype in (np.float64,
                                                                             np.float32):
        M = A
    else:
        M = _prepare(A)
    if M is None:
        return None
    n = M.shape[0]
    uplo = ctypes.byref(ctypes.c_char(b"U"))
    nn, lda = _dims(n)
    if _call("potrf", M.dtype, uplo, nn, M.ctypes.data_as(ctypes.c_void_p), lda) != 0:
        raise np.linalg.LinAlgError("Matrix is not positive definite")
    return M
