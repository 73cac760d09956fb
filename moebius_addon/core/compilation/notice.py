"""Say when numba compiles: the one-time preparation of the numerical kernels.

The first use of a kernel after installing (or updating) compiles it, seconds to minutes on a
small machine (docs/blender.md, "Install"); later uses load it from numba's cache, which fires
no compile event. :func:`compiling` watches numba's ``"numba:compile"`` events so that scripts
and the command line can say why nothing moves yet, and how long it took.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from numba.core import event

#: What :func:`compiling` says at the first compile it sees.
PREPARING = ("compiling the numerical kernels (only on the first use after installing or "
             "updating; cached afterwards) …")


class CompileWatch(event.Listener):
    """Counts the kernels numba compiles (outermost compiles only) and their seconds, also per
    kernel (``by_kernel``: ``"module.qualname"`` → seconds); calls ``say(PREPARING)`` at the
    first."""

    def __init__(self, say: Callable[[str], None] | None = None) -> None:
        self.say = say
        self.kernels = 0
        self.seconds = 0.0
        self.by_kernel: dict[str, float] = {}
        self._depth = 0
        self._t0 = 0.0

    @property
    def active(self) -> bool:
        """Whether a compile is in progress."""
        return self._depth > 0

    def on_start(self, ev) -> None:
        if self._depth == 0:
            if self.kernels == 0 and self.say is not None:
                self.say(PREPARING)
            self._t0 = time.perf_counter()
        self._depth += 1

    def on_end(self, ev) -> None:
        self._depth -= 1
        if self._depth == 0:
            seconds = time.perf_counter() - self._t0
            self.kernels += 1
            self.seconds += seconds
            f = ev.data["dispatcher"].py_func
            name = f"{f.__module__.rsplit('.', 1)[-1]}.{f.__qualname__}"
            self.by_kernel[name] = self.by_kernel.get(name, 0.0) + seconds

    def summary(self) -> str:
        """``"compiled 12 kernels in 30.1 s"`` (empty if nothing was compiled)."""
        if not self.kernels:
            return ""
        return f"compiled {self.kernels} kernel{'s' * (self.kernels != 1)} in {self.seconds:.1f} s"


_WATCHES: list[CompileWatch] = []


@contextmanager
def compiling(say: Callable[[str], None] | None = None) -> Iterator[CompileWatch]:
    """Watch numba compiling inside the block: ``say(PREPARING)`` at the first compile, and
    ``say(watch.summary())`` at the end when something was compiled (inside another such
    block only the outer one speaks). Yields the :class:`CompileWatch` (``kernels``,
    ``seconds``, ``active``)."""
    # inside another watch (relax_object within the command line's) the outer one speaks
    watch = CompileWatch(None if _WATCHES else say)
    _WATCHES.append(watch)
    try:
        with event.install_listener("numba:compile", watch):
            yield watch
    finally:
        _WATCHES.remove(watch)
    if watch.kernels and watch.say is not None:
        say(watch.summary())
