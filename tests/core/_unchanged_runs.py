"""Short runs whose every iterate must stay bit-for-bit what it was before pinned vertices
existed: the reference ``data/unchanged_runs.json`` was written by this module's
``main()`` on the commit before pins (run it there to regenerate; it uses nothing newer),
but for the two cases of the hs metric on the tree engine, written again when its constraint
preconditioner's barycenter rows became projected (another preconditioner, so other Krylov
iterates within their tolerance: energies within 2.1e-6, gradient norms within 8.1e-4 of
the old histories' largest values, the iteration counts equal).

Each case records, per accepted iterate, the history (energy, step, grad_norm,
constraint_residual) as hexadecimal floats and a SHA-256 of the final vertex array.
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np

from moebius_addon.core import resample
from moebius_addon.core.runs.methods import METHODS, make_run
from moebius_addon.core.topology import knots

REFERENCE = Path(__file__).resolve().parent / "data" / "unchanged_runs.json"
_KEYS = ("energy", "step", "grad_norm", "constraint_residual")


def _hopf(n: int = 24) -> list[np.ndarray]:
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    a = np.c_[np.cos(t), np.sin(t), 0 * t]
    b = np.c_[1.0 + np.cos(t), 0 * t, np.sin(t)]
    return [a, b]


def curves() -> dict:
    return {
        "trefoil": resample(knots.torus_knot(2, 3, 200), 60),
        "fhw": knots.freedman_unknot(600),
        "hopf": _hopf(),
    }


#: (curve, method, metric, engine, iterations)
CASES = (
    [("trefoil", m, "hs", "exact", 4) for m in METHODS]
    + [("fhw", m, "hs", "exact", 2) for m in METHODS]
    + [
        ("trefoil", "projected_gradient", "l2", "exact", 3),
        ("trefoil", "projected_gradient", "hs", "tree", 3),
        ("trefoil", "projected_gradient", "l2", "tree", 3),
        ("hopf", "projected_gradient", "hs", "exact", 3),
        ("hopf", "trust_region", "hs", "exact", 3),
        ("hopf", "projected_gradient", "hs", "tree", 3),
    ]
)


def case_id(case) -> str:
    return "-".join(map(str, case))


def run_case(case, P=None, **options) -> dict:
    """The record of one case (``P``: its curve, built here when not given)."""
    name, method, metric, engine, iterations = case
    if P is None:
        P = curves()[name]
    run = make_run(method, P, metric, iterations, 0.0, engine=engine, **options)
    while not run.done:
        run.step()
    x = np.ascontiguousarray(np.concatenate(run.x) if isinstance(run.x, list) else run.x)
    return {
        "nit": run.nit,
        **{k: [float(v).hex() for v in run.history[k]] for k in _KEYS},
        "x_sha256": hashlib.sha256(x.tobytes()).hexdigest(),
    }


def main() -> None:
    P = curves()
    out = {case_id(c): run_case(c, P[c[0]]) for c in CASES}
    REFERENCE.write_text(json.dumps(out, indent=1) + "\n")
    print(f"wrote {len(out)} cases to {REFERENCE}", file=sys.stderr)


if __name__ == "__main__":
    main()
