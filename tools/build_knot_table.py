"""Build ``moebius_addon/core/data/knot_table.json.gz`` from KnotInfo and LinkInfo.

Run at build time only (``pip install database_knotinfo``, the ``build`` extra)::

    .venv/bin/python tools/build_knot_table.py

The add-on ships the compressed JSON and never imports ``database_knotinfo``. The table holds
every prime knot up to 12 crossings (0_1, 3_1 … 12n_888: 2 978 entries with the unknot) and
every prime link up to 11 crossings in each orientation LinkInfo lists (L2a1{0} …
L11n459{1,1,1}: 4 188 entries), each with KnotInfo's or LinkInfo's braid word (σ_i^{±1} written
±i, 1-based) and the invariants identification needs: the Alexander polynomial (KnotInfo's for
knots; for links the one-variable polynomial from LinkInfo's Conway polynomial), the Jones
polynomial, the determinant, the signature, and for links the linking numbers.

Every entry is checked here against its source before it is written: the closure of the braid
word, as a planar diagram (``core.pd.from_braid``), must have KnotInfo's Jones and Alexander
polynomials (computed by ``core.jones`` and ``core.invariants``), its signature
(``core.goeritz``), and, for a link, LinkInfo's number of components and linking matrix (up to
the order of the components). Where a link's
braid closes to another orientation of the same link (LinkInfo's braid of L10n99{0,0,0} does),
the components to reverse are found and stored (``reverse``), and the Jones polynomial is
checked on the reversed diagram. The build stops if any entry fails.
"""

from __future__ import annotations

import argparse
import gzip
import io
import itertools
import json
import re
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from moebius_addon.core.topology import goeritz, invariants, jones, pd  # noqa: E402

OUT = ROOT / "moebius_addon" / "core" / "data" / "knot_table.json.gz"
MAX_KNOT_CROSSINGS = 12
MAX_LINK_CROSSINGS = 11

# Common names (Rolfsen's table, folklore, Wikipedia's list of prime knots); the first is the
# one a description shows. Each is also an alias of the name it follows.
KNOT_NAMES = {
    "0_1": ["unknot"],
    "3_1": ["trefoil", "trefoil knot", "right-handed trefoil", "overhand knot",
            "torus knot T(2,3)"],
    "4_1": ["figure-eight knot", "figure-eight", "figure eight", "figure8", "figure_eight",
            "Listing's knot", "Savoy knot"],
    "5_1": ["cinquefoil", "pentafoil", "Solomon's seal knot", "torus knot T(2,5)"],
    "5_2": ["three-twist knot"],
    "6_1": ["stevedore knot", "stevedore"],
    "6_2": ["Miller Institute knot"],
    "7_1": ["septafoil", "heptafoil", "torus knot T(2,7)"],
    "7_2": ["five-twist knot"],
    "7_4": ["endless knot"],
    "8_1": ["six-twist knot"],
    "8_18": ["carrick mat"],
    "8_19": ["torus knot T(3,4)"],
    "9_1": ["torus knot T(2,9)"],
    "10_124": ["torus knot T(3,5)"],
    "10_161": ["Perko pair", "Perko knot"],
    "11n_34": ["Conway knot"],
    "11n_42": ["Kinoshita–Terasaka knot", "Kinoshita-Terasaka knot"],
}
MIRROR_ALIASES = {"left-handed trefoil": "m3_1"}
# Links: the common name belongs to the link whatever the orientation; the alias names the
# orientation a braid of positive crossings (or the usual picture) gives.
LINK_NAMES = {
    "L2a1": (["Hopf link"], "L2a1{1}"),
    "L4a1": (["Solomon's knot", "Solomon's link", "King Solomon's knot", "torus link T(2,4)"],
             "L4a1{1}"),
    "L5a1": (["Whitehead link"], "L5a1{0}"),
    "L6a4": (["Borromean rings"], "L6a4{0,0}"),
}

# KnotInfo leaves these blank for the unknot.
UNKNOT = {"braid_index": 1, "unknotting_number": 0, "genus": 0, "determinant": 1,
          "symmetry": "fully amphicheiral", "signature": 0}


def _int_or_none(text: str) -> int | None:
    text = text.strip()
    return int(text) if text.lstrip("-").isdigit() else None


def _ints(text: str) -> list[int]:
    return [int(x) for x in re.findall(r"-?\d+", text)]


def _jones_of(vector: str, knot: bool) -> dict[int, int]:
    """KnotInfo's vector ``[low, high, coefficients…]`` in t (knots) or LinkInfo's in
    x = t^(1/2), as ``{exponent of x: coefficient}``."""
    v = _ints(vector)
    if len(v) == 1:  # the unknot: "1"
        return {0: v[0]}
    step = 2 if knot else 1
    return {step * v[0] + step * k: c for k, c in enumerate(v[2:]) if c}


def _stored_jones(poly: dict[int, int]) -> list[int]:
    """``{exponent of x: coefficient}`` as ``[lowest exponent of x, c_0, c_1, …]`` with the
    exponents stepping by 2 (Jones polynomials of knots and links have one parity)."""
    lo, hi = min(poly), max(poly)
    return [lo] + [poly.get(e, 0) for e in range(lo, hi + 1, 2)]


def _conway_to_alexander(text: str) -> list[int]:
    """LinkInfo's Conway polynomial ∇(z) as the Alexander polynomial Δ(t) = ∇(t^½ − t^−½),
    normalized like ``invariants.alexander_polynomial`` (lowest power t⁰, positive)."""
    poly: dict[int, int] = {}  # exponent of x = t^(1/2)
    terms = re.findall(r"([+-]?)(\d*)\*?(z(?:\^(\d+))?)?", text.replace(" ", ""))
    for sgn, num, z, pw in terms:
        if not num and not z:
            continue
        c = int(num or 1) * (-1 if sgn == "-" else 1)
        k = (int(pw) if pw else 1) if z else 0
        # (x - 1/x)^k = sum_i binom(k, i) x^(k-i) (-1/x)^i
        for i in range(k + 1):
            e = k - 2 * i
            poly[e] = poly.get(e, 0) + c * _binom(k, i) * (-1) ** i
    poly = {e: c for e, c in poly.items() if c}
    if not poly:
        return [0]
    lo, hi = min(poly), max(poly)
    coeffs = [poly.get(e, 0) for e in range(lo, hi + 1, 2)]
    return coeffs if coeffs[0] > 0 else [-c for c in coeffs]


def _binom(n: int, k: int) -> int:
    from math import comb

    return comb(n, k)


def _upper(L: np.ndarray) -> list[int]:
    K = len(L)
    return [int(L[a, b]) for a in range(K) for b in range(a + 1, K)]


def _matching_orientation(d: pd.PlanarDiagram, want: np.ndarray, jones_want: dict[int, int]
                          ) -> tuple[list[int], pd.PlanarDiagram] | None:
    """Components to reverse so that the closure has LinkInfo's linking matrix (up to the order
    of the components) and Jones polynomial; None if no choice does."""
    K = len(d.components())
    for r in range(K):
        for flip in itertools.combinations(range(1, K), r):
            e = d.reverse(flip) if flip else d
            L = pd.linking_matrix(e)
            if not any((L[np.ix_(p, p)] == want).all() for p in itertools.permutations(range(K))):
                continue
            if jones.jones(e) == jones_want:
                return list(flip), e
    return None


def _choose_braid(words: list[list[int]]) -> list[int]:
    """Of several braid words (KnotInfo gives two for a few knots), the one whose closure
    is shortest as ``knots.braid_closure`` lays it out: fewest slots times strands."""
    return min(words, key=lambda w: (max(len(w), 3) * (max(map(abs, w)) + 1), len(w)))


def knot_rows(database) -> tuple[list, list[str]]:
    rows, failures = [], []
    for r in database.link_list()[1:]:
        name = r["name"]
        crossings = int(r["crossing_number"])
        if crossings > MAX_KNOT_CROSSINGS:
            continue
        if name == "0_1":
            rows.append([name, [], 0, True, UNKNOT["braid_index"], 0, 0, 1,
                         UNKNOT["symmetry"], 0, [1], [0, 1]])
            continue
        b = json.loads(r["braid_notation"])
        word = _choose_braid(b if isinstance(b[0], list) else [b])
        d = pd.from_braid(word)
        want_jones = _jones_of(r["jones_polynomial_vector"], knot=True)
        want_alex = _ints(r["alexander_polynomial_vector"])[2:]
        got_jones = jones.jones(d)
        got_alex = invariants.alexander_polynomial(d)
        if got_jones != want_jones or got_alex != want_alex:
            failures.append(f"{name}: braid {word} closes to Jones {got_jones}, Alexander "
                            f"{got_alex}; KnotInfo: {want_jones}, {want_alex}")
            continue
        det = _int_or_none(r["determinant"])
        if det != abs(sum(c * (-1) ** k for k, c in enumerate(got_alex))):
            failures.append(f"{name}: determinant {det} is not |Δ(-1)|")
        sig = goeritz.signature(d)
        if sig != _int_or_none(r["signature"]):
            failures.append(f"{name}: signature {sig}, KnotInfo: {r['signature']}")
        rows.append([
            name, word, crossings, r["alternating"] == "Y", _int_or_none(r["braid_index"]),
            _int_or_none(r["unknotting_number"]), _int_or_none(r["three_genus"]), det,
            r["symmetry_type"], sig, got_alex,
            _stored_jones(got_jones),
        ])
    return rows, failures


def link_rows(database) -> tuple[list, list[str]]:
    rows, failures = [], []
    for r in database.link_list(proper_links=True)[1:]:
        name = r["name"]
        crossings = int(r["crossing_number"])
        if crossings > MAX_LINK_CROSSINGS:
            continue
        nums = _ints(r["braid_notation"])
        strands, word = nums[0], nums[1:]
        d = pd.from_braid(word, strands)
        K = int(r["components"])
        want_lk = np.array([_ints(row) for row in re.findall(r"\{([^{}]*)\}",
                                                              r["linking_matrix"])])
        want_jones = _jones_of(r["jones_polynomial_vector"], knot=False)
        if len(d.components()) != K or d.loops:
            failures.append(f"{name}: braid {word} closes to {len(d.components())} components "
                            f"(+{d.loops} loops), LinkInfo says {K}")
            continue
        found = _matching_orientation(d, want_lk, want_jones)
        if found is None:
            failures.append(f"{name}: no orientation of the closure of {word} has LinkInfo's "
                            f"linking matrix and Jones polynomial")
            continue
        flip, e = found
        alex = invariants.alexander_polynomial(e)
        want_alex = _conway_to_alexander(r["conway_polynomial"])
        if alex != want_alex:
            failures.append(f"{name}: Alexander {alex}, from LinkInfo's Conway polynomial "
                            f"{want_alex}")
            continue
        det = _int_or_none(r["determinant"])
        if det != abs(sum(c * (-1) ** k for k, c in enumerate(alex))):
            failures.append(f"{name}: determinant {det} is not |Δ(-1)|")
        sig = goeritz.signature(e)
        if sig != _int_or_none(r["signature"]):
            failures.append(f"{name}: signature {sig}, LinkInfo: {r['signature']}")
        rows.append([
            name, strands, word, flip, crossings, K, r["alternating"] == "Y", det,
            _upper(pd.linking_matrix(e)), alex, _stored_jones(want_jones), sig,
        ])
    return rows, failures


def aliases(knots: list, links: list) -> dict[str, str]:
    table = {}
    names = {row[0] for row in knots} | {row[0] for row in links}
    for name, words in KNOT_NAMES.items():
        assert name in names, name
        for w in words:
            table[w] = name
    for w, name in MIRROR_ALIASES.items():
        table[w] = name
    for _base, (words, name) in LINK_NAMES.items():
        assert name in names, name
        for w in words:
            table[w] = name
    return table


def build() -> dict:
    import database_knotinfo

    knots, f1 = knot_rows(database_knotinfo)
    links, f2 = link_rows(database_knotinfo)
    failures = f1 + f2
    if failures:
        raise SystemExit("entries that are not what KnotInfo/LinkInfo say:\n" +
                         "\n".join(failures))
    return {
        "source": "KnotInfo (https://knotinfo.org) and LinkInfo "
        "(https://link-info-repo.onrender.com), C. Livingston and A. H. Moore, via the PyPI "
        f"package database_knotinfo {database_knotinfo.version()} (GPL); generated by "
        "tools/build_knot_table.py",
        "conventions": "braid: sigma_i^{+1} = i, sigma_i^{-1} = -i, 1-based, sigma_i a "
        "positive crossing (3_1 = [1,1,1] is KnotInfo's, the positive trefoil); jones: "
        "[lowest exponent of x = t^(1/2), coefficients of x^lo, x^(lo+2), ...]; alexander: "
        "coefficients of t^0, t^1, ... (links: the one-variable polynomial, Conway-"
        "normalized); linking: the upper triangle of the linking matrix, row by row, for the "
        "components of the closed braid in the order of their lowest strand after reversing "
        "those in reverse",
        "knot_fields": ["name", "braid", "crossings", "alternating", "braid_index",
                        "unknotting_number", "genus", "determinant", "symmetry", "signature",
                        "alexander", "jones"],
        "link_fields": ["name", "strands", "braid", "reverse", "crossings", "components",
                        "alternating", "determinant", "linking", "alexander", "jones",
                        "signature"],
        "knot_names": KNOT_NAMES,
        "link_names": {base: words for base, (words, _) in LINK_NAMES.items()},
        "aliases": aliases(knots, links),
        "knots": knots,
        "links": links,
    }


def write(table: dict, out: Path) -> int:
    text = json.dumps(table, ensure_ascii=False, separators=(",", ":"))
    buf = io.BytesIO()
    # mtime=0 and no file name: the same table gives the same bytes
    with gzip.GzipFile(fileobj=buf, mode="wb", compresslevel=9, mtime=0, filename="") as f:
        f.write(text.encode("utf-8"))
    out.write_bytes(buf.getvalue())
    return len(text)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    table = build()
    raw = write(table, args.out)
    print(f"wrote {len(table['knots'])} knots and {len(table['links'])} links to {args.out}: "
          f"{args.out.stat().st_size} bytes ({raw} bytes of JSON before compression)")


if __name__ == "__main__":
    main()
