"""Tangled starts (core/tangle.py) and untangling them with the default settings; the type of
every curve checked independently with topoly's Jones polynomial (tests/core/test_knots.py)."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core.topology import knots, tangle
from tests.core.test_adaptive import _min_gap_distance
from tests.core.test_knots import table_jones, topoly_jones

ROOT = Path(__file__).resolve().parents[2]


def topoly_says(P, name) -> bool:
    """Whether topoly's Jones polynomial of ``P`` is the table's for ``name`` in at least two
    of three seeded directions: topoly read a coarse tangled trefoil (its strands 0.45 edge
    lengths apart at the closest) as another knot in one direction of six, whatever its
    reduction method, and as the trefoil in the five others."""
    want = table_jones(name)
    seeds = (2024, 7, 11)
    return sum(topoly_jones(P, seed) == want for seed in seeds) >= 2


def _bench():
    spec = importlib.util.spec_from_file_location("untangle", ROOT / "bench" / "untangle.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_tangle_braid_moves():
    word, strands = tangle.tangle_braid([1, 1, 1], seed=3, conjugations=2, stabilizations=2,
                                        pairs=3)
    assert strands == 4 and len(word) == 3 + 4 + 2 + 6
    assert tangle.tangle_braid([1, 1, 1], seed=3, conjugations=2, stabilizations=2,
                               pairs=3) == (word, strands)
    assert tangle.tangle_braid([1, 1, 1], seed=4)[0] != tangle.tangle_braid([1, 1, 1], seed=3)[0]
    # conjugation and cancelling pairs keep the exponent sum, each stabilization adds ±1
    assert abs(sum(np.sign(word)) - 3) <= 2
    with pytest.raises(ValueError, match="conjugations"):
        tangle.tangle_braid([1, 1, 1], conjugations=-1)
    with pytest.raises(ValueError, match="has no braid word"):
        tangle.tangled("0_1")


@pytest.mark.parametrize(("name", "how"), [("3_1", "braid"), ("4_1", "crumple"),
                                           ("L2a1{1}", "braid"), ("5_2", "both")])
def test_tangled_starts_keep_their_type(name, how):
    P = tangle.tangled(name, seed=1, how=how)
    assert topoly_says(P, name)
    parts = P if isinstance(P, list) else [P]
    for p in parts:
        ln = np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1)
        assert np.ptp(ln) / ln.mean() < 1e-9
    # farther from relaxed than the table's own curve: more energy
    assert core.moebius_energy(P) > 1.5 * core.moebius_energy(knots.named(name))


def test_crumple_keeps_strands_half_an_edge_apart():
    P = knots.named("3_1", 100)
    Q = tangle.crumple(P, seed=2, steps=60)
    np.testing.assert_array_equal(Q, tangle.crumple(P, seed=2, steps=60))
    h = np.linalg.norm(np.roll(Q, -1, axis=0) - Q, axis=1).mean()
    assert _min_gap_distance(Q, gap=3) >= 0.49 * h
    assert np.abs(Q - P).max() > 2 * h  # it moved


def test_a_tangled_trefoil_untangles_to_the_table_energy():
    bench = _bench()
    # contact ratio 0.36 at 100 edges: refined to 400 before the first iterate
    P = tangle.tangled("3_1", 100, seed=101, pairs=3, conjugations=1)
    closest = [_min_gap_distance(P)]
    r = core.relax(P, method="projected_gradient_implicit", tol=1e-4, max_iter=3000,
                   callback=lambda s: closest.append(_min_gap_distance(s.x)))
    assert r.success and r.refinements[0]["iteration"] == 0
    n = len(r.x)
    assert abs(r.fun / bench.table_energy("3_1", n) - 1) < 0.01
    assert topoly_says(r.x, "3_1")
    assert min(closest) > 1e-4 * np.linalg.norm(r.x[1] - r.x[0])


@pytest.mark.slow
@pytest.mark.parametrize("task", ["5_2-braid-0", "6_2-crumple-0", "7_4-braid-1",
                                  "L4a1{1}-braid-0", "trefoil-crumple-30"])
def test_part_of_the_untangling_benchmark(task, tmp_path, monkeypatch):
    bench = _bench()
    monkeypatch.setattr(bench, "OUT", tmp_path)
    (t,) = [t for t in bench.tasks() if t["id"] == task]
    row = bench.run_task(t, 5000)
    assert row["kept"] and row["status"] == "CONVERGED"
    assert row["ratio"] is None or abs(row["ratio"] - 1) < 0.01
    saved = np.load(tmp_path / f"{task}.npz")
    x = [saved[k] for k in saved.files]
    assert topoly_says(x if len(x) > 1 else x[0], t["name"])
    assert row["closest_edges"] > 1e-4
