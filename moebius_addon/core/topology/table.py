"""The shipped table of prime knots (up to 12 crossings) and prime links (up to 11 crossings):
names, braid words, invariants; lookup by name, alias or mirror; search.

``data/knot_table.json.gz`` is built by ``tools/build_knot_table.py`` from KnotInfo and LinkInfo
(``database_knotinfo``, a build-time dependency only), which checked every braid word against
the source's Jones and Alexander polynomials and linking matrix. Names are KnotInfo's and
LinkInfo's: ``3_1`` … ``10_165``, ``11a_1`` … ``12n_888``, ``L2a1{0}`` … ``L11n459{1,1,1}``
(a link in each orientation LinkInfo lists: the braces say which components are reversed).
The mirror image of an entry is its name with ``m`` before it (``m3_1``, the left-handed
trefoil); ``3_1*``, ``mirror of 3_1`` and ``3_1 mirror`` are read the same way.
"""

from __future__ import annotations

import difflib
import gzip
import json
import re
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

__all__ = ["Entry", "entries", "entry", "lookup", "names", "search"]

_DATA = Path(__file__).resolve().parents[1] / "data" / "knot_table.json.gz"


@dataclass(frozen=True)
class Entry:
    """One knot or link of the table (or the mirror image of one).

    ``jones`` is ``(lowest exponent of x, coefficients)`` in ``x = t^(1/2)`` with the exponents
    stepping by 2; ``alexander`` the coefficients of ``t^0, t^1, …``; ``linking`` the upper
    triangle of the linking matrix (row by row) of the curve :func:`knots.named` makes;
    ``signature`` KnotInfo's or LinkInfo's (3_1: −2; a link's for the orientation named)."""

    name: str
    kind: str  # "knot" or "link"
    braid: tuple[int, ...]
    strands: int
    crossings: int
    components: int
    alternating: bool
    determinant: int
    alexander: tuple[int, ...]
    jones: tuple[int, tuple[int, ...]]
    linking: tuple[int, ...] = ()
    reverse: tuple[int, ...] = ()
    signature: int | None = None
    common: tuple[str, ...] = ()
    extra: dict = field(default_factory=dict, compare=False)
    mirror_of: str | None = None

    @property
    def base(self) -> str:
        """The table name without the mirror prefix (``3_1`` for ``m3_1``)."""
        return self.mirror_of or self.name

    @property
    def unoriented(self) -> str:
        """A link's name without its orientation (``L6a4`` for ``L6a4{0,0}``)."""
        return self.base.split("{")[0]

    @property
    def amphicheiral(self) -> bool | None:
        """Whether the knot is its own mirror image (KnotInfo's symmetry type); None for links,
        whose table does not say."""
        sym = self.extra.get("symmetry")
        return None if sym is None else "amphicheiral" in sym

    def linking_matrix(self) -> list[list[int]]:
        K = self.components
        L = [[0] * K for _ in range(K)]
        it = iter(self.linking)
        for a in range(K):
            for b in range(a + 1, K):
                L[a][b] = L[b][a] = next(it)
        return L

    @property
    def description(self) -> str:
        parts = [self.common[0]] if self.common else []
        if self.mirror_of:
            parts.insert(0, f"mirror image of {self.mirror_of}")
        if self.kind == "link":
            parts.append(f"{self.components}-component link")
        parts.append(f"{self.crossings} crossings" if self.crossings else "no crossings")
        parts.append("alternating" if self.alternating else "non-alternating")
        if self.extra.get("symmetry"):
            parts.append(self.extra["symmetry"])
        return ", ".join(parts)

    def mirror(self) -> Entry:
        """The mirror image (every crossing switched): ``m`` + name, or back."""
        lo, coeffs = self.jones
        hi = lo + 2 * (len(coeffs) - 1)
        return Entry(
            name=self.mirror_of if self.mirror_of else "m" + self.name,
            kind=self.kind, braid=tuple(-g for g in self.braid), strands=self.strands,
            crossings=self.crossings, components=self.components,
            alternating=self.alternating, determinant=self.determinant,
            alexander=self.alexander, jones=(-hi, tuple(reversed(coeffs))),
            linking=tuple(-v for v in self.linking), reverse=self.reverse,
            signature=None if self.signature is None else -self.signature,
            common=self.common if self.mirror_of else _mirror_common(self),
            extra=self.extra, mirror_of=None if self.mirror_of else self.name)


def _mirror_common(e: Entry) -> tuple[str, ...]:
    if e.amphicheiral:
        return e.common
    return tuple(n.replace("right-handed", "left-handed") for n in e.common)


@cache
def _load() -> dict:
    with gzip.open(_DATA, "rt", encoding="utf-8") as f:
        raw = json.load(f)
    table: dict[str, Entry] = {}
    knot_names = raw["knot_names"]
    link_names = raw["link_names"]
    for row in raw["knots"]:
        r = dict(zip(raw["knot_fields"], row, strict=True))
        word = tuple(r["braid"])
        table[r["name"]] = Entry(
            name=r["name"], kind="knot", braid=word,
            strands=max((abs(g) for g in word), default=0) + 1, crossings=r["crossings"],
            components=1, alternating=r["alternating"], determinant=r["determinant"],
            alexander=tuple(r["alexander"]), jones=(r["jones"][0], tuple(r["jones"][1:])),
            signature=r["signature"], common=tuple(knot_names.get(r["name"], ())),
            extra={k: r[k] for k in ("braid_index", "unknotting_number", "genus", "symmetry")})
    for row in raw["links"]:
        r = dict(zip(raw["link_fields"], row, strict=True))
        table[r["name"]] = Entry(
            name=r["name"], kind="link", braid=tuple(r["braid"]), strands=r["strands"],
            crossings=r["crossings"], components=r["components"],
            alternating=r["alternating"], determinant=r["determinant"],
            alexander=tuple(r["alexander"]), jones=(r["jones"][0], tuple(r["jones"][1:])),
            linking=tuple(r["linking"]), reverse=tuple(r["reverse"]),
            signature=r["signature"], common=tuple(link_names.get(r["name"].split("{")[0], ())))
    aliases = {_normal(a): n for a, n in raw["aliases"].items()}
    default_orientation: dict[str, str] = {}
    for n in table:
        if "{" in n:
            default_orientation.setdefault(n.split("{")[0], n)
    for n in raw["aliases"].values():  # the orientation an alias names is the default
        if "{" in n:
            default_orientation[n.split("{")[0]] = n
    return {"entries": table, "aliases": aliases, "lower": {n.lower(): n for n in table},
            "unoriented": {k.lower(): v for k, v in default_orientation.items()},
            "source": raw["source"]}


def _normal(text: str) -> str:
    """Aliases compare without case, apostrophes, hyphens, underscores or extra spaces."""
    text = text.lower().replace("’", "").replace("'", "").replace("–", " ")
    return " ".join(re.sub(r"[-_]", " ", text).split())


def names(kind: str | None = None) -> list[str]:
    """Every table name, knots by crossing number (``0_1``, ``3_1``, …, ``12n_888``), then links
    (``L2a1{0}``, …, ``L11n459{1,1,1}``); ``kind`` "knot" or "link" for one of them."""
    if kind not in (None, "knot", "link"):
        raise ValueError(f"kind must be 'knot', 'link' or None, got {kind!r}")
    return [n for n, e in _load()["entries"].items() if kind is None or e.kind == kind]


def entries() -> list[Entry]:
    """Every table entry (not the mirror images), in the order of :func:`names`."""
    return list(_load()["entries"].values())


def source() -> str:
    """Where the table comes from (KnotInfo, LinkInfo, the database version)."""
    return _load()["source"]


_MIRROR = (re.compile(r"^\s*m\s*\(\s*(.+?)\s*\)\s*$"), re.compile(r"^\s*mirror(?: image)?"
                                                                     r"(?: of)?\s+(.+?)\s*$"),
           re.compile(r"^\s*(.+?)\s*\*\s*$"), re.compile(r"^\s*(.+?)\s+mirror\s*$"))


def lookup(name: str) -> str | None:
    """The table name (or ``m`` + table name) that ``name`` means, or None: a table name in any
    case, an alias (``"trefoil"``, ``"Borromean rings"``), a link without its orientation
    (``"L6a4"``: the orientation its alias names, else the first listed), or a mirror
    (``"m3_1"``, ``"3_1*"``, ``"mirror of trefoil"``)."""
    text = str(name).strip()
    t = _load()
    key = _resolve(text, t)
    if key is not None:
        return key
    for pattern in _MIRROR:
        m = pattern.match(text)
        if m:
            key = _resolve(m.group(1), t)
            if key is not None:
                return key[1:] if key.startswith("m") and key[1:] in t["entries"] else "m" + key
    if text[:1] in "mM" and len(text) > 1:
        key = _resolve(text[1:], t)
        if key is not None and not key.startswith("m"):
            return "m" + key
    return None


def _resolve(text: str, t: dict) -> str | None:
    low = text.strip().lower()
    if low in t["lower"]:
        return t["lower"][low]
    if low in t["unoriented"]:
        return t["unoriented"][low]
    return t["aliases"].get(_normal(text))


def entry(name: str) -> Entry:
    """The entry ``name`` means (:func:`lookup`); ``ValueError`` naming close matches if none."""
    key = lookup(name)
    if key is None:
        near = search(name, limit=8) or close_matches(name)
        hint = f"; did you mean {', '.join(near)}?" if near else (
            "; names look like 3_1, 10_161, 11a_1, 12n_888, L2a1{0}, L6a4{0,0}, or 'trefoil', "
            "'Borromean rings'; core.knots.search(text) finds them")
        raise ValueError(f"unknown knot or link {name!r}{hint}")
    t = _load()["entries"]
    return t[key] if key in t else t[key[1:]].mirror()


@cache
def _haystacks() -> dict[str, str]:
    return {n: " ".join([n.lower(), _normal(" ".join(e.common)), _normal(e.description)])
            for n, e in _load()["entries"].items()}


def search(text: str, limit: int | None = 50) -> list[str]:
    """Names matching ``text``, best first: the entry ``text`` names exactly (name, alias or
    mirror), then names starting with it, then entries whose name, common names or
    description contain every word of it (``"borromean"``, ``"10_16"``, ``"torus"``,
    ``"amphicheiral 8"``). An empty text lists the table from the start."""
    text = str(text).strip()
    out: list[str] = []
    exact = lookup(text) if text else None
    if exact:
        out.append(exact)
    low = text.lower()
    words = _normal(text).split()
    prefix, rest = [], []
    for n, hay in _haystacks().items():
        if n == exact:
            continue
        if low and n.lower().startswith(low):
            prefix.append(n)
            continue
        if all(w in hay for w in words):
            rest.append(n)
        if limit is not None and len(out) + len(prefix) >= limit:
            break
    out += prefix + rest
    return out[:limit] if limit is not None else out


def close_matches(text: str, limit: int = 5, extra: tuple[str, ...] = ()) -> list[str]:
    """Names and aliases spelled like ``text`` (difflib's ratio at least 0.75), best first:
    what a "did you mean …?" offers when :func:`search` finds nothing (``"trefoyl"`` →
    ``["trefoil"]``). ``extra``: more names to offer (the Blender catalogue's generators)."""
    t = _load()
    words = [*t["aliases"], *t["lower"], *(_normal(e) for e in extra)]
    return difflib.get_close_matches(_normal(str(text)), words, n=limit, cutoff=0.75)
