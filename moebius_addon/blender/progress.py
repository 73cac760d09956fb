"""Progress of the blocking calls scripts make (``relax_object``, ``convert_object``,
``identify_object``; the command line's lines): the one-time compiling of the kernels and, for a
relaxation, one line per iterate. Headless runs of minutes otherwise print nothing until done.
"""

from __future__ import annotations

import sys
from collections.abc import Callable

Progress = bool | Callable[[str], None] | None


def _print(line: str) -> None:
    print(f"moebius: {line}", file=sys.stdout, flush=True)


def reporter(progress: Progress) -> Callable[[str], None] | None:
    """What ``progress=`` asks for: None (False or None: silent), :func:`print` with the
    ``moebius:`` prefix (True), or the given callable, which receives each line."""
    if progress is None or progress is False:
        return None
    if progress is True:
        return _print
    if callable(progress):
        return progress
    raise TypeError(f"progress must be True, False or a callable taking a line, got "
                    f"{progress!r}")
