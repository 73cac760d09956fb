"""How the runs' arrays take their pages: :func:`runs.memory.small_pages`."""

import threading

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core.runs import memory, projected
from tests.conftest import trefoil


def _advice(switch) -> bool:
    """numpy's huge-page advice as it is now (read by setting it back)."""
    now = switch(False)
    switch(now)
    return now


@pytest.fixture
def switch():
    sw = memory._numpy_huge_page_switch()
    if sw is None:
        pytest.skip("this numpy has no huge-page advice to switch")
    before = sw(True)
    yield sw
    sw(before)


@pytest.mark.parametrize("text, compacts", [
    ("always [madvise] never\n", True),
    ("[always] defer defer+madvise madvise never\n", True),
    ("always defer [defer+madvise] madvise never\n", True),
    ("always [defer] defer+madvise madvise never\n", False),
    ("always defer defer+madvise madvise [never]\n", False),
    ("garbled\n", False),
])
def test_which_defrag_modes_compact_at_the_fault(tmp_path, text, compacts):
    f = tmp_path / "defrag"
    f.write_text(text)
    assert memory._huge_pages_compact(str(f)) is compacts
    assert memory._huge_pages_compact(str(tmp_path / "missing")) is False


def test_small_pages_switch_the_advice_off_inside_and_back(switch, monkeypatch):
    monkeypatch.setattr(memory, "_COMPACTS", True)
    with memory.small_pages():
        assert _advice(switch) is False
        with memory.small_pages():
            assert _advice(switch) is False
        assert _advice(switch) is False  # the inner exit leaves the outer's setting
    assert _advice(switch) is True
    with pytest.raises(RuntimeError), memory.small_pages():
        raise RuntimeError("inside")
    assert _advice(switch) is True
    switch(False)  # a user's own setting comes back as it was
    with memory.small_pages():
        pass
    assert _advice(switch) is False


def test_small_pages_leave_the_advice_where_nothing_compacts(switch, monkeypatch):
    monkeypatch.setattr(memory, "_COMPACTS", False)
    with memory.small_pages():
        assert _advice(switch) is True


def test_small_pages_of_overlapping_threads_restore_once_both_left(switch, monkeypatch):
    monkeypatch.setattr(memory, "_COMPACTS", True)
    a_in, b_in, a_out = threading.Event(), threading.Event(), threading.Event()
    seen = {}

    def a():
        with memory.small_pages():
            a_in.set()
            b_in.wait(5)
        a_out.set()

    def b():
        a_in.wait(5)
        with memory.small_pages():
            b_in.set()
            a_out.wait(5)
            seen["b after a left"] = _advice(switch)

    ts = [threading.Thread(target=a), threading.Thread(target=b)]
    for t in ts:
        t.start()
    for t in ts:
        t.join(10)
    assert seen == {"b after a left": False}
    assert _advice(switch) is True


def test_a_run_sets_up_and_steps_on_small_pages(switch, monkeypatch):
    monkeypatch.setattr(memory, "_COMPACTS", True)
    seen = []
    prepare = projected.Relaxation._prepare

    def spy(self, *args):
        seen.append(_advice(switch))
        return prepare(self, *args)

    monkeypatch.setattr(projected.Relaxation, "_prepare", spy)
    P = core.resample(trefoil(240), 60)
    run = projected.Relaxation(P, metric="hs", engine="exact")
    assert _advice(switch) is True
    assert run.step()
    assert seen and not any(seen)
    assert _advice(switch) is True
    assert np.all(np.isfinite(run.X))
