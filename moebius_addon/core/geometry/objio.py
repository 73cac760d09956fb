"""Polylines in Wavefront OBJ files: ``v`` vertices joined by ``l`` lines.

This is the format the Repulsive Curves data set and Blender's OBJ exporter use for curves:
``v x y z`` lines, then edges either as ``l a b`` pairs (Blender writes one pair per edge, in any
order and direction) or as longer ``l a b c …`` runs. Everything else — faces, normals, texture
coordinates, materials, ``o``/``g`` names, comments — is skipped; object names only serve to make
error messages precise.
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence

import numpy as np

from ..runs.checks import check_flag

__all__ = ["read_obj", "write_obj"]

# A coordinate as OBJ writers print one: decimal, optional exponent. Python's float() also
# takes "nan", "inf" and "1_0" (read as 10), none of which is a point of a curve.
_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")
_INDEX = re.compile(r"[+-]?\d+")


def read_obj(
    path: str | os.PathLike, *, allow_open: bool = False
) -> list[np.ndarray] | tuple[list[np.ndarray], list[bool]]:
    """Read the polylines of an OBJ file.

    The edges of all ``l`` lines are joined into connected components; each component must be
    a simple closed loop (every vertex on exactly two edges) or, with ``allow_open``, a simple
    path. Components come in the order of their first vertex in the file. A loop starts at that
    vertex and runs the way the file's first ``l`` line leaving it goes; an open path starts at
    its end with the lower index. An open path whose two ends lie at the same point (some
    exporters repeat the first vertex instead of closing the loop) counts as closed, the
    repeated vertex dropped.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.obj`` file.
    allow_open : bool
        False (default): every component must be closed, and the result is the list of
        polygons. True: open components are returned too, and the result is the pair
        ``(components, closed)`` with ``closed[c]`` telling whether component ``c`` is a loop.

    Returns
    -------
    list of (n_c, 3) float64 arrays, or (list of arrays, list of bool) when ``allow_open``.

    Raises
    ------
    ValueError
        The file has no ``l`` lines, refers to a missing vertex, has a vertex on three or more
        edges, or (without ``allow_open``) has an open component. The message says which.
    """
    allow_open = check_flag("allow_open", allow_open)
    name = os.fspath(path)
    verts, edges, where = _parse(name)
    if not edges:
        raise ValueError(
            f"{name!r} has no polylines (no 'l' lines with two or more vertices); "
            "export the curve as a polyline, i.e. as mesh edges (Blender: convert the curve to "
            "a mesh of edges, without faces, before exporting to OBJ)"
        )
    comps, closed, labels = _components(verts, edges, where, name)
    if allow_open:
        return comps, closed
    for c, is_closed in enumerate(closed):
        if not is_closed:
            first, last = comps[c][0], comps[c][-1]
            raise ValueError(
                f"component {c + 1} of {len(comps)} in {name!r} ({labels[c]}, "
                f"{len(comps[c])} vertices) is open: its ends {first.tolist()} and "
                f"{last.tolist()} are not joined; close it (in Blender: select both end "
                "vertices and press F, or Alt+C on a curve) or call "
                "read_obj(path, allow_open=True)"
            )
    return comps


def write_obj(
    path: str | os.PathLike, P: np.ndarray | Sequence[np.ndarray], *, name: str = "knot"
) -> None:
    """Write a closed polygon, or a link (list of polygons), as an OBJ polyline.

    One object ``name`` holding all vertices, and every component as a closed loop of
    ``l a b`` pairs, as Blender writes them. Coordinates are written with ``repr`` precision,
    so :func:`read_obj` gives back exactly the same arrays.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.obj`` file (overwritten).
    P : (n, 3) array or list of (n_c, 3) arrays
        Vertices of each closed component, ``n_c >= 3``.
    name : str
        Object name (``o`` line): one line of printable characters without ``#`` or ``\\``,
        else ValueError (a line break would start a line of its own, ``#`` a comment, and a
        ``\\`` at the end would join the next line to it, so the file would read back as
        something else).
    """
    _check_name(name)
    comps = [P] if isinstance(P, np.ndarray) else list(P)
    if not comps:
        raise ValueError("nothing to write: the link has no components")
    arrays = []
    for c, X in enumerate(comps):
        X = np.asarray(X, dtype=np.float64)
        if X.ndim != 2 or X.shape[1] != 3 or len(X) < 3:
            raise ValueError(f"component {c + 1} has shape {X.shape}; expected (n, 3) with n >= 3")
        if not np.all(np.isfinite(X)):
            raise ValueError(f"component {c + 1} has NaN or infinite coordinates")
        arrays.append(X)
    lines = ["# closed polylines written by moebius_addon", f"o {name}"]
    for X in arrays:
        lines.extend(f"v {x!r} {y!r} {z!r}" for x, y, z in X.tolist())
    start = 1
    for X in arrays:
        n = len(X)
        lines.extend(f"l {start + i} {start + (i + 1) % n}" for i in range(n))
        start += n
    with open(path, "w", encoding="utf-8", newline="\n") as f:
        f.write("\n".join(lines) + "\n")


def _check_name(name) -> None:
    """ValueError unless ``name`` is one line of OBJ text that reads back as written."""
    if not isinstance(name, str):
        raise ValueError(f"name must be text, got {name!r} ({type(name).__name__})")
    bad = next((c for c in name if c in "#\\" or not (c.isprintable() or c == " ")), None)
    if bad is not None:
        what = "a comment" if bad == "#" else (
            "a line continuation" if bad == "\\" else "a new line or a lost character")
        raise ValueError(f"the object name {name!r} holds {bad!r}, which an OBJ file reads as "
                         f"{what}: give a name of printable characters without '#' or '\\'")


def _parse(name: str) -> tuple[np.ndarray, list[tuple[int, int]], dict[tuple[int, int], str]]:
    """Vertices, undirected-deduplicated edges (0-based, file direction) and where each edge
    was read ("object 'Knot', line 12")."""
    verts: list[list[float]] = []
    edges: list[tuple[int, int]] = []
    where: dict[tuple[int, int], str] = {}
    seen: set[tuple[int, int]] = set()
    obj = None
    with open(name, encoding="utf-8", errors="replace") as f:
        text = f.read().replace("\\\n", " ")  # OBJ line continuation
    for lineno, raw in enumerate(text.splitlines(), start=1):
        parts = raw.split("#", 1)[0].split()
        if not parts:
            continue
        key = parts[0]
        if key == "v":
            coords = parts[1:4]
            if len(coords) != 3:
                raise ValueError(f"{name!r}, line {lineno}: vertex needs x y z: {raw.strip()!r}")
            bad = [t for t in coords if not _NUMBER.fullmatch(t)]
            if bad:
                raise ValueError(f"{name!r}, line {lineno}: bad vertex {raw.strip()!r}: "
                                 f"{bad[0]!r} is not a decimal number; fix the coordinate in "
                                 "the file or export the curve again")
            xyz = [float(t) for t in coords]
            if not all(map(np.isfinite, xyz)):
                raise ValueError(f"{name!r}, line {lineno}: vertex {raw.strip()!r} has a "
                                 "coordinate too large for a float; scale the curve down "
                                 "before exporting")
            verts.append(xyz)
        elif key in ("o", "g"):
            obj = " ".join(parts[1:]) or None
        elif key == "l":
            idx = []
            for tok in parts[1:]:
                head = tok.split("/", 1)[0]
                if not _INDEX.fullmatch(head):
                    raise ValueError(
                        f"{name!r}, line {lineno}: bad index {tok!r} in {raw.strip()!r} "
                        "(a vertex index is a whole number)"
                    )
                i = int(head)
                i = i - 1 if i > 0 else len(verts) + i  # negative: relative to the end
                if not 0 <= i < len(verts):
                    raise ValueError(
                        f"{name!r}, line {lineno}: vertex {tok} does not exist "
                        f"({len(verts)} vertices read so far)"
                    )
                idx.append(i)
            label = (f"object {obj!r}, " if obj else "") + f"line {lineno}"
            for a, b in zip(idx[:-1], idx[1:], strict=True):
                key_ab = (min(a, b), max(a, b))
                if a != b and key_ab not in seen:
                    seen.add(key_ab)
                    edges.append((a, b))
                    where[key_ab] = label
    return np.asarray(verts, dtype=np.float64).reshape(-1, 3), edges, where


def _components(
    verts: np.ndarray,
    edges: list[tuple[int, int]],
    where: dict[tuple[int, int], str],
    name: str,
) -> tuple[list[np.ndarray], list[bool], list[str]]:
    nbrs: dict[int, list[int]] = {}
    for a, b in edges:
        nbrs.setdefault(a, []).append(b)
        nbrs.setdefault(b, []).append(a)
    for v, adj in nbrs.items():
        if len(adj) > 2:
            label = where[(min(v, adj[0]), max(v, adj[0]))]
            raise ValueError(
                f"{name!r} ({label}): vertex {v + 1} lies on {len(adj)} edges, so the polyline "
                "branches there; every vertex of a curve must join exactly two edges "
                "(one at the ends of an open curve)"
            )
    # First vertex written after v in an "l" line: the direction the file gives to a loop.
    first_out: dict[int, int] = {}
    for a, b in edges:
        first_out.setdefault(a, b)
    comps, closed, labels = [], [], []
    done: set[int] = set()
    for s in sorted(nbrs):  # file order of the vertices; a component starts at its first vertex
        if s in done:
            continue
        if len(nbrs[s]) == 2:  # s may be inside an open path: find its end, if any
            end = _walk(nbrs, s, nbrs[s][0])[-1]
            if len(nbrs[end]) == 1:
                s = min(end, _walk(nbrs, end, nbrs[end][0])[-1])
        path = _walk(nbrs, s, first_out.get(s, nbrs[s][0]) if len(nbrs[s]) == 2 else nbrs[s][0])
        is_closed = len(nbrs[s]) == 2
        done.update(path)
        X = verts[path]
        if not is_closed and len(X) > 3 and np.array_equal(X[0], X[-1]):
            X, is_closed = X[:-1], True
        comps.append(X.copy())
        closed.append(is_closed)
        a, b = path[0], path[1]
        labels.append(where[(min(a, b), max(a, b))])
    return comps, closed, labels


def _walk(nbrs: dict[int, list[int]], start: int, second: int) -> list[int]:
    """Vertices met walking from ``start`` through ``second`` until a dead end or back at
    ``start`` (not repeated)."""
    path = [start, second]
    prev, cur = start, second
    while True:
        nxt = [w for w in nbrs[cur] if w != prev]
        if not nxt or nxt[0] == start:
            return path
        prev, cur = cur, nxt[0]
        path.append(cur)
