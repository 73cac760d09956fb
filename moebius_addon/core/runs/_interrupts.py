"""Steps that an interruption (Ctrl+C, an exception from a callback) leaves resumable.

A step can be interrupted anywhere: inside the engine's update, where the factorization of the
last iterate has been set aside for its memory to be recycled and the new one is not built
yet (the next step then failed with ``'NoneType' object has no attribute 'pseudo_inverse'``),
or inside a numba kernel, where CPython reports the ``KeyboardInterrupt`` that arrives as the
kernel returns as ``SystemError: ... returned a result with an exception set`` (2 of 13
interrupts of a relaxation). The runs commit an accepted iterate whole (position,
energy, gradient, direction) only after its preparation finished, so the state they hold is
always the last accepted iterate's; what an interruption can leave half-made is the engine,
and :func:`resumable` rebuilds it there before the next step.
"""

from __future__ import annotations

import functools


def _keyboard_interrupt(err: BaseException) -> KeyboardInterrupt | None:
    """The KeyboardInterrupt behind a SystemError raised as a kernel returned, if any."""
    seen = err
    for _ in range(8):
        seen = seen.__cause__ or seen.__context__
        if seen is None:
            return None
        if isinstance(seen, KeyboardInterrupt):
            return seen
    return None


def as_interrupt(call):
    """Wrap ``call`` so that a ``SystemError`` carrying a ``KeyboardInterrupt`` (Ctrl+C as a
    numba kernel returned) is raised as that interrupt: for the calls outside a run's
    ``step()`` that reach kernels (a run's set-up and start checks, a refinement)."""

    @functools.wraps(call)
    def guarded(*args, **kwargs):
        try:
            return call(*args, **kwargs)
        except SystemError as err:
            interrupt = _keyboard_interrupt(err)
            if interrupt is None:
                raise
            raise interrupt from None

    return guarded


def resumable(step):
    """Wrap a run's ``step()``: after an interruption inside it, the next call first calls
    ``self._resume()`` (rebuild what the engine holds at the accepted iterate); a
    ``SystemError`` that carries a ``KeyboardInterrupt`` is raised as that interrupt."""

    stepped = as_interrupt(step)

    @functools.wraps(step)
    def guarded(self, *args, **kwargs):
        if getattr(self, "_interrupted", False) and not self.done:
            self._resume()
        self._interrupted = True
        more = stepped(self, *args, **kwargs)
        self._interrupted = False
        return more

    return guarded
