"""Refusals by memory estimate: a size whose arrays would not fit is refused before any work,
with the estimate in the message (a machine that swaps, or a process killed by the
out-of-memory handler, says nothing useful; numba's ``MemoryError`` says less)."""

from __future__ import annotations

import functools
import os

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
