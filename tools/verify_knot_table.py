"""Verify every entry of the shipped knot table on the curve ``core.knots.named`` makes of it.

For each name (knots and links, or a seeded sample) the default curve is built and checked:

* ``check``: it passes the start check (``core.check_polygon``, coarseness included);
* ``topoly``: its Jones polynomial computed by topoly (GPL, a test dependency, an implementation
  independent of ours) from the polygon's coordinates equals the table's, which are KnotInfo's
  and LinkInfo's values (tools/build_knot_table.py);
* ``ours``: the invariants ``core.identify`` reads off a projection of the curve (components,
  Alexander and Jones polynomials, signature) equal the table's, its linking matrix equals the
  table's in the component order of the curve, and the name is among those ``identify``
  returns.

With ``--pd`` each entry is drawn instead from KnotInfo's or LinkInfo's own PD code
(``core.knots.from_pd``; needs ``database_knotinfo``) and checked the same way (start check at
the default edge count, ``identify`` names it), into ``verify_pd_drawing.jsonl``.

Results go to a JSON-lines file, one line per name; a run skips the names already there, so it
can be stopped and started again. It prints counts as it goes and a summary at the end::

    .venv/bin/python tools/verify_knot_table.py                 # the whole table (hours)
    .venv/bin/python tools/verify_knot_table.py --sample 50     # a seeded sample
    .venv/bin/python tools/verify_knot_table.py --summary       # counts of the file so far
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
from functools import cache
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from moebius_addon.core import check_polygon, contact_ratio, identify  # noqa: E402
from moebius_addon.core.topology import knots, table  # noqa: E402

OUT = ROOT / "out" / "verify_knot_table.jsonl"


def topoly_jones(P, seed: int = 2024) -> dict[int, int]:
    """topoly's Jones polynomial of the polygon(s) as ``{exponent of t^(1/2): coefficient}``
    (a random rotation first: flat inputs can hang topoly)."""
    import topoly

    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    R = q * np.sign(np.diag(r))
    parts = P if isinstance(P, list) else [P]
    arg = [(c @ R.T).tolist() for c in parts] if isinstance(P, list) else (P @ R.T).tolist()
    del parts
    text = topoly.jones(arg, closure=topoly.Closure.CLOSED, max_cross=60, translate=False,
                        minimal=False, poly_reduce=False, run_parallel=False)
    return parse_topoly(str(text))


def parse_topoly(text: str) -> dict[int, int]:
    """``"- t^0.5 - t^2.5"``, ``"4 - t^-3.0 + 3t^-2.0"`` → ``{1: -1, 5: -1}``, …"""
    poly: dict[int, int] = {}
    for sgn, num, t, power in re.findall(r"([+-]?)\s*(\d*)\s*(t(?:\^(-?[\d.]+))?)?",
                                         text.replace(" ", "")):
        if not num and not t:
            continue
        c = int(num or 1) * (-1 if sgn == "-" else 1)
        e = round(2 * float(power)) if power else (2 if t else 0)
        poly[e] = poly.get(e, 0) + c
    return {e: c for e, c in poly.items() if c}


def table_jones(e: table.Entry) -> dict[int, int]:
    lo, coeffs = e.jones
    return {lo + 2 * k: c for k, c in enumerate(coeffs) if c}


def verify(name: str, use_topoly: bool = True) -> dict:
    e = table.entry(name)
    t0 = time.perf_counter()
    P = knots.named(name)
    parts = P if isinstance(P, list) else [P]
    row = {"name": name, "n": int(sum(len(c) for c in parts)), "components": len(parts)}
    try:
        check_polygon(P)
        row["check"] = True
    except ValueError as err:
        row["check"] = False
        row["check_error"] = str(err)
    row["contact_ratio"] = round(float(contact_ratio(P)), 3)
    t1 = time.perf_counter()
    r = identify(P)
    fp = r.fingerprint
    ours_jones = dict(fp.jones) if fp.jones is not None else None
    row["ours"] = bool(fp.components == e.components and list(fp.alexander) == list(e.alexander)
                       and ours_jones == table_jones(e) and fp.signature == e.signature
                       and r.linking_matrix == (e.linking_matrix() if e.components > 1
                                                else [[0]])
                       and name in r.names)
    row["identified"] = list(r.names)
    row["diagram_crossings"] = r.crossings
    row["identify_seconds"] = round(time.perf_counter() - t1, 4)
    if use_topoly:
        t2 = time.perf_counter()
        got = topoly_jones(P)
        row["topoly"] = got == table_jones(e)
        if not row["topoly"]:
            row["topoly_jones"] = sorted(got.items())
        row["topoly_seconds"] = round(time.perf_counter() - t2, 3)
    row["seconds"] = round(time.perf_counter() - t0, 3)
    return row


@cache
def _pd_codes() -> dict[str, str]:
    import database_knotinfo

    codes = {r["name"]: r["pd_notation"] for r in database_knotinfo.link_list()[1:]}
    codes.update({r["name"]: r["pd_notation_vector"]
                  for r in database_knotinfo.link_list(proper_links=True)[1:]})
    return codes


def verify_pd(name: str) -> dict:
    """Draw the entry from its source's PD code and check the curve."""
    t0 = time.perf_counter()
    row = {"name": name}
    if name == "0_1":
        return {**row, "check": True, "ours": True, "n": 0, "contact_ratio": 0.0,
                "identified": ["0_1"], "identify_seconds": 0.0, "seconds": 0.0}
    P = knots.from_pd(_pd_codes()[name])
    parts = P if isinstance(P, list) else [P]
    row["n"] = int(sum(len(c) for c in parts))
    try:
        check_polygon(P)
        row["check"] = True
    except ValueError as err:
        row["check"] = False
        row["check_error"] = str(err)
    row["contact_ratio"] = round(float(contact_ratio(P)), 3)
    t1 = time.perf_counter()
    r = identify(P)
    row["identify_seconds"] = round(time.perf_counter() - t1, 4)
    row["identified"] = list(r.names)
    row["ours"] = name in r.names
    row["seconds"] = round(time.perf_counter() - t0, 3)
    return row


def summary(path: Path) -> dict:
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    out = {"entries": len(rows)}
    for key in ("check", "ours", "topoly"):
        out[key] = sum(1 for r in rows if r.get(key) is True)
        out[key + "_failed"] = [r["name"] for r in rows if r.get(key) is False]
    out["all_three"] = sum(1 for r in rows if r.get("check") and r.get("ours")
                           and r.get("topoly"))
    out["unique"] = sum(1 for r in rows if r.get("identified") == [r["name"]])
    if rows:
        out["max_n"] = max(r["n"] for r in rows)
        out["min_contact_ratio"] = min(r["contact_ratio"] for r in rows)
        out["max_identify_seconds"] = max(r["identify_seconds"] for r in rows)
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=OUT)
    p.add_argument("--sample", type=int, default=None, help="a seeded sample of this size")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--kind", choices=["knot", "link"], default=None)
    p.add_argument("--no-topoly", action="store_true")
    p.add_argument("--summary", action="store_true", help="only print the counts so far")
    p.add_argument("--pd", action="store_true",
                   help="draw each entry from its source's PD code instead (core.knots.from_pd)")
    args = p.parse_args()
    if args.pd and args.out == OUT:
        args.out = OUT.with_name("verify_pd_drawing.jsonl")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    if args.summary:
        print(json.dumps(summary(args.out), indent=1))
        return
    names = knots.names(args.kind)
    if args.sample:
        rng = np.random.default_rng(args.seed)
        names = [names[i] for i in sorted(rng.choice(len(names), args.sample, replace=False))]
    done = set()
    if args.out.exists():
        done = {json.loads(line)["name"] for line in args.out.read_text().splitlines()
                if line.strip()}
    todo = [n for n in names if n not in done]
    print(f"{len(names)} names, {len(names) - len(todo)} done before, {len(todo)} to go; "
          f"results in {args.out}", flush=True)
    t0 = time.perf_counter()
    bad = 0
    with args.out.open("a") as f:
        for k, name in enumerate(todo, 1):
            row = verify_pd(name) if args.pd else verify(name, not args.no_topoly)
            f.write(json.dumps(row) + "\n")
            f.flush()
            ok = row["check"] and row["ours"] and row.get("topoly", True)
            bad += not ok
            if not ok:
                print(f"  FAILED {name}: {row}", flush=True)
            if k % 100 == 0 or k == len(todo):
                print(f"{k}/{len(todo)} in {time.perf_counter() - t0:.0f} s, {bad} failed",
                      flush=True)
    print(json.dumps(summary(args.out), indent=1))


if __name__ == "__main__":
    main()
