"""A start is checked once at the door: its vertices validated and its closest pairs searched
once on the way from ``relax`` into a run, whatever wraps the run."""

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core.geometry import collision, layout, polygon
from moebius_addon.core.geometry.polygon import CheckedCurve, check_curve
from moebius_addon.core.runs import base
from tests.conftest import trefoil


@pytest.fixture
def start():
    return core.resample(trefoil(120), 120)


@pytest.fixture
def counted(monkeypatch):
    """How often the start's closest pairs are searched and its layout is made."""
    counts = {"closest pairs": 0, "unit layout": 0}

    def counting(name, f):
        def wrapped(*args, **kwargs):
            counts[name] += 1
            return f(*args, **kwargs)
        return wrapped

    # the searches and the layout where the checks and the runs reach them
    monkeypatch.setattr(polygon, "closest_pairs",
                        counting("closest pairs", collision.closest_pairs))
    monkeypatch.setattr(polygon, "closest_vertices",
                        counting("closest pairs", collision.closest_vertices))
    unit_layout = counting("unit layout", layout.as_unit_layout)
    for module in (layout, polygon, base):
        monkeypatch.setattr(module, "as_unit_layout", unit_layout)
    return counts


@pytest.mark.parametrize("options", [{}, {"refine": False}, {"restarts": 1}])
def test_a_start_is_checked_once_on_the_way_into_a_run(start, counted, options):
    core.make_run("projected_gradient", start, "hs", max_iter=0, **options)
    assert counted == {"closest pairs": 1, "unit layout": 1}


def test_the_check_counts_what_it_says(start, counted):
    # the counter sees a second check (the test above cannot pass by counting nothing)
    core.check_polygon(start)
    core.check_polygon(start)
    assert counted == {"closest pairs": 2, "unit layout": 2}


def test_a_checked_start_runs_as_its_vertices_do():
    P = core.resample(trefoil(120), 120)
    checked = check_curve(P)
    a = core.make_run("projected_gradient", P, "hs", max_iter=3, refine=False)
    b = base.Run.__new__(type(a))  # the same class, started from the checked curve
    b.__init__(checked, "hs", 3, 1e-6)
    while not a.done:
        a.step()
    while not b.done:
        b.step()
    np.testing.assert_array_equal(a.result().x, b.result().x)
    assert a.history["energy"] == b.history["energy"]


def test_what_the_door_keeps_is_what_the_checks_say():
    P = core.resample(trefoil(120), 120)
    checked = check_curve(P)
    assert isinstance(checked, CheckedCurve) and checked.coarse_checked
    assert checked.ratio == core.contact_ratio(P)
    assert core.contact_ratio(checked) == core.contact_ratio(P)
    assert check_curve(checked) is checked  # not checked again
    # a start checked without the coarseness rule gets it when a run needs it
    coarse = check_curve(trefoil(40) * [1, 1, 0.1], coarseness=False)
    assert not coarse.coarse_checked
    with pytest.raises(ValueError, match="too coarse for its shape"):
        check_curve(coarse)
    with pytest.raises(ValueError, match="too coarse for its shape"):
        core.check_polygon(trefoil(40) * [1, 1, 0.1])
