"""The two spellings of the iteration limit and the tolerance, in one table.

The core names them as scipy does (``max_iter``, ``tol``); the Blender layer and the command
line as the panel does (``max_iterations``, ``tolerance``, ``--max-iterations``,
``--tolerance``). Both spellings are accepted everywhere (docs/api.md, "Relaxation"): this
table is what every door reads.
"""

from __future__ import annotations

#: core name -> the Blender layer's (and the command line's) name of the same option
SPELLINGS = {"max_iter": "max_iterations", "tol": "tolerance"}


def take_spelling(options: dict, name: str, value, default):
    """``value`` of the option ``name`` (a key of :data:`SPELLINGS` or one of its values), or
    the value given under the other spelling, popped from ``options``; TypeError when both
    spellings were given (``value`` differs from ``default`` and the other is in
    ``options``)."""
    other = SPELLINGS.get(name) or next(k for k, v in SPELLINGS.items() if v == name)
    if other not in options:
        return value
    given = options.pop(other)
    if value != default:
        raise TypeError(f"{name} and {other} are the same option; give one of them")
    return given
