"""core.runs.batch: tasks from what a user types, runs here and on a LocalCluster, resume, failures,
refusals before any work. Tasks are tiny (40 edges, a few iterations)."""

from __future__ import annotations

import csv
import json
import os
import re
import shlex
import shutil
import signal
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from moebius_addon.core import write_obj
from moebius_addon.core.runs import batch

ROOT = Path(__file__).resolve().parents[2]
SMALL = {"edges": [40], "max_iter": 4, "identify": False}


def small(*inputs, **kw):
    return batch.tasks(inputs, **{**SMALL, **kw})


def rows(out) -> list[dict]:
    with (Path(out) / "results.csv").open(newline="") as f:
        return list(csv.DictReader(f))


def quiet(_):
    pass


def lemniscate_obj(path: Path) -> Path:
    """A closed planar polygon through itself: read_obj takes it, relax refuses it."""
    t = np.linspace(0.0, 2.0 * np.pi, 40, endpoint=False)
    write_obj(path, np.c_[np.sin(t), np.sin(2.0 * t), 0.0 * t])
    return path


def test_tasks_from_names_patterns_ranges_and_files(tmp_path):
    (tmp_path / "braids.txt").write_text("# two braids\nmy trefoil: 1 1 1\n[[1,5,2,4],[3,1,4,6],"
                                         "[5,3,6,2]]\n")
    (tmp_path / "objs").mkdir()
    lemniscate_obj(tmp_path / "objs" / "eight.obj")
    got = batch.tasks(["trefoil", "5_*", str(tmp_path / "braids.txt"), str(tmp_path / "objs")],
                      crossings="4", edges=None)
    names = [t.name for t in got]
    assert names[:3] == ["3_1", "5_1", "5_2"]
    assert "4_1" in names and "my trefoil" in names and "braids-3" in names
    assert "eight" in names
    eight = got[names.index("eight")]
    assert eight.kind == "file" and eight.edges == 40 and len(eight.curve) == 1
    assert got[0].edges == len(batch.knots.named("3_1"))
    # one task per (curve, edge count, seed); ids unique
    more = batch.tasks(["3_1"], edges=[40, 60], seeds=(0, 1))
    assert len({t.id for t in more}) == 4


@pytest.mark.parametrize("inputs, kw, words", [
    (["3_1", "not_a_knot"], {}, "unknown knot or link 'not_a_knot'"),
    (["14_*"], {}, "matches no knot"),
    (["missing.obj"], {}, "cannot read"),
    ([], {"crossings": "15"}, "no knot of 15 crossings"),
    ([], {"crossings": "7-5"}, "empty"),
    ([], {}, "nothing to run"),
    (["3_1"], {"edges": [2]}, "at least 4"),
    (["3_1"], {"method": "newton"}, "unknown method"),
])
def test_bad_inputs_refused(inputs, kw, words):
    with pytest.raises(ValueError, match=words):
        batch.tasks(inputs, **kw)


def test_unreadable_files_refused(tmp_path):
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2\nl 2 3\n")  # an open path
    with pytest.raises(ValueError, match="cannot read"):
        batch.tasks([str(bad)])
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ValueError, match="no .obj files"):
        batch.tasks([str(empty)])
    junk = tmp_path / "junk.txt"
    junk.write_text("not a braid\n")
    with pytest.raises(ValueError, match="junk.txt:1"):
        batch.tasks([str(junk)])
    if os.geteuid() != 0:  # root reads anything
        locked = lemniscate_obj(tmp_path / "locked.obj")
        locked.chmod(0)
        with pytest.raises(ValueError, match="cannot read"):
            batch.tasks([str(locked)])


def test_scheduler_that_does_not_answer_refused_before_work(tmp_path):
    pytest.importorskip("distributed")
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = tmp_path / "out"
    with pytest.raises(ValueError, match="no Dask scheduler answers"):
        batch.run(small("3_1"), out, scheduler=f"tcp://127.0.0.1:{port}", timeout=2, say=quiet)
    assert not out.exists()


def test_too_many_workers_refused(tmp_path):
    cores = os.cpu_count()
    with pytest.raises(ValueError, match="exceed"):
        batch.run(small("3_1"), tmp_path, workers=cores, threads=2, say=quiet)
    assert not (tmp_path / "results.csv").exists()


def test_missing_dask_says_how_to_install(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed fails
    with pytest.raises(ImportError, match=r"moebius_addon\[batch\]"):
        batch.run(small("3_1"), tmp_path, workers=1, say=quiet)
    assert not (tmp_path / "results.csv").exists()


def test_failed_task_recorded_others_finish(tmp_path):
    todo = small("3_1", str(lemniscate_obj(tmp_path / "eight.obj")), "4_1")
    report = batch.run(todo, tmp_path / "out", workers=0, say=quiet)
    assert sorted(report["done"]) == sorted(t.id for t in todo if t.name != "eight")
    (bad,) = report["failed"]
    assert "intersects itself" in report["failed"][bad]
    by_id = {r["id"]: r for r in rows(tmp_path / "out")}
    assert "intersects itself" in by_id[bad]["error"]
    assert all(by_id[t.id]["status1"] for t in todo if t.name != "eight")
    # a failed task is tried again, finished ones are not
    again = batch.run(todo, tmp_path / "out", workers=0, say=quiet)
    assert list(again["failed"]) == [bad] and again["done"] == []
    assert len(again["skipped"]) == 2


def test_resume_skips_finished_tasks(tmp_path):
    out = tmp_path / "out"
    todo = small("3_1", "4_1", "5_1", "5_2")
    first = batch.run(todo, out, workers=0, limit=2, say=quiet)  # interrupted half way
    assert len(first["done"]) == 2
    mtimes = {i: (out / "curves" / f"{i}.npz").stat().st_mtime_ns for i in first["done"]}
    second = batch.run(todo, out, workers=0, say=quiet)
    assert sorted(second["skipped"]) == sorted(first["done"])
    assert sorted(second["done"]) == sorted(set(t.id for t in todo) - set(first["done"]))
    assert {i: (out / "curves" / f"{i}.npz").stat().st_mtime_ns for i in first["done"]} == mtimes
    assert sorted(r["id"] for r in rows(out)) == sorted(t.id for t in todo)
    # a task whose polygon is gone runs again
    (out / "curves" / f"{first['done'][0]}.npz").unlink()
    third = batch.run(todo, out, workers=0, say=quiet)
    assert third["done"] == [first["done"][0]]
    assert len(json.loads((out / "run.json").read_text())) == 3  # one record per run


def test_largest_first():
    todo = batch.tasks(["3_1", "4_1"], edges=[40, 80], max_iter=1)
    assert sorted(todo, key=lambda t: -t.cost)[0].edges == 80


def test_stages_resample_and_relax_again(tmp_path):
    (task,) = batch.tasks(["3_1"], edges=[40], stages=(1, 2), max_iter=3, identify=True)
    row = batch.run_task(task, threads=1)
    assert row["error"] == ""
    assert [r["n"] for r in row["runs"]] == [40, 80]
    assert len(row["x"]) == 80 and row["identified"] == "3_1"


def test_local_cluster_equals_in_process(tmp_path):
    """Two worker processes against the same tasks run in one process, bit for bit. The
    in-process run is a subprocess with the workers' thread counts (batch.thread_env): the
    BLAS thread count changes the last bits of its products."""
    pytest.importorskip("distributed")
    inputs = ["3_1", "4_1", "5_1", "5_2"]
    todo = small(*inputs) + batch.tasks(["3_1"], edges=[40], stages=(1, 1.5), max_iter=3,
                                        identify=True)
    here = tmp_path / "here"
    env = {**os.environ, **batch.thread_env(1),
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    for args in (["--edges", "40", "--max-iter", "4", "--no-identify", *inputs],
                 ["3_1", "--edges", "40", "--stages", "1", "1.5", "--max-iter", "3"]):
        subprocess.run([sys.executable, "-m", "moebius_addon.core.runs.batch", *args, "--workers",
                        "0", "--out", str(here)], env=env, check=True, capture_output=True)
    cluster = tmp_path / "cluster"
    environ = dict(os.environ)
    report = batch.run(todo, cluster, workers=2, threads=1, dashboard=None, say=quiet)
    # the nannies set OMP_NUM_THREADS=1 and others here; the processes started after this
    # test (the bitwise thread-count tests) ran their BLAS on one thread
    assert dict(os.environ) == environ
    assert report["failed"] == {} and len(report["done"]) == len(todo)
    a, b = {r["id"]: r for r in rows(here)}, {r["id"]: r for r in rows(cluster)}
    assert sorted(a) == sorted(b) == sorted(t.id for t in todo)
    workers = {b[i]["worker"] for i in b}
    assert all(w.split(":")[1] != str(os.getpid()) for w in workers)
    for i in a:
        for key in ("n1", "energy1", "iterations1", "status1", "n2", "energy2", "identified"):
            assert a[i][key] == b[i][key], (i, key)
        x, y = batch.load_curve(here, i), batch.load_curve(cluster, i)
        assert x.dtype == y.dtype and np.array_equal(x, y), i


def test_command_line(tmp_path, capsys):
    out = tmp_path / "out"
    assert batch.console(["batch", "3_1", "--edges", "40", "--max-iter", "2", "--workers", "0",
                          "--no-identify", "--out", str(out)]) == 0
    assert [r["id"] for r in rows(out)] == ["3_1_40"]
    assert batch.console(["batch", "nope_9", "--out", str(out)]) == 2
    assert "unknown knot or link 'nope_9'" in capsys.readouterr().err
    assert batch.console(["relax"]) == 2


# --------------------------------------------------------------------------------------------
# Nothing lost, nothing misread


def test_every_input_is_its_own_task_or_the_clash_is_refused(tmp_path):
    notes = tmp_path / "notes.txt"
    notes.write_text("a b: 1 1 1\na-b: 1 1 1 1 1\n3_1: 1 1 1 1 1\n")
    got = small(str(notes))
    assert [t.name for t in got] == ["a b", "a-b", "3_1"]
    assert len({t.id for t in got}) == 3
    assert len(small("3_1", "trefoil", "3_*")) == 1  # one input three times: one task
    with pytest.raises(ValueError, match=re.escape(
            f"{notes}:3 ('3_1: 1 1 1 1 1') and the table's 3_1 are both named '3_1'")):
        small(str(notes), "3_1")
    for d in ("x", "y"):
        (tmp_path / d).mkdir()
        lemniscate_obj(tmp_path / d / "knot.obj")
    with pytest.raises(ValueError, match=re.escape(
            f"the file '{tmp_path / 'x' / 'knot.obj'}' and the file "
            f"'{tmp_path / 'y' / 'knot.obj'}' are both named 'knot'")):
        small(str(tmp_path / "x" / "knot.obj"), str(tmp_path / "y" / "knot.obj"))
    # the same file twice (itself and its folder) is one task
    assert len(small(str(tmp_path / "x" / "knot.obj"), str(tmp_path / "x"))) == 1


def test_cut_row_and_cut_polygon_are_not_done(tmp_path):
    out = tmp_path / "out"
    todo = small("3_1", "4_1", "5_1")
    batch.run(todo, out, workers=0, say=quiet)
    table = out / "results.csv"
    cut = rows(out)[-1]["id"]  # a kill in the middle of the last row
    table.write_bytes(table.read_bytes()[:-15])
    damaged = next(t.id for t in todo if t.id != cut)  # a kill in the middle of np.savez
    npz = out / "curves" / f"{damaged}.npz"
    npz.write_bytes(npz.read_bytes()[: npz.stat().st_size // 2])
    assert batch.done_ids(out) == {t.id for t in todo} - {cut, damaged}
    with pytest.raises(ValueError, match=re.escape(f"{npz} is damaged")):
        batch.load_curve(out, damaged)
    again = batch.run(todo, out, workers=0, say=quiet)
    assert sorted(again["done"]) == sorted([cut, damaged]) and again["failed"] == {}
    # the cut line is gone, no row is glued to it, every line has the header's fields
    lines = list(csv.reader(table.open(newline="")))
    assert {len(r) for r in lines} == {len(lines[0])}
    assert [r[0] for r in lines[1:]] == [t.id for t in todo if t.id != cut] + again["done"]
    assert batch.load_curve(out, damaged).shape == (40, 3)
    assert batch.done_ids(out) == {t.id for t in todo}


def test_changed_settings_are_refused_with_the_difference(tmp_path):
    out = tmp_path / "out"
    batch.run(small("3_1"), out, workers=0, say=quiet)
    with pytest.raises(ValueError, match=re.escape(
            "task '3_1_40' finished with other settings (tol 0.0001 there, 1e-06 now)")):
        batch.run(small("3_1", tol=1e-6), out, workers=0, say=quiet)
    with pytest.raises(ValueError, match=re.escape(
            "(method projected_gradient_implicit there, projected_gradient now; max_iter 4 "
            "there, 5 now)")):
        batch.run(small("3_1", method="projected_gradient", max_iter=5), out, workers=0,
                  say=quiet)
    assert len(rows(out)) == 1
    # the same settings are done; asked to, the changed ones run again
    assert batch.run(small("3_1"), out, workers=0, say=quiet)["skipped"] == ["3_1_40"]
    again = batch.run(small("3_1", tol=1e-6), out, workers=0, resume=False, say=quiet)
    assert again["done"] == ["3_1_40"]
    assert rows(out)[-1]["tol"] == "1e-06"


def test_long_names_are_safe_file_names(tmp_path):
    notes = tmp_path / "long.txt"
    long = "k" * 300
    notes.write_text(f"{long}: 1 1 1\n{long}x: 1 1 1\n")
    todo = small(str(notes))
    report = batch.run(todo, tmp_path / "out", workers=0, say=quiet)
    assert sorted(report["done"]) == sorted(t.id for t in todo) and report["failed"] == {}
    assert len({t.id for t in todo}) == 2
    assert all(len(f"{t.id}.npz") < 255 for t in todo)  # a file name's limit on common systems
    assert sorted(r["name"] for r in rows(tmp_path / "out")) == [long, long + "x"]
    for t in todo:
        assert batch.load_curve(tmp_path / "out", t.id).shape == (40, 3)


def _foreign_table(out: Path) -> str:
    out.mkdir()
    (out / "results.csv").write_text("name,energy\n3_1,75.1\n")
    return f"{out / 'results.csv'} is not the results table of a batch run (no column 'id'"


def _a_file(out: Path) -> str:
    out.write_text("")
    return f"{out} is a file, not a folder; choose another output folder (--out)"


def _curves_a_file(out: Path) -> str:
    out.mkdir()
    (out / "curves").write_text("")
    return f"cannot write in {out} (File exists); make it writable"


@pytest.mark.parametrize("fault", [_foreign_table, _a_file, _curves_a_file])
def test_folder_faults_are_one_line_with_the_file_and_fix(tmp_path, capsys, fault):
    out = tmp_path / "out"
    words = fault(out)
    assert batch.console(["batch", "3_1", "--edges", "40", "--max-iter", "2", "--no-identify",
                          "--workers", "0", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and words in err, err


def test_damaged_run_log_is_named(tmp_path):
    out = tmp_path / "out"
    batch.run(small("3_1"), out, workers=0, say=quiet)
    (out / "run.json").write_text('[{"started": ')
    with pytest.raises(ValueError, match=re.escape(
            f"{out / 'run.json'} is damaged (Expecting value at line 1); it is only the log "
            "of the runs (not needed to resume): repair it or move it away")):
        batch.run(small("3_1", "4_1"), out, workers=0, say=quiet)
    (out / "run.json").unlink()
    assert batch.run(small("3_1", "4_1"), out, workers=0, say=quiet)["done"] == ["4_1_40"]


def test_finished_folder_is_only_read(tmp_path):
    """A finished folder may be read-only (an archive): a run finds nothing to do and
    rewrites nothing."""
    out = tmp_path / "out"
    batch.run(small("3_1"), out, workers=0, say=quiet)
    before = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    if os.geteuid() != 0:  # root writes anywhere
        out.chmod(0o555)
    try:
        report = batch.run(small("3_1"), out, workers=0, say=quiet)
    finally:
        out.chmod(0o755)
    assert report["skipped"] == ["3_1_40"] and report["done"] == []
    assert {p.name: p.stat().st_mtime_ns for p in out.iterdir()} == before


def test_the_sync_cancel_race_is_dropped_and_nothing_else(tmp_path):
    # Ctrl-C before distributed's sync() has its future: its cancel callback reads the unset
    # future and tornado logs the NameError (seen once in the test below). The record is
    # dropped; a NameError anywhere else, or another error from that callback, is not
    import inspect
    import logging

    distributed = pytest.importorskip("distributed")
    source = inspect.getsource(distributed.utils.sync)
    assert "def cancel()" in source and "future.cancel()" in source  # still the code it drops

    def raised(code, path):
        scope = {}
        exec(compile(code, str(path), "exec"), scope)
        try:
            scope["cancel"]()
        except Exception as e:  # noqa: BLE001 - the record of any error
            return logging.LogRecord("tornado.application", logging.ERROR, "", 0, "x", None,
                                     (type(e), e, e.__traceback__))

    utils = tmp_path / "distributed" / "utils.py"
    other = tmp_path / "mine" / "utils.py"
    race = "def cancel():\n    future.cancel()\n"
    assert not batch._sync_cancel_race(raised(race, utils))
    assert batch._sync_cancel_race(raised(race, other))
    assert batch._sync_cancel_race(raised("def cancel():\n    1 / 0\n", utils))
    assert batch._sync_cancel_race(logging.LogRecord("tornado.application", logging.ERROR, "",
                                                     0, "no exception", None, None))
    quiet = batch._Quiet()
    quiet.guard()
    try:
        assert batch._sync_cancel_race in logging.getLogger("tornado.application").filters
    finally:
        quiet.stop()
    assert batch._sync_cancel_race not in logging.getLogger("tornado.application").filters


@pytest.mark.parametrize("workers", ["0", "2"])
def test_ctrl_c_says_what_finished_and_how_to_resume(tmp_path, workers):
    """Ctrl-C in a terminal reaches the whole process group: the command and, with workers,
    the Dask workers too."""
    if workers != "0":
        pytest.importorskip("distributed")
        if (os.cpu_count() or 1) < 2:
            pytest.skip("two workers need two cores")
    out = tmp_path / "out"
    args = [sys.executable, "-m", "moebius_addon.core.runs.batch", "--crossings", "3-8", "--edges",
            "60", "--max-iter", "200", "--tol", "1e-12", "--no-identify", "--workers", workers,
            "--dashboard", "", "--out", str(out)]
    env = {**os.environ,
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    # as a terminal starts it: Ctrl-C's default action (a suite started in the background of a
    # non-interactive shell, `make test &`, hands its children SIGINT ignored)
    proc = subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    lines = []
    for line in proc.stdout:  # interrupt once the first task has finished
        lines.append(line)
        if re.match(r"\[[#.]+\] 1/", line):
            os.killpg(proc.pid, signal.SIGINT)
            break
    rest, err = proc.communicate(timeout=120)
    said = "".join(lines) + rest
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    finished = {r["id"] for r in rows(out)}
    assert re.search(rf"interrupted: {len(finished)} done now, 0 failed, \d+ not run", said)
    assert "run the same command again to resume" in said
    assert err.strip().endswith(
        "interrupted; to resume: python -m moebius_addon.core.runs.batch " +
        " ".join(shlex.quote(a) for a in args[3:]))
    assert batch.done_ids(out) == finished


def test_write_fault_mid_run_stops_with_the_file_and_what_finished(tmp_path):
    """``curves`` turns into a file after the first task (a disk unmounted, a folder
    replaced): the next polygon cannot be written."""
    out = tmp_path / "out"
    said = []

    def say(line):
        said.append(line)
        if line.startswith("[") and (out / "curves").is_dir():
            shutil.rmtree(out / "curves")
            (out / "curves").write_text("")

    todo = small("3_1", "4_1", "5_1")
    with pytest.raises(ValueError, match=r"cannot write .*curves/\w+\.npz \(Not a directory\); "
                       r"free space on its disk or make .* writable, then run the same "
                       r"command again to resume"):
        batch.run(todo, out, workers=0, say=say)
    assert said[-1].startswith("stopped: 1 done now, 0 failed, 2 not run")
