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


#: :func:`small_pages` from this many vertices on. FHW, two threads, with and without the
#: advice alternated in one process: at 10⁶ the set-up took 7.9-8.1 s against 10.6-12.1 s and
#: a later iteration 9.4-10.3 s against 9.8-10.7 s; at 10⁵ and 3·10⁵ no difference showed;
#: the crowd of 1 000 × 30 edges was 0.17-0.45 s slower per iteration in three rounds of five
#: (and 0.01-0.05 s faster in two).
SMALL_PAGES_FROM = 500_000

_pages = {"lock": threading.Lock(), "depth": 0, "before": None}


@contextlib.contextmanager
def small_pages(vertices: int):
    """For a run of ``vertices`` from :data:`SMALL_PAGES_FROM` on: numpy's arrays made inside
    are not advised to use transparent huge pages where the system would compact memory for
    them at the fault (:func:`_huge_pages_compact`), and the advice is as it was afterwards
    (the outermost of nested or concurrent uses restores it). At 10⁶ vertices a run makes
    about 3 GB of fresh arrays per iteration, and compacting for their huge pages cost
    seconds of system time (docs/performance.md, "A million edges"); smaller runs gained
    nothing or lost (:data:`SMALL_PAGES_FROM`)."""
    switch = (_numpy_huge_page_switch() if _COMPACTS and vertices >= SMALL_PAGES_FROM
              else None)
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
