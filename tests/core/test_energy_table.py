"""The published Möbius-energy table (docs/data/energy_table.csv) and its relaxed polygons
(docs/data/energy_table_curves.npz, written by ``bench/energy_table.py --pack``): one row and
one curve per prime knot up to 10 crossings, the numbers of each row consistent with each other,
and a seeded sample of the curves recomputed: their energy is the row's, their knot type the
row's name, their polygon embedded."""

import csv
from pathlib import Path

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core.topology import knots

ROOT = Path(__file__).resolve().parents[2]
CSV = ROOT / "docs" / "data" / "energy_table.csv"
CURVES = ROOT / "docs" / "data" / "energy_table_curves.npz"


@pytest.fixture(scope="module")
def rows():
    with CSV.open() as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def curves():
    with np.load(CURVES) as packed:
        return {name: packed[name] for name in packed.files}


def test_one_row_and_one_curve_per_knot_in_table_order(rows, curves):
    names = [n for n in knots.names("knot") if knots.info(n)["crossings"] <= 10]
    assert len(names) == 250
    assert [r["name"] for r in rows] == names
    assert list(curves) == names
    for r in rows:
        assert int(r["crossings"]) == knots.info(r["name"])["crossings"]
        assert int(r["n2"]) == 2 * int(r["n1"])
        assert len(curves[r["name"]]) == int(r["n2"])
        assert curves[r["name"]].dtype == np.float32


def test_rows_are_consistent(rows):
    for r in rows:
        e1, e2 = float(r["energy1"]), float(r["energy2"])
        assert 4.0 - 1e-6 <= e2 <= e1 + 1e-9, r["name"]  # finer polygons have less energy
        # Richardson with order 2: E_inf = E2 + (E2 - E1) / 3, rounded to 4 decimals
        assert float(r["extrapolated"]) == pytest.approx(e2 + (e2 - e1) / 3, abs=6e-5), r["name"]
        assert r["name"] in r["identified"].split(" | "), r["name"]
        for k in ("1", "2"):
            assert r["status" + k] in ("CONVERGED", "MAX_ITER", "TIME"), r["name"]
            assert int(r["iterations" + k]) >= 0 and float(r["seconds" + k]) >= 0
    # knotted curves lie above the least energy a knot can have (> 6 pi + 4, FHW 1994)
    assert all(float(r["energy2"]) > 6 * np.pi + 4 for r in rows if r["name"] != "0_1")


SAMPLE = sorted(np.random.default_rng(16).choice(250, size=6, replace=False).tolist())


@pytest.mark.parametrize("index", SAMPLE)
def test_packed_curves_are_what_the_row_says(rows, curves, index):
    r = rows[index]
    P = curves[r["name"]].astype(np.float64)
    edges = np.linalg.norm(np.roll(P, -1, axis=0) - P, axis=1)
    np.testing.assert_allclose(edges, 1.0, rtol=1e-4)  # equilateral, unit edges
    np.testing.assert_allclose(P.mean(axis=0), 0.0, atol=1e-3)
    core.check_polygon(P)  # embedded: no self-contact
    e = core.moebius_energy(P, engine="exact")
    assert e == pytest.approx(float(r["energy2"]), rel=2e-5)  # float32 coordinates
    assert r["name"] in core.identify(P).names
