"""The energy and metric records: every room reads them and none names an energy.

An energy is a module of core/energies/ with its record (core.energies.record); the engine, the
runs, the warm-up, batch and the Blender layer learn from the records, so no module outside
core/energies/ compares a value with an energy's name. The metrics: one record each
(core.metrics.records), one pair weight for every sum of hs (core.metrics.hs_weight).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from moebius_addon import core
from moebius_addon.core.compilation import warmup
from moebius_addon.core.energies import ENERGIES
from moebius_addon.core.energies.choice import ENERGY_OPTIONS, RUN_ENERGY_NAMES, check_energy
from moebius_addon.core.metrics import banded, gram
from moebius_addon.core.metrics.records import METRIC_RECORDS
from moebius_addon.core.tree import hs_metric
from moebius_addon.core.tree import moebius as moebius_tree
from moebius_addon.core.tree import tangent_point as tangent_point_tree

PACKAGE = Path(core.__file__).resolve().parent.parent


def _name_comparisons(source: str) -> list[str]:
    """Comparisons (``==``, ``!=``, ``in``) of anything with an energy's name spelt out."""
    names = set(ENERGIES)
    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.Compare):
            continue
        for side in (node.left, *node.comparators):
            items = side.elts if isinstance(side, (ast.Tuple, ast.List, ast.Set)) else [side]
            found += [i.value for i in items
                      if isinstance(i, ast.Constant) and i.value in names]
    return found


def test_no_energy_is_named_outside_its_room():
    rooms = PACKAGE / "core" / "energies"
    for path in sorted(PACKAGE.rglob("*.py")):
        if rooms in path.parents:
            continue
        assert _name_comparisons(path.read_text(encoding="utf-8")) == [], path
    # the check sees a comparison, spelt either way
    assert _name_comparisons('if energy == "tangent_point": pass\n')
    assert _name_comparisons('x = name in ("moebius", "x")\n')
    assert not _name_comparisons('def f(energy="moebius"): pass\n')


def test_every_energy_has_a_whole_record():
    assert core.ENERGY_NAMES == tuple(ENERGIES) and core.ENERGY_NAMES[0] == "moebius"
    for name, r in ENERGIES.items():
        assert r.name == name and r.label and r.help and r.short
        choice = check_energy(name)
        assert choice.records == (r,)
        assert isinstance(choice.scaling, float)
        if r.repulsive:  # a run may minimize it alone: it has the metric order and a tree
            assert name in RUN_ENERGY_NAMES
            assert 1.0 < choice.metric_order < 2.0
            assert 0.0 < r.default_theta < 2.0 and r.frame is not None
        else:
            assert r.weight is not None and r.weight.default == 0.0
            assert r.frame is None
        if r.warmup:
            assert name in warmup.PATHS
    # the defaults live once: the tree's θ per energy, read by the tree modules
    assert moebius_tree.THETA == ENERGIES["moebius"].default_theta == 0.175
    assert tangent_point_tree.THETA == ENERGIES["tangent_point"].default_theta == 0.5
    assert set(ENERGY_OPTIONS) == {"alpha", "beta", "stiffness"}


def test_parameters_are_refused_by_name():
    with pytest.raises(ValueError, match="alpha is an option of the tangent-point energy"):
        check_energy("moebius", alpha=2.0)
    with pytest.raises(ValueError, match="beta must lie in"):
        check_energy("tangent_point", beta=10.0)
    assert check_energy("tangent_point", stiffness=0.0).label == "tangent_point(2, 4.5)"
    assert check_energy("tangent_point", stiffness=0.25).label == (
        "tangent_point(2, 4.5) + bending(0.25)")
    assert check_energy("moebius", stiffness=0.25).short_label == "Energy + 0.25 bend"


def test_metric_records_are_the_lists_every_room_reads():
    assert set(METRIC_RECORDS) == set(core.METRICS)
    assert set(gram.ORDERED_METRICS) == {n for n, m in METRIC_RECORDS.items() if m.order is None}
    assert banded.BANDED_METRICS == ("l2", "h1", "h2")
    assert hs_metric.METRICS == ("hs_pure", "hs")
    assert set(banded.BANDED_METRICS) | set(hs_metric.METRICS) == set(METRIC_RECORDS)
    for m in METRIC_RECORDS.values():
        assert m.label and m.help
        assert core.ENGINES["tree"].holds_dense(m.name) == (m.tree_solver is None)


def test_the_hs_weight_is_written_once():
    # gram.py ×3, open.py, hs_metric.py ×2 call core.metrics.hs_weight.hs_weight
    for module in ("core/metrics/gram.py", "core/metrics/open.py", "core/tree/hs_metric.py"):
        text = (PACKAGE / module).read_text(encoding="utf-8")
        assert "**-expo" not in text and "** -expo" not in text, module
        assert "hs_weight(" in text, module
