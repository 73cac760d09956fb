"""What a first contact sees: numba's compiling said (core.compiling), both spellings of the
iteration limit and the tolerance (core.runs.aliases), the warm-up paths (core.warm)."""

import numba as nb
import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core.compilation.notice import PREPARING, compiling
from moebius_addon.core.compilation.warmup import PATHS, main


def test_compiling_is_said_once_and_counted():
    @nb.njit  # defined here, so never in any cache: it compiles at its first call
    def twice(x):
        return 2.0 * x

    lines = []
    with compiling(lines.append) as watch:
        assert twice(1.5) == 3.0
        assert twice(2.5) == 5.0  # the same signature: no second compile
    assert watch.kernels == 1 and not watch.active and watch.seconds > 0
    assert lines == [PREPARING, watch.summary()] and lines[1].startswith("compiled 1 kernel in")
    lines.clear()
    with compiling(lines.append) as watch:  # compiled already: nothing to say
        assert twice(3.0) == 6.0
    assert watch.kernels == 0 and lines == [] and watch.summary() == ""


def test_inside_another_watch_only_the_outer_one_speaks():
    @nb.njit
    def inner(x):
        return x + 1

    outer_lines, inner_lines = [], []
    with compiling(outer_lines.append) as outer:
        with compiling(inner_lines.append) as watch:
            inner(1)
        assert watch.kernels == 1
    assert inner_lines == [] and outer.kernels == 1 and outer_lines[0] == PREPARING


def test_both_spellings_of_the_limits():
    P = core.knots.named("3_1", 60)
    a = core.relax(P, max_iter=2, tol=0.0)
    b = core.relax(P, max_iterations=2, tolerance=0.0)
    assert a.nit == b.nit == 2 and np.array_equal(a.x, b.x)
    run = core.make_run("projected_gradient", P, max_iterations=1, tolerance=0.5)
    assert (run.max_iter, run.tol) == (1, 0.5)
    with pytest.raises(TypeError, match="max_iter and max_iterations are the same option"):
        core.relax(P, max_iter=3, max_iterations=2)
    with pytest.raises(TypeError, match="tol and tolerance are the same option"):
        core.make_run("projected_gradient", P, tol=1e-3, tolerance=1e-4)


def test_warmup_names_its_paths(capsys):
    # each energy whose record has a warm-up path adds its own (core.energies)
    assert set(PATHS) == {"exact", "convert", "identify", "open", "tree", "tangent_point",
                          "bending", "cables", "obstacles", "untangle_cables", "pack_in_volume"}
    with pytest.raises(SystemExit):
        main(["nope"])
    assert "unknown path(s) nope" in capsys.readouterr().err
