"""Braid words and PD codes as people type them.

Braid words: ``1 -2 1 -2``, ``[1, -2, 1, -2]`` (KnotInfo), ``{3, {1, -2, 1, -2}}`` (LinkInfo:
strands first), ``BR[3, {1, -2, 1, -2}]`` (KnotTheory), ``s1 s2^-1 s1 s2^-1`` or
``σ1 σ2⁻¹ σ1 σ2⁻¹``. PD codes: ``[[1,5,2,4],[3,1,4,6],[5,3,6,2]]`` (KnotInfo),
``{{4, 1, 3, 2}, {2, 3, 1, 4}}`` (LinkInfo), ``PD[X[1,5,2,4], X[3,1,4,6], X[5,3,6,2]]``
(KnotTheory), rows of five with Knoodle's handedness last.
"""

from __future__ import annotations

import re

from .pd import PlanarDiagram, parse_pd

__all__ = ["parse_braid", "parse_notation"]

# A bracketed word, and LinkInfo's and KnotTheory's strands first: {3, {1, -2, 1, -2}}.
_LIST = r"[\[\{\(][^\[\]\{\}\(\)]*[\]\}\)]"
_ONE_LIST = re.compile(rf"\s*{_LIST}\s*")
_WITH_STRANDS = re.compile(rf"\s*[\[\{{\(]\s*[+-]?\d+\s*,\s*{_LIST}\s*[\]\}}\)]\s*")
_SIGMA = re.compile(r"[sσ]\s*(\d+)\s*(\^\s*\(?\s*-\s*1\s*\)?|⁻¹|\^-1|')?", re.IGNORECASE)


def parse_braid(text: str) -> tuple[list[int], int | None]:
    """``(word, strands)`` of a braid word typed as above; ``strands`` is None unless the text
    gives it (LinkInfo's and KnotTheory's forms). ``ValueError`` says what is wrong."""
    text = str(text).strip()
    if not text:
        raise ValueError("the braid word is empty: type generators as 1 -2 1 -2 (σ1 σ2⁻¹ σ1 "
                         "σ2⁻¹, KnotInfo's convention: σi is a positive crossing)")
    if _SIGMA.search(text) and not re.search(r"[\[\{]", text):
        word = []
        rest = _SIGMA.sub(" ", text)
        if rest.strip(" ,;*·."):
            raise ValueError(f"could not read {rest.strip()!r} in the braid word {text!r}")
        for m in _SIGMA.finditer(text):
            word.append(-int(m.group(1)) if m.group(2) else int(m.group(1)))
        return _checked(word, None, text)
    body = re.sub(r"^\s*BR\s*", "", text, flags=re.IGNORECASE)
    if re.search(r"[^\d\s,;+\-\[\]\{\}\(\)]", body):
        bad = re.search(r"[^\d\s,;+\-\[\]\{\}\(\)]+", body).group(0)
        raise ValueError(f"could not read {bad!r} in the braid word {text!r}: type whole "
                         "numbers, e.g. 1 -2 1 -2")
    body = _signed(body, text)
    inner = re.search(r"[\[\{\(][^\[\]\{\}\(\)]*[\]\}\)]", body)
    strands = None
    # the brackets' forms whole: numbers after a bracketed word were read into it, or skipped
    if re.search(r"[\[\]\{\}\(\)]", body) and not (_ONE_LIST.fullmatch(body)
                                                   or _WITH_STRANDS.fullmatch(body)):
        raise ValueError(f"could not read the brackets of the braid word {text!r}: write "
                         "1 -2 1 -2, [1, -2, 1, -2], {3, {1, -2, 1, -2}} or "
                         "BR[3, {1, -2, 1, -2}], with nothing before or after")
    if inner and re.search(r"^\s*[\[\{\(]\s*-?\d+\s*,\s*[\[\{\(]", body):
        strands = int(re.findall(r"-?\d+", body)[0])  # {3, {1, -2, 1, -2}}
        word = [int(v) for v in re.findall(r"-?\d+", inner.group(0))]
    else:
        word = [int(v) for v in re.findall(r"[+-]?\d+", body)]
    return _checked(word, strands, text)


def _signed(body: str, text: str) -> str:
    """``body`` with each sign joined to the number it is typed before: ``- 2`` is σ2⁻¹ as
    ``-2`` is (reading the number alone turned 4_1's ``1 - 2 1 - 2`` into 3_1's ``1 2 1 2``).
    A sign before no number (``1 2 -``, ``--2``) is refused: no reading of it is safe."""
    body = re.sub(r"([+-])\s+(?=\d)", r"\1", body)
    stray = re.search(r"[+-](?!\d)", body)
    if stray:
        raise ValueError(f"a sign {stray.group(0)!r} in the braid word {text!r} stands before "
                         "no generator: write σi⁻¹ as -i with one sign, e.g. 1 -2 1 -2")
    return body


def _checked(word: list[int], strands: int | None, text: str) -> tuple[list[int], int | None]:
    if not word:
        raise ValueError(f"no generators found in the braid word {text!r}")
    if 0 in word:
        raise ValueError(f"braid word {text!r}: generators are nonzero (σi as i, σi⁻¹ as -i)")
    need = max(abs(g) for g in word) + 1
    if strands is not None and strands < need:
        raise ValueError(f"braid word {text!r} uses σ{need - 1}, which needs {need} strands, "
                         f"not {strands}")
    return word, strands


def is_pd(text: str) -> bool:
    """Whether ``text`` is written as a PD code (``X[…]``, or groups of numbers inside one more
    pair of brackets, ``[[1,2,3,4]]`` too) rather than a braid word."""
    text = str(text)
    if re.search(r"X\s*\[", text) or re.match(r"^\s*PD\s*\[", text):
        return True
    if re.match(r"^\s*[\[\{\(]\s*[\[\{\(]", text):  # a list of crossings, even of one
        return True
    groups = re.findall(r"[\[\{\(][^\[\]\{\}\(\)]*[\]\}\)]", text)
    loose = re.sub(r"[\[\{\(][^\[\]\{\}\(\)]*[\]\}\)]", " ", text)
    return len(groups) >= 2 and not re.search(r"\d", loose)


def parse_notation(text: str) -> tuple[str, object]:
    """``("pd", PlanarDiagram)`` or ``("braid", (word, strands))`` from a typed PD code or
    braid word (which one is read from its brackets: a PD code is a list of crossings)."""
    if is_pd(text):
        return "pd", parse_pd(text)
    return "braid", parse_braid(text)


def describe(kind: str, value) -> str:
    """A short label for a notation, e.g. ``braid 1 -2 1 -2`` or ``PD code of 3 crossings``."""
    if kind == "braid":
        word, strands = value
        s = " ".join(str(g) for g in word)
        return f"braid {s}" + (f" ({strands} strands)" if strands else "")
    d: PlanarDiagram = value
    return f"PD code of {d.crossings} crossing{'' if d.crossings == 1 else 's'}"
