"""Memory: refusals by estimate (a size whose arrays would not fit is refused before any work,
with the estimate in the message: a machine that swaps, or a process killed by the
out-of-memory handler, says nothing useful; numba's ``MemoryError`` says less), and how the
runs' arrays take their pages (:func:`give_back`, :func:`small_pages`)."""

from __future__ import annotations

import contextlib
import functools
import os
import threading

#: Share of the machine's physical memory one call may need before it is refused (as
#: ``solvers.base`` allows the dense runs).
MEMORY_SHARE = 0.75


def physical_memory() -> float | None:
    """Bytes of physical memory, or None where the system does not say (Windows)."""
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return None


def available_memory() -> float | None:
    """Bytes of memory the system can give without swapping (Linux's ``MemAvailable``), else
    the physical memory, else None."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0
    except OSError:
        pass
    return physical_memory()


def check_memory(need: float, what: str, fix: str) -> None:
    """ValueError when ``need`` bytes are more than :data:`MEMORY_SHARE` of this machine's
    memory: "``what`` needs about 12.3 GB, more than …: ``fix``". Nothing where the system
    does not say how much memory it has."""
    total = physical_memory()
    if total is None or need <= MEMORY_SHARE * total:
        return
    raise ValueError(f"{what} needs about {_gb(need)} of memory, more than this machine's "
                     f"{total / 1e9:.1f} GB allow ({MEMORY_SHARE:.0%} of it): {fix}")


def _gb(need: float) -> str:
    return f"{need / 1e9:.3g} GB" if need < 1e15 else f"{need:.2g} bytes"


@functools.cache
def _libc_trim():
    """glibc's ``malloc_trim``, or None (another C library, or another system); looked up at
    the first call, not at import."""
    if os.name != "posix":
        return None
    try:
        import ctypes

        return ctypes.CDLL("libc.so.6").malloc_trim
    except (OSError, AttributeError):
        return None


def give_back() -> None:
    """Return the heap's free pages to the system (glibc's ``malloc_trim(0)``; nothing
    elsewhere). Arrays below glibc's mmap threshold (up to 32 MB: the (N, 3) fields of
    10⁶ vertices are 24 MB) come from the heap, whose freed pages stay resident."""
    trim = _libc_trim()
    if trim is not None:
        trim(0)


def _numpy_huge_page_switch():
    """numpy's switch of its huge-page advice (``_set_madvise_hugepage``: numpy madvises
    every array of 4 MB or more ``MADV_HUGEPAGE`` on Linux), or None where it has none."""
    try:
        from numpy._core import multiarray
    except ImportError:  # numpy < 2
        from numpy.core import multiarray
    return getattr(multiarray, "_set_madvise_hugepage", None)


def _huge_pages_compact(path: str = "/sys/kernel/mm/transparent_hugepage/defrag") -> bool:
    """Whether a huge page asked for by madvise is compacted for at the fault, in the
    faulting thread (Linux's THP ``defrag`` set to always, madvise or defer+madvise)."""
    try:
        with open(path) as f:
            mode = f.read().split("[", 1)[1].split("]", 1)[0]
    except (OSError, IndexError):
        return False
    return mode in ("always", "madvise", "defer+madvise")


_pages = {"lock": threading.Lock(), "depth": 0, "before": None}


@contextlib.contextmanager
def small_pages():
    """numpy's arrays made inside are not advised to use transparent huge pages, where the
    system would compact memory for them at the fault (:func:`_huge_pages_compact`); the
    advice as it was afterwards (the outermost of nested or concurrent uses restores it).

    A run at 10⁶ vertices makes about 3 GB of fresh arrays per iteration: the faults of
    their huge pages spent seconds of system time compacting memory, and an iteration took
    1.5 s longer with the advice than without (docs/performance.md, "A million edges")."""
    switch = _numpy_huge_page_switch() if _COMPACTS else None
    if switch is None:
        yield
        return
    with _pages["lock"]:
        if _pages["depth"] == 0:
            _pages["before"] = switch(False)
        _pages["depth"] += 1
    try:
        yield
    finally:
        with _pages["lock"]:
            _pages["depth"] -= 1
            if _pages["depth"] == 0:
                switch(_pages["before"])


_COMPACTS = _huge_pages_compact()
