"""The output folder of a batch run (:mod:`.batch`): written so that a kill at any moment
leaves nothing that reads as done, read strictly, and every fault named with its fix.

* ``curves/<id>.npz`` is written under a temporary name and renamed over the old one: the name
  holds a whole file or none (``np.savez`` alone writes in place, and a cut file read as done).
* A row of ``results.csv`` is appended as one line (line breaks in a field become spaces),
  after its polygon. A file that does not end in a line break (a kill or a full disk in the
  middle of a row) loses that cut line before the next row is appended, so no row is glued to
  it.
* A row counts only if it has the header's number of fields and its numbers parse; the last
  row of an id decides, so a cut retry leaves its task not done. A task is done only if its
  row has no error and its polygon loads with the row's vertex count.
* ``run.json`` is replaced whole.

Every fault of the folder raises :class:`FolderError`, a ValueError whose one-line message
names the file and the fix.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import zipfile
from pathlib import Path

import numpy as np

#: the columns that describe a task, in the order of ``results.csv``; ``Task.settings`` reads it
SETTINGS_FIELDS = ("id", "name", "kind", "ref", "edges", "stages", "energy", "method", "tol",
                   "max_iter", "max_seconds", "seed", "how", "identify")
#: per stage; ``cpu``: CPU seconds of the worker process (all its threads) over the stage,
#: which on a shared machine says more about the cost than the wall ``seconds``
STAGE_FIELDS = ("n", "energy", "iterations", "seconds", "cpu", "status")
_NUMBERS = {"edges": int, "max_iter": int, "seed": int, "tol": float, "max_seconds": float}
_STAGE_NUMBERS = {"n": int, "iterations": int, "energy": float, "seconds": float,
                  "cpu": float}
_FIX_OUT = "choose another output folder (--out)"


class FolderError(ValueError):
    """A fault of the output folder; the message names the file and the fix."""


def fields(n_stages: int) -> list[str]:
    """The columns of ``results.csv`` for tasks of up to ``n_stages`` stages."""
    per = [f"{f}{k}" for k in range(1, n_stages + 1) for f in STAGE_FIELDS]
    return [*SETTINGS_FIELDS, *per, "identified", "worker", "error"]


def column_type(column: str):
    """``int`` or ``float`` for a numeric column of ``results.csv``, else None."""
    if column in _NUMBERS:
        return _NUMBERS[column]
    base = column.rstrip("0123456789")
    return _STAGE_NUMBERS.get(base) if base != column else None


def _why(e: Exception) -> str:
    return getattr(e, "strerror", None) or f"{type(e).__name__}: {e}"


def check(out: Path) -> None:
    """Refuse an output folder that names a file."""
    if out.exists() and not out.is_dir():
        raise FolderError(f"{out} is a file, not a folder; {_FIX_OUT}")


# --------------------------------------------------------------------------------------------
# Reading


def _whole(rec: list[str], header: list[str]) -> bool:
    """A row with the header's fields, its numbers parsing, and every stage if it finished."""
    if len(rec) != len(header):
        return False
    row = dict(zip(header, rec, strict=True))
    if not row["id"]:
        return False
    for column, value in row.items():
        kind = column_type(column)
        if kind is not None and value != "":
            try:
                kind(value)
            except ValueError:
                return False
    if row["error"] == "":
        n = len(row["stages"].split())
        return n > 0 and all(row.get(f"status{k}") for k in range(1, n + 1))
    return True


def read_table(out) -> tuple[list[str], dict[str, dict], list[int]]:
    """The header of ``out/results.csv``, its whole rows by id and the line numbers of the
    rows that are not whole. The last row of an id decides: an id whose last row is cut is
    absent. No file: ``([], {}, [])``. A table without the task columns, or one that cannot
    be read, raises :class:`FolderError`."""
    path = Path(out) / "results.csv"
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return [], {}, []
    except OSError as e:
        raise FolderError(f"cannot read {path} ({_why(e)}); make it readable or move it away, "
                          f"or {_FIX_OUT}") from None
    end = data.rfind(b"\n") + 1
    try:
        text = data[:end].decode("utf-8")
    except UnicodeDecodeError:
        raise FolderError(f"{path} is not a text table (not UTF-8); move it away, or "
                          f"{_FIX_OUT}") from None
    reader = csv.reader(io.StringIO(text))
    header = next(reader, [])
    if not header:
        return [], {}, [1] if data else []
    missing = [c for c in (*SETTINGS_FIELDS, "error") if c not in header]
    if missing:
        raise FolderError(f"{path} is not the results table of a batch run (no column "
                          f"{', '.join(repr(c) for c in missing)}); move it away, or "
                          f"{_FIX_OUT}")
    at = header.index("id")
    rows, bad = {}, []
    records = [(reader.line_num, rec) for rec in reader]
    if end < len(data):  # the cut last line
        records.append((text.count("\n") + 1,
                        next(csv.reader([data[end:].decode("utf-8", "replace")]), [])))
    for line, rec in records:
        if not rec:
            continue
        if _whole(rec, header):
            rows[rec[at]] = dict(zip(header, rec, strict=True))
        else:
            bad.append(line)
            if len(rec) > at + 1:  # its id is whole: that task's last attempt was cut
                rows.pop(rec[at], None)
    return header, rows, bad


def read_results(out) -> dict[str, dict]:
    """The whole rows of ``out/results.csv`` by task id (the last row of an id decides; a row
    cut short or not parsing does not count)."""
    return read_table(out)[1]


def _parts(out, task_id: str) -> list[np.ndarray]:
    path = Path(out) / "curves" / f"{task_id}.npz"
    try:
        with np.load(path) as z:
            parts = [z[f"x{k}"] for k in range(len(z.files))]
    except FileNotFoundError:
        raise FolderError(f"{path} does not exist: task {task_id!r} has not finished; run "
                          f"the batch again into {Path(out)} to run it") from None
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as e:
        raise FolderError(f"{path} is damaged ({_why(e)}); run the batch again into "
                          f"{Path(out)}: its task runs again") from None
    if not parts or any(p.ndim != 2 or p.shape[1] != 3 or not np.isfinite(p).all()
                        for p in parts):
        raise FolderError(f"{path} is damaged (not polygons of finite 3-D points); run the "
                          f"batch again into {Path(out)}: its task runs again")
    return parts


def load_curve(out, task_id: str):
    """The relaxed polygon of a finished task (a list for a link). A missing or damaged file
    raises :class:`FolderError`."""
    parts = _parts(out, task_id)
    return parts[0] if len(parts) == 1 else parts


def finished(out, task_id: str, row: dict) -> bool:
    """Whether the task of ``row`` finished: no error, and its polygon loads with the vertex
    count of its last stage."""
    if row["error"]:
        return False
    try:
        parts = _parts(out, task_id)
    except FolderError:
        return False
    n = row.get(f"n{len(row['stages'].split())}", "")
    return n == "" or sum(len(p) for p in parts) == int(n)


def done_ids(out) -> set[str]:
    """Ids of the tasks finished without error whose polygon loads from ``out/curves``."""
    return {i for i, r in read_results(out).items() if finished(out, i, r)}


def read_log(out) -> list:
    """The runs recorded in ``out/run.json`` (none if it does not exist)."""
    path = Path(out) / "run.json"
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        return []
    except (OSError, UnicodeDecodeError) as e:
        raise FolderError(f"cannot read {path} ({_why(e)}); it is only the log of the runs "
                          f"(not needed to resume): move it away") from None
    try:
        runs = json.loads(text)
    except json.JSONDecodeError as e:
        raise FolderError(f"{path} is damaged ({e.msg} at line {e.lineno}); it is only the "
                          f"log of the runs (not needed to resume): repair it or move it "
                          f"away") from None
    if not isinstance(runs, list):
        raise FolderError(f"{path} is not a list of runs; it is only the log of the runs "
                          f"(not needed to resume): move it away")
    return runs


# --------------------------------------------------------------------------------------------
# Writing


def _remove(path: Path) -> None:
    """Remove a temporary file if it is there (the error that stopped it is the one to tell)."""
    with contextlib.suppress(OSError):
        path.unlink(missing_ok=True)


def _replace(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` whole or not at all: a temporary file renamed over it."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with tmp.open("w", newline="", encoding="utf-8") as f:
            f.write(text)
        os.replace(tmp, path)
    finally:
        _remove(tmp)


def log_run(out: Path, record: dict) -> None:
    """Append ``record`` to ``out/run.json``."""
    path = out / "run.json"
    runs = read_log(out)
    try:
        _replace(path, json.dumps(runs + [record], indent=1) + "\n")
    except OSError as e:
        raise FolderError(f"cannot write {path} ({_why(e)}); make {out} writable, or "
                          f"{_FIX_OUT}") from None


def _line(row: dict, columns: list[str]) -> str:
    buf = io.StringIO()
    csv.DictWriter(buf, fieldnames=columns, extrasaction="ignore").writerow(row)
    return buf.getvalue()


class Writer:
    """Appends rows to ``results.csv`` and writes polygons, as results arrive."""

    def __init__(self, out: Path, n_stages: int):
        self.out, self.path = out, out / "results.csv"
        header, rows, _ = read_table(out)
        try:
            (out / "curves").mkdir(parents=True, exist_ok=True)
            if header and sum(f.startswith("status") for f in header) >= n_stages:
                self.fields = header
                self._cut_tail()
            else:  # new, a cut header, or these tasks have more stages: widen the header
                self.fields = fields(max(n_stages,
                                         sum(f.startswith("status") for f in header)))
                head = _line(dict(zip(self.fields, self.fields, strict=True)), self.fields)
                _replace(self.path, head + "".join(_line(r, self.fields) for r in rows.values()))
        except OSError as e:
            raise FolderError(f"cannot write in {out} ({_why(e)}); make it writable, or "
                              f"{_FIX_OUT}") from None

    def _cut_tail(self) -> None:
        """Drop a last line cut short, so that the next row starts on a line of its own."""
        with self.path.open("rb+") as f:
            data = f.read()
            end = data.rfind(b"\n") + 1
            if end < len(data):
                f.truncate(end)

    def write(self, row: dict) -> None:
        """The polygon (``row["x"]``, if any) by rename, then the row as one line."""
        x = row.pop("x", None)
        target = self.path
        try:
            if x is not None:
                parts = x if isinstance(x, list) else [x]
                target = self.out / "curves" / f"{row['id']}.npz"
                tmp = target.with_name(f".{row['id']}.{os.getpid()}.tmp.npz")
                try:
                    np.savez(tmp, **{f"x{k}": p for k, p in enumerate(parts)})
                    os.replace(tmp, target)
                finally:
                    _remove(tmp)
                target = self.path
            flat = {k: v for k, v in row.items() if k != "runs"}
            for k, s in enumerate(row.get("runs", []), 1):
                flat.update({f"{f}{k}": s[f] for f in STAGE_FIELDS})
            flat = {k: " ".join(v.split()) if k == "error" else
                    v.replace("\r", " ").replace("\n", " ") if isinstance(v, str) else v
                    for k, v in flat.items()}
            with self.path.open("a", newline="", encoding="utf-8") as f:
                f.write(_line(flat, self.fields))
        except OSError as e:
            raise FolderError(f"cannot write {target} ({_why(e)}); free space on its disk or "
                              f"make {self.out} writable, then run the same command again to "
                              f"resume") from None
