"""The check of a numeric option that every public door uses (``core.check_number``)."""

from __future__ import annotations

import numbers

import numpy as np


def check_number(name: str, value, low: float = -np.inf, *, above: bool = False,
                 integer: bool = False):
    """``value`` as a finite float (an int with ``integer``) at least ``low`` (above it with
    ``above``), else ValueError naming the option: NaN compares False with every bound, so
    plain comparisons let it through to a run that then stalls for no visible reason. Only
    real numbers count: text (``"3"``) and booleans (``True``) are refused, not converted.

    Parameters
    ----------
    name : str
        The option's name as the caller knows it (goes into the message).
    value : object
        What the caller passed.
    low : float
        Smallest allowed value (excluded with ``above``).
    integer : bool
        Require a whole number and return it as ``int``.
    """
    if not isinstance(value, numbers.Real) or isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be a number, got {value!r} "
                         f"({type(value).__name__})")
    try:
        x = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not np.isfinite(x) or x < low or (above and x == low):
        bound = "" if low == -np.inf else f" {'>' if above else '>='} {low:g}"
        raise ValueError(f"{name} must be a finite number{bound}, got {value!r}")
    if integer:
        if x != int(x):
            raise ValueError(f"{name} must be a whole number, got {value!r}")
        return int(value) if isinstance(value, numbers.Integral) else int(x)
    return x


def check_flag(name: str, value) -> bool:
    """``value`` as a bool, else ValueError naming the option: only ``True`` and ``False``
    (numpy's too) count, since ``bool("False")`` is True and a string flag would silently
    mean the opposite of what it says."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {value!r} "
                         f"({type(value).__name__})")
    return bool(value)
