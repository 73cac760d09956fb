"""OBJ polylines: exact round trip, what Blender and the Repulsive Curves data write, and errors
that say what is wrong."""

import numpy as np
import pytest

from moebius_addon.core.geometry.objio import read_obj, write_obj
from tests.conftest import SHARED, read_obj_vertices, trefoil

DATA = SHARED / "data" / "repulsive-curves"


def _write(tmp_path, text, name="curve.obj"):
    path = tmp_path / name
    path.write_text(text)
    return path


def _verts(P):
    return "".join(f"v {x} {y} {z}\n" for x, y, z in P)


def _same_loop(A, B):
    """A and B are the same closed loop up to the starting vertex and the direction."""
    if A.shape != B.shape:
        return False
    k = int(np.argmin(np.linalg.norm(B - A[0], axis=1)))
    fwd, bwd = np.roll(B, -k, axis=0), np.roll(B[::-1], k + 1, axis=0)
    return np.array_equal(A, fwd) or np.array_equal(A, bwd)


def test_round_trip_is_exact(tmp_path):
    P = trefoil(101) * np.pi  # digits that need full repr precision
    path = tmp_path / "t.obj"
    write_obj(path, P)
    (Q,) = read_obj(path)
    assert Q.dtype == np.float64
    np.testing.assert_array_equal(Q, P)


def test_round_trip_link_keeps_components_in_order(tmp_path):
    comps = [trefoil(50), 3.0 + trefoil(20), np.eye(3)]
    write_obj(tmp_path / "l.obj", comps, name="Link")
    text = (tmp_path / "l.obj").read_text()
    assert "o Link" in text and text.count("\nl ") == 73
    back = read_obj(tmp_path / "l.obj")
    assert len(back) == 3
    for a, b in zip(comps, back, strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize(
    "name", ["freedman_unknot_1184.obj", "nice_trefoil_287.obj", "sampleknot_264.obj"]
)
def test_reads_the_shared_files(name):
    (P,) = read_obj(DATA / name)
    raw = read_obj_vertices(DATA / name)
    assert P.shape == raw.shape
    # every vertex is used once and consecutive vertices are joined by an edge of the file
    assert np.array_equal(np.unique(P, axis=0), np.unique(raw, axis=0))
    edges = {
        tuple(sorted(map(int, line.split()[1:3])))
        for line in (DATA / name).read_text().splitlines()
        if line.startswith("l ")
    }
    index = {tuple(v): i + 1 for i, v in enumerate(raw)}
    ids = [index[tuple(v)] for v in P]
    assert all(tuple(sorted((a, b))) in edges for a, b in zip(ids, np.roll(ids, -1), strict=True))


def test_loop_starts_at_first_vertex_and_follows_the_file(tmp_path):
    # sampleknot_264.obj writes "l 1 264", "l 264 263", …: the loop runs backwards
    (P,) = read_obj(DATA / "sampleknot_264.obj")
    raw = read_obj_vertices(DATA / "sampleknot_264.obj")
    np.testing.assert_array_equal(P[0], raw[0])
    np.testing.assert_array_equal(P[1], raw[-1])


def test_shuffled_pairs_single_line_and_blender_clutter(tmp_path, rng):
    P = trefoil(40)
    pairs = [(i + 1, (i + 1) % 40 + 1) for i in range(40)]
    rng.shuffle(pairs)
    pairs = [(b, a) if rng.random() < 0.5 else (a, b) for a, b in pairs]
    shuffled = "".join(f"l {a} {b}\n" for a, b in pairs)
    text = "# Blender 4.2 OBJ File\nmtllib x.mtl\no Knot\n" + _verts(P) + "s 0\n" + shuffled
    (Q,) = read_obj(_write(tmp_path, text))
    assert _same_loop(P, Q)
    np.testing.assert_array_equal(Q[0], P[0])
    one_line = "g knot\n" + _verts(P) + "vn 0 0 1\nl " + " ".join(map(str, range(1, 41))) + " 1\n"
    (Q,) = read_obj(_write(tmp_path, one_line))
    np.testing.assert_array_equal(Q, P)


def test_negative_indices_slashes_crlf_and_continued_lines(tmp_path):
    P = trefoil(5)
    (Q,) = read_obj(_write(tmp_path, _verts(P) + "l -5/1 -4/2 -3 \\\r\n -2 -1 -5\r\n"))
    np.testing.assert_array_equal(Q, P)


def test_repeated_end_point_counts_as_closed(tmp_path):
    P = trefoil(10)
    text = _verts(P) + f"v {P[0][0]} {P[0][1]} {P[0][2]}\nl " + " ".join(map(str, range(1, 12)))
    (Q,) = read_obj(_write(tmp_path, text))
    np.testing.assert_array_equal(Q, P)


def test_no_polylines_is_an_error(tmp_path):
    path = _write(tmp_path, "o Cube\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(ValueError, match="no polylines"):
        read_obj(path)


def test_open_component_is_named(tmp_path):
    loop = trefoil(12)
    text = "o Ring\n" + _verts(loop) + "".join(f"l {i + 1} {(i + 1) % 12 + 1}\n" for i in range(12))
    text += "o Tail\n" + _verts(loop[:6] + 5) + "l 13 14 15 16 17 18\n"
    path = _write(tmp_path, text)
    with pytest.raises(ValueError, match=r"component 2 of 2 .*object 'Tail'.* is open.*allow_open"):
        read_obj(path)
    comps, closed = read_obj(path, allow_open=True)
    assert closed == [True, False]
    np.testing.assert_array_equal(comps[1], loop[:6] + 5)


def test_open_path_is_returned_from_its_lower_end(tmp_path):
    P = trefoil(6)
    (Q,), closed = read_obj(
        _write(tmp_path, _verts(P) + "l 3 4\nl 2 3\nl 6 5\nl 1 2\nl 4 5\n"), allow_open=True
    )
    assert closed == [False]
    np.testing.assert_array_equal(Q, P)


def test_branching_and_missing_vertices_are_errors(tmp_path):
    P = trefoil(4)
    with pytest.raises(ValueError, match="vertex 1 lies on 3 edges"):
        read_obj(_write(tmp_path, _verts(P) + "l 1 2 3 4 1\nl 1 3\n"))
    with pytest.raises(ValueError, match="line 5: vertex 9 does not exist"):
        read_obj(_write(tmp_path, _verts(P) + "l 1 2 9\n"))
    with pytest.raises(ValueError, match="bad vertex"):
        read_obj(_write(tmp_path, "v 1 2 x\n"))


def test_write_rejects_bad_input(tmp_path):
    with pytest.raises(ValueError, match=r"shape \(4, 2\)"):
        write_obj(tmp_path / "x.obj", np.zeros((4, 2)))
    with pytest.raises(ValueError, match="component 2 has NaN"):
        write_obj(tmp_path / "x.obj", [trefoil(5), np.full((5, 3), np.nan)])
    with pytest.raises(ValueError, match="no components"):
        write_obj(tmp_path / "x.obj", [])


@pytest.mark.parametrize("coord", ["nan", "inf", "-inf", "1e999", "1_0"])
def test_a_vertex_that_is_no_decimal_number_is_refused_with_its_line(tmp_path, coord):
    # float() read "nan" and "inf" as vertices and "1_0" as 10
    P = trefoil(4)
    text = _verts(P[:2]) + f"v {coord} 0 0\n" + _verts(P[3:]) + "l 1 2 3 4 1\n"
    with pytest.raises(ValueError, match=f"line 3: (bad )?vertex 'v {coord} 0 0'"):
        read_obj(_write(tmp_path, text))


def test_an_index_with_an_underscore_is_refused(tmp_path):
    P = trefoil(12)  # int("1_0") is 10, a vertex that exists here
    with pytest.raises(ValueError, match="line 13: bad index '1_0'"):
        read_obj(_write(tmp_path, _verts(P) + "l 1 2 3 4 5 6 7 8 9 1_0 11 12 1\n"))


@pytest.mark.parametrize("name, char", [("knot\nl 1 50", r"'\\n'"), ("a # b", "'#'"),
                                        ("knot\\", r"'\\\\'"), ("a\u2028b", r"'\\u2028'")])
def test_a_name_that_would_not_read_back_is_refused(tmp_path, name, char):
    path = tmp_path / "k.obj"
    with pytest.raises(ValueError, match=f"object name .* holds {char}"):
        write_obj(path, trefoil(5), name=name)
    assert not path.exists()  # refused before the file is opened


def test_allow_open_as_text_is_refused(tmp_path):
    path = _write(tmp_path, _verts(trefoil(4)) + "l 1 2 3 4 1\n")
    # bool("False") is True: a pair (components, flags) came back instead of the polygons
    with pytest.raises(ValueError, match=r"allow_open must be True or False, got 'False'"):
        read_obj(path, allow_open="False")
