"""LAPACK routines numpy does not expose, taken from the OpenBLAS that numpy itself ships.

numpy has Cholesky but no triangular inverse or solve; scipy is not available at run time
(Blender ships numpy only). numpy's wheels bundle OpenBLAS with the whole LAPACK, ILP64 with
the ``_64_`` symbol suffix; we call ``potrf``/``potri``/``trtri`` from it through ctypes. Where
the library cannot be found (another numpy build) every function returns None and the callers
fall back to numpy-only code.
"""

from __future__ import annotations

import ctypes
import glob
import os

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
            names = [f"{p}{r}{suffix}" for p in "ds" for r in ("potrf", "potri", "trtri")]
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


def spd_inverse(A: np.ndarray):
    """Inverse of an SPD matrix (potrf + potri) or None if LAPACK is unavailable."""
    M = _prepare(A)
    if M is None:
        return None
    n = M.shape[0]
    uplo = ctypes.byref(ctypes.c_char(b"U"))
    nn, lda = _dims(n)
    ptr = M.ctypes.data_as(ctypes.c_void_p)
    if _call("potrf", M.dtype, uplo, nn, ptr, lda) != 0:
        raise np.linalg.LinAlgError("Matrix is not positive definite")
    if _call("potri", M.dtype, uplo, nn, ptr, lda) != 0:
        raise np.linalg.LinAlgError("Singular matrix")
    # 'U' in column-major = lower triangle in row-major: mirror it to the full matrix
    iu = np.triu_indices(n, 1)
    M[iu] = M.T[iu]
    return M


def triangular_inverse(L: np.ndarray):
    """Inverse of a lower-triangular matrix (trtri) or None if LAPACK is unavailable."""
    M = _prepare(L)
    if M is None:
        return None
    n = M.shape[0]
    # row-major lower = column-major upper
    uplo = ctypes.byref(ctypes.c_char(b"U"))
    diag = ctypes.byref(ctypes.c_char(b"N"))
    nn, lda = _dims(n)
    if _call("trtri", M.dtype, uplo, diag, nn, M.ctypes.data_as(ctypes.c_void_p), lda) != 0:
        raise np.linalg.LinAlgError("Singular matrix")
    return np.tril(M)
