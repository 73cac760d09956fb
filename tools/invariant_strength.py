"""How many knots of the table the invariants of ``core.identify`` tell apart, and what the
HOMFLY-PT polynomial would add.

Every prime knot up to 12 crossings and its mirror image (an amphicheiral knot once, as
``identify`` indexes them) is keyed by the Alexander and Jones polynomials, then with the
signature (``identify``'s key), then with KnotInfo's HOMFLY-PT polynomial as well (needs
``database_knotinfo``, the ``build`` extra; mirror image: ``v → −1/v``). Prints, for each key,
the entries that share it with another entry, the groups of those, and the chiral knots that
share it with their own mirror image only::

    .venv/bin/python tools/invariant_strength.py
"""

from __future__ import annotations

import importlib
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

identify = importlib.import_module("moebius_addon.core.topology.identify")


def homfly(vector: str) -> tuple:
    """KnotInfo's ``homfly_polynomial_vector`` ``[z_lo, z_hi, [v_lo, v_hi, c…], …]`` (powers
    of z² and v²) as a sorted tuple of ``((2 v-power, 2 z-power), coefficient)``."""
    v = json.loads(vector)
    z_lo = v[0]
    terms = []
    for k, row in enumerate(v[2:]):
        v_lo = row[0]
        terms += [((2 * (v_lo + j), 2 * (z_lo + k)), c) for j, c in enumerate(row[2:]) if c]
    return tuple(sorted(terms))


def mirror_homfly(h: tuple) -> tuple:
    # v^(2a) -> (-1/v)^(2a) = v^(-2a)
    return tuple(sorted(((-a, b), c) for (a, b), c in h))


def main() -> None:
    from database_knotinfo import link_list

    source = {r["name"]: r for r in link_list()[1:]}
    full, _ = identify._index()
    rows = []
    for key, entries in full.items():
        for e in entries:
            if e.kind != "knot":
                continue
            if e.crossings == 0:
                h = ((((0, 0), 1),))
            else:
                h = homfly(source[e.base]["homfly_polynomial_vector"])
                h = mirror_homfly(h) if e.mirror_of else h
            # key: (components, alexander, jones, linking, signature)
            rows.append((e, key[1], key[2], key[4], h))
    print(f"{len(rows)} knots up to 12 crossings with their mirror images")
    keys = {"Alexander + Jones": lambda r: (r[1], r[2]),
            "+ signature (identify)": lambda r: (r[1], r[2], r[3]),
            "+ signature + HOMFLY-PT": lambda r: (r[1], r[2], r[3], r[4]),
            "Alexander + Jones + HOMFLY-PT": lambda r: (r[1], r[2], r[4])}
    mirrored = {}
    for label, key in keys.items():
        groups: dict = {}
        for r in rows:
            groups.setdefault(key(r), []).append(r[0])
        shared = [g for g in groups.values() if len(g) > 1]
        own = [g for g in shared if len({e.base for e in g}) == 1]
        mirrored[label] = {g[0].base for g in own}
        print(f"{label:32s} {sum(map(len, shared)):5d} share their key with another entry, "
              f"{len(shared)} groups; {len(own)} chiral knots share it with their mirror image "
              f"alone ({', '.join(sorted(g[0].base for g in own)[:6])}, …)")
    parted = mirrored["Alexander + Jones"] - mirrored["+ signature (identify)"]
    order = {n: k for k, n in enumerate(table_names())}
    print(f"the signature tells {len(parted)} chiral knots from their mirror images: "
          f"{', '.join(sorted(parted, key=order.get))}")


def table_names() -> list[str]:
    from moebius_addon.core.topology import knots

    return knots.names("knot")


if __name__ == "__main__":
    main()
