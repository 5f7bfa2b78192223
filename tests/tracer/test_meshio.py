"""OBJ and PLY files read as Mitsuba reads them; vertex normals computed as Mitsuba does."""

import contextlib
import io
import math
import os
import re
import struct
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from whitted.tracer.errors import UserError
from whitted.tracer.meshio import (
    MeshData,
    MeshError,
    compute_vertex_normals,
    face_normals,
    load_mesh,
    row_lengths,
)

#: Mitsuba stores positions, normals and uvs in float32 and computes its normals in
#: float32: a unit vector is then off by a few 2^-24; 1e-5 leaves a wide margin.
F32_TOL = 1e-5


def write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


SQUARE = """\
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
"""


# --------------------------------------------------------------------------- OBJ


def test_obj_plain_vertex_indices_give_positions_and_faces(tmp_path):
    m = load_mesh(write(tmp_path, "a.obj", SQUARE + "f 1 2 3\nf 1 3 4\n"))
    assert isinstance(m, MeshData)
    np.testing.assert_array_equal(m.vertices, [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    np.testing.assert_array_equal(m.faces, [[0, 1, 2], [0, 2, 3]])
    assert m.vertices.dtype == np.float64 and m.faces.dtype == np.int64
    assert m.normals is None and m.uvs is None


def test_obj_v_vt_form_gives_uvs_flipped_like_mitsuba(tmp_path):
    text = SQUARE + "vt 0.25 0.125\nvt 0.5 0.75\nvt 1 1\nf 1/1 2/2 3/3\n"
    m = load_mesh(write(tmp_path, "a.obj", text))
    # Mitsuba's obj plugin flips v by default (flip_tex_coords = true).
    np.testing.assert_array_equal(m.uvs, [[0.25, 0.875], [0.5, 0.25], [1, 0]])
    raw = load_mesh(tmp_path / "a.obj", flip_tex_coords=False)
    np.testing.assert_array_equal(raw.uvs, [[0.25, 0.125], [0.5, 0.75], [1, 1]])
    assert m.normals is None
    # Unused positions are dropped: vertices are the corners the faces use.
    np.testing.assert_array_equal(m.vertices, [[0, 0, 0], [1, 0, 0], [1, 1, 0]])


def test_obj_v_double_slash_vn_form_gives_unit_normals(tmp_path):
    text = SQUARE + "vn 0 0 2\nvn 0 3 4\nf 1//1 2//2 3//1\n"
    m = load_mesh(write(tmp_path, "a.obj", text))
    np.testing.assert_allclose(m.normals, [[0, 0, 1], [0, 0.6, 0.8], [0, 0, 1]], atol=1e-15)
    assert m.uvs is None


def test_obj_v_vt_vn_form_gives_all_three(tmp_path):
    text = SQUARE + "vt 0 0\nvt 1 0\nvt 1 1\nvn 0 0 1\nf 1/1/1 2/2/1 3/3/1\n"
    m = load_mesh(write(tmp_path, "a.obj", text), flip_tex_coords=False)
    np.testing.assert_array_equal(m.vertices, [[0, 0, 0], [1, 0, 0], [1, 1, 0]])
    np.testing.assert_array_equal(m.uvs, [[0, 0], [1, 0], [1, 1]])
    np.testing.assert_array_equal(m.normals, np.tile([0.0, 0, 1], (3, 1)))


def test_obj_negative_indices_count_back_from_the_last_element_read(tmp_path):
    rel = load_mesh(write(tmp_path, "r.obj", SQUARE + "f -4 -3 -2\nv 5 5 5\nf -5 -1 -2\n"))
    ab = load_mesh(write(tmp_path, "a.obj", SQUARE + "f 1 2 3\nv 5 5 5\nf 1 5 4\n"))
    np.testing.assert_array_equal(rel.vertices, ab.vertices)
    np.testing.assert_array_equal(rel.faces, ab.faces)
    text = SQUARE + "vt 0 0\nvt 1 0\nvt 1 1\nvn 0 0 1\nf -4/-3/-1 -3/-2/-1 -2/-1/-1\n"
    m = load_mesh(write(tmp_path, "b.obj", text), flip_tex_coords=False)
    np.testing.assert_array_equal(m.uvs, [[0, 0], [1, 0], [1, 1]])
    np.testing.assert_array_equal(m.normals[:, 2], 1)


def test_obj_quad_becomes_two_triangles_and_a_pentagon_three(tmp_path):
    text = SQUARE + "v 0.5 1.5 0\nf 1 2 3 4\nf 1 2 3 5 4\n"
    m = load_mesh(write(tmp_path, "a.obj", text))
    # A fan around the first corner: (v0, v1, v2), (v0, v2, v3), ...
    np.testing.assert_array_equal(m.faces, [[0, 1, 2], [0, 2, 3], [0, 1, 2], [0, 2, 4],
                                            [0, 4, 3]])


def test_obj_vertices_are_split_by_distinct_index_triples_in_order_of_first_use(tmp_path):
    # Two faces of a cube's corner: position 1 is used with normals 1 and 2, so it
    # becomes two vertices; a repeated triple is one vertex.
    text = ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nvn 0 0 -1\nvn 0 -1 0\n"
            "f 1//1 3//1 2//1\nf 1//2 2//2 4//2\nf 2//1 3//1 1//1\n")
    m = load_mesh(write(tmp_path, "a.obj", text))
    assert len(m.vertices) == 6
    np.testing.assert_array_equal(m.faces, [[0, 1, 2], [3, 4, 5], [2, 1, 0]])
    np.testing.assert_array_equal(m.vertices[[0, 3]], [[0, 0, 0], [0, 0, 0]])
    np.testing.assert_array_equal(m.normals[[0, 3]], [[0, 0, -1], [0, -1, 0]])


def test_obj_other_statements_comments_and_line_endings_are_ignored(tmp_path):
    text = ("# a comment\r\nmtllib x.mtl\r\no thing\r\ng group\r\ns 1\r\nusemtl red\r\n"
            "v\t0 0 0\r\nv 1 0 0 1.0\r\nv 0 1 0 0.5 0.5 0.5\r\n\r\nl 1 2\r\n"
            "vp 0.5\r\nf 1 2 3 # trailing words are not indices\r\n")
    m = load_mesh(write(tmp_path, "a.obj", text))
    np.testing.assert_array_equal(m.faces, [[0, 1, 2]])
    np.testing.assert_array_equal(m.vertices, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])


def test_obj_degenerate_faces_are_kept(tmp_path):
    m = load_mesh(write(tmp_path, "a.obj", SQUARE + "f 1 2 3\nf 1 1 2\n"))
    assert len(m.faces) == 2


def test_obj_vertex_table_equals_mitsubas(tmp_path, mi):
    # Positive indices only: Mitsuba's obj plugin does not read negative ones.
    text = (SQUARE + "v 0.5 0.5 1\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\nvn 0 1 1\n"
            "f 1/1/1 2/2/1 3/3/2 4/4/2\nf 1/1/1 2/2/1 5/3/1\nf 2/2/2 3/3/2 5/4/2\n")
    path = write(tmp_path, "a.obj", text)
    m = load_mesh(path)
    params = mi.traverse(mi.load_dict({"type": "obj", "filename": str(path)}))
    np.testing.assert_array_equal(np.array(params["faces"]).reshape(-1, 3), m.faces)
    np.testing.assert_allclose(np.array(params["vertex_positions"]).reshape(-1, 3),
                               m.vertices, atol=F32_TOL)
    np.testing.assert_allclose(np.array(params["vertex_texcoords"]).reshape(-1, 2), m.uvs,
                               atol=F32_TOL)
    np.testing.assert_allclose(np.array(params["vertex_normals"]).reshape(-1, 3), m.normals,
                               atol=F32_TOL)


# --------------------------------------------------------------------------- PLY

_FMT = {"char": "b", "uchar": "B", "short": "h", "ushort": "H", "int": "i", "uint": "I",
        "float": "f", "double": "d", "int8": "b", "uint8": "B", "int16": "h",
        "uint16": "H", "int32": "i", "uint32": "I", "float32": "f", "float64": "d"}


def write_ply(path, fmt, elements):
    """A PLY file. ``elements``: [(name, [(prop, type) or (prop, 'list', count_t, item_t)],
    rows)], each row a tuple with one value per scalar property and a sequence per list."""
    head = ["ply", f"format {fmt} 1.0", "comment written by the tests"]
    for name, props, rows in elements:
        head.append(f"element {name} {len(rows)}")
        for p in props:
            head.append(f"property list {p[2]} {p[3]} {p[0]}" if p[1] == "list"
                        else f"property {p[1]} {p[0]}")
    head.append("end_header")
    out = ("\n".join(head) + "\n").encode()
    order = "<" if fmt == "binary_little_endian" else ">"
    for _, props, rows in elements:
        for row in rows:
            if fmt == "ascii":
                words = []
                for p, v in zip(props, row, strict=True):
                    words += [str(len(v)), *map(str, v)] if p[1] == "list" else [str(v)]
                out += (" ".join(words) + "\n").encode()
                continue
            for p, v in zip(props, row, strict=True):
                if p[1] == "list":
                    out += struct.pack(order + _FMT[p[2]], len(v))
                    out += struct.pack(order + _FMT[p[3]] * len(v), *v)
                else:
                    out += struct.pack(order + _FMT[p[1]], v)
    Path(path).write_bytes(out)
    return Path(path)


XYZ = [("x", "float"), ("y", "float"), ("z", "float")]
VERTS = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, 1.0, 0.0), (0.0, 1.0, 0.0), (0.5, 0.5, 1.0)]
FACES = [([0, 1, 2],), ([0, 2, 3],), ([0, 1, 4],)]
FACE_PROP = [("vertex_indices", "list", "uchar", "int")]


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
def test_ply_triangles_read_alike_in_every_format(tmp_path, fmt):
    m = load_mesh(write_ply(tmp_path / "a.ply", fmt,
                            [("vertex", XYZ, VERTS), ("face", FACE_PROP, FACES)]))
    np.testing.assert_array_equal(m.vertices, VERTS)
    np.testing.assert_array_equal(m.faces, [[0, 1, 2], [0, 2, 3], [0, 1, 4]])
    assert m.normals is None and m.uvs is None


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
@pytest.mark.parametrize("count_t,index_t", [("uchar", "int"), ("uint8", "uint32"),
                                             ("ushort", "ushort"), ("int", "short"),
                                             ("char", "uint")])
def test_ply_polygons_of_any_integer_types_are_fans(tmp_path, fmt, count_t, index_t):
    faces = [([0, 1, 2, 3],), ([0, 1, 4],), ([3, 2, 4, 1, 0],)]
    prop = [("vertex_index", "list", count_t, index_t)]
    verts = [v + (1.0,) for v in VERTS]
    m = load_mesh(write_ply(tmp_path / "a.ply", fmt,
                            [("vertex", XYZ[:2] + [("z", "double"), ("w", "float")], verts),
                             ("face", prop, faces)]))
    np.testing.assert_array_equal(m.faces, [[0, 1, 2], [0, 2, 3], [0, 1, 4], [3, 2, 4],
                                            [3, 4, 1], [3, 1, 0]])


@pytest.mark.parametrize("names", [("u", "v"), ("s", "t"), ("texture_u", "texture_v")])
def test_ply_normals_and_each_uv_naming(tmp_path, names):
    props = XYZ + [("nx", "float"), ("ny", "float"), ("nz", "float"),
                   (names[0], "float"), (names[1], "float")]
    rows = [v + (0.0, 0.0, 2.0, 0.25 * i, 0.5) for i, v in enumerate(VERTS)]
    m = load_mesh(write_ply(tmp_path / "a.ply", "binary_little_endian",
                            [("vertex", props, rows), ("face", FACE_PROP, FACES)]))
    np.testing.assert_array_equal(m.normals, np.tile([0.0, 0, 1], (5, 1)))
    # Mitsuba's ply plugin does not flip v (its flip_tex_coords defaults to false).
    np.testing.assert_array_equal(m.uvs, [[0.25 * i, 0.5] for i in range(5)])


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
def test_ply_unknown_properties_and_elements_are_skipped(tmp_path, fmt):
    vprops = [("confidence", "double"), *XYZ, ("red", "uchar"),
              ("tags", "list", "uchar", "short"), ("nx", "float")]  # nx alone: no normals
    vrows = [(0.5, *v, 200, [1, 2, 3][:i % 4], 0.0) for i, v in enumerate(VERTS)]
    fprops = [("flags", "ushort"), *FACE_PROP, ("quality", "float"),
              ("more", "list", "uint", "double")]
    frows = [(7, f[0], 0.5, [1.5] * i) for i, f in enumerate(FACES)]
    other = ("material", [("ids", "list", "int", "uchar"), ("shine", "float")],
             [([1, 2], 0.5), ([], 1.0), ([3], 2.0)])
    # Two elements of one name are refused (their data could not be told apart by
    # name), so the element after the faces has a name of its own.
    after = ("material_2", *other[1:])
    path = write_ply(tmp_path / "a.ply", fmt, [other, ("vertex", vprops, vrows),
                                               ("edge", [("a", "int"), ("b", "int")],
                                                [(0, 1), (1, 2)]),
                                               ("face", fprops, frows), after])
    m = load_mesh(path)
    np.testing.assert_array_equal(m.vertices, VERTS)
    np.testing.assert_array_equal(m.faces, [[0, 1, 2], [0, 2, 3], [0, 1, 4]])
    assert m.normals is None and m.uvs is None


@pytest.mark.parametrize("newline", ["\n", "\r\n", "\r"])
@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
def test_ply_lines_may_end_in_lf_crlf_or_cr(tmp_path, fmt, newline):
    p = write_ply(tmp_path / "a.ply", fmt, [("vertex", XYZ, VERTS), ("face", FACE_PROP, FACES)])
    head, body = p.read_bytes().split(b"end_header\n")
    if fmt == "ascii":
        body = body.replace(b"\n", newline.encode())
    p.write_bytes(head.replace(b"\n", newline.encode()) + b"end_header" + newline.encode()
                  + body)
    np.testing.assert_array_equal(load_mesh(p).faces, [[0, 1, 2], [0, 2, 3], [0, 1, 4]])
    if fmt == "ascii":  # and line numbers count those lines
        p.write_bytes(p.read_bytes().replace(b"0.5 0.5 1.0", b"0.5 oops 1.0"))
        check_error(p, ":15:", "'oops'")

def test_ply_equals_mitsubas_reading(tmp_path, mi):
    props = XYZ + [("nx", "float"), ("ny", "float"), ("nz", "float"),
                   ("u", "float"), ("v", "float")]
    rng = np.random.default_rng(3)
    rows = [tuple(v) + tuple(rng.normal(size=3)) + (0.1 * i, 0.2 * i)
            for i, v in enumerate(VERTS)]
    path = write_ply(tmp_path / "a.ply", "binary_little_endian",
                     [("vertex", props, rows), ("face", FACE_PROP, FACES)])
    m = load_mesh(path)
    params = mi.traverse(mi.load_dict({"type": "ply", "filename": str(path)}))
    np.testing.assert_array_equal(np.array(params["faces"]).reshape(-1, 3), m.faces)
    np.testing.assert_allclose(np.array(params["vertex_positions"]).reshape(-1, 3),
                               m.vertices, atol=F32_TOL)
    np.testing.assert_allclose(np.array(params["vertex_normals"]).reshape(-1, 3), m.normals,
                               atol=F32_TOL)
    np.testing.assert_allclose(np.array(params["vertex_texcoords"]).reshape(-1, 2), m.uvs,
                               atol=F32_TOL)


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
def test_ply_doubles_are_rounded_to_float32_as_mitsuba_stores_them(tmp_path, fmt):
    # Mitsuba keeps positions, normals and uvs in float32 whatever the file's type; so
    # does the mesh read here (its vertex normals are then computed from the same values).
    props = [(c, "double") for c in ("x", "y", "z", "nx", "ny", "nz", "u", "v")]
    rows = [(0.1 * i, 1 / 3, 0.7, 0.1, 0.2, 0.3 + i, 0.1, 2 / 3) for i in range(5)]
    m = load_mesh(write_ply(tmp_path / "a.ply", fmt, [("vertex", props, rows),
                                                      ("face", FACE_PROP, FACES)]))
    f32 = np.asarray(rows, dtype=np.float32).astype(np.float64)
    np.testing.assert_array_equal(m.vertices, f32[:, :3])
    np.testing.assert_array_equal(m.uvs, f32[:, 6:])
    n = f32[:, 3:6]
    np.testing.assert_array_equal(m.normals, n / np.linalg.norm(n, axis=1, keepdims=True))


def test_ply_double_positions_equal_mitsubas_bit_for_bit(tmp_path, mi):
    rng = np.random.default_rng(5)
    rows = [tuple(v) for v in rng.normal(size=(5, 3)).tolist()]
    path = write_ply(tmp_path / "a.ply", "binary_little_endian",
                     [("vertex", [("x", "double"), ("y", "double"), ("z", "double")], rows),
                      ("face", FACE_PROP, FACES)])
    params = mi.traverse(mi.load_dict({"type": "ply", "filename": str(path)}))
    np.testing.assert_array_equal(np.array(params["vertex_positions"]).reshape(-1, 3),
                                  load_mesh(path).vertices)


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
def test_ply_polygons_with_more_lists_and_uchar_lengths_above_127_are_fans(tmp_path, fmt):
    # Faces carrying a second list (per-corner texture coordinates, as some exporters
    # write) and a scalar after the lists: read record by record, fanned alike.
    polys = [[0, 1, 2, 3], [0, 1, 4], [3, 2, 4, 1, 0]]
    props = [("flags", "ushort"), ("vertex_indices", "list", "uchar", "int"),
             ("texcoord", "list", "int", "float"), ("quality", "double")]
    rows = [(7, p, [0.5] * 2 * len(p), 1.5) for p in polys]
    m = load_mesh(write_ply(tmp_path / "a.ply", fmt, [("vertex", XYZ, VERTS),
                                                      ("face", props, rows)]))
    np.testing.assert_array_equal(m.faces, [[0, 1, 2], [0, 2, 3], [0, 1, 4], [3, 2, 4],
                                            [3, 4, 1], [3, 1, 0]])
    # Vertices whose positions, normals and uvs follow a list of varying length.
    vprops = [("tags", "list", "uchar", "short"), *XYZ, ("nx", "float"), ("ny", "float"),
              ("nz", "double"), ("u", "float"), ("v", "float")]
    vrows = [([1, 2, 3][:i % 4], *v, 0.0, 0.6, 0.8, 0.25 * i, 0.5) for i, v in enumerate(VERTS)]
    m = load_mesh(write_ply(tmp_path / "v.ply", fmt, [("vertex", vprops, vrows),
                                                      ("face", FACE_PROP, FACES)]))
    np.testing.assert_array_equal(m.vertices, VERTS)
    np.testing.assert_allclose(m.normals, np.tile([0, 0.6, 0.8], (5, 1)), atol=1e-7)
    np.testing.assert_array_equal(m.uvs, [[0.25 * i, 0.5] for i in range(5)])
    # A 130-gon: its length, 130, is a uchar above 127 (negative if read as a char).
    ring = [(math.cos(k / 20.7), math.sin(k / 20.7), 0.0) for k in range(130)]
    m = load_mesh(write_ply(tmp_path / "b.ply", fmt, [("vertex", XYZ, ring),
                                                      ("face", FACE_PROP, [(list(range(130)),)])]))
    np.testing.assert_array_equal(m.faces, [[0, k, k + 1] for k in range(1, 129)])


def test_ply_binary_polygons_cut_short_are_refused_naming_the_record(tmp_path):
    polys = [([0, 1, 2, 3],), ([0, 1, 4],), ([3, 2, 4, 1, 0],)]
    p = write_ply(tmp_path / "a.ply", "binary_little_endian",
                  [("vertex", XYZ, VERTS), ("face", [("vertex_index", "list", "int", "uint")],
                                            polys)])
    (tmp_path / "cut.ply").write_bytes(p.read_bytes()[:-3])
    check_error(tmp_path / "cut.ply", "ends inside element 'face'", "after 2 of 3 records")
    # Cut inside the last record's length (2 of its 4 bytes left).
    (tmp_path / "mid.ply").write_bytes(p.read_bytes()[:-(4 * 5 + 2)])
    check_error(tmp_path / "mid.ply", "ends inside element 'face'", "after 2 of 3 records")
    # A list length larger than the file: refused the same way, not allocated.
    data = bytearray(p.read_bytes())
    at = data.index(b"end_header\n") + len(b"end_header\n") + 5 * 12
    data[at:at + 4] = struct.pack("<i", 10**9)
    (tmp_path / "long.ply").write_bytes(bytes(data))
    check_error(tmp_path / "long.ply", "ends inside element 'face'", "after 0 of 3 records")


@pytest.mark.parametrize("edit,words", [
    (("3 0 1 2\n", "3 0 1 2 7\n"), (":16:", "more numbers on the line")),
    (("3 0 1 2\n", "3 0 1\n"), (":16:", "line ends early")),
    (("3 0 1 2\n", "4 0 1 2\n"), (":16:", "line ends early")),
    (("0.5 0.5 1.0\n", "0.5 0.5\n"), (":15:", "line ends early")),
    (("3 0 1 2\n", "2.5 0 1 2\n"), (":16:", "expected an integer", "'2.5'")),
    (("3 0 1 2\n", "3 0 1e0 2\n"), (":16:", "expected an integer", "'1e0'")),
    (("3 0 1 2\n", "3.0 0 1 2\n"), (":16:", "expected an integer", "'3.0'")),
    (("3 0 1 2\n", "3 0 1 4294967296\n"), (":16:", "does not fit", "'int'")),
    (("3 0 1 2\n", "-3 0 1 2\n"), (":16:", "does not fit", "'uchar'")),
    (("3 0 1 2\n", "3 0 1 2 # a comment\n"), (":16:", "expected an integer", "'#'")),
])
def test_ply_ascii_records_are_one_line_of_numbers_of_their_declared_types(tmp_path, edit,
                                                                            words):
    p = write_ply(tmp_path / "a.ply", "ascii", [("vertex", XYZ, VERTS),
                                                ("face", FACE_PROP, FACES)])
    text = p.read_text()
    assert edit[0] in text
    p.write_text(text.replace(edit[0], edit[1], 1))
    check_error(p, *words)


def test_ply_ascii_line_of_the_wrong_length_is_refused_as_such(tmp_path):
    # One number too many shifts what follows the list: the line's length is the problem,
    # not the 0.5 that now falls among the indices.
    props = [("vertex_indices", "list", "uchar", "int"), ("quality", "float")]
    p = write_ply(tmp_path / "a.ply", "ascii", [("vertex", XYZ, VERTS),
                                                ("face", props, [(f[0], 0.5) for f in FACES])])
    p.write_text(p.read_text().replace("3 0 1 2 0.5\n", "3 0 1 2 0.5 9\n"))
    check_error(p, ":17:", "more numbers on the line than the header declares")
    # A negative length of a signed type is a number of that type, but no list's length.
    p = write_ply(tmp_path / "b.ply", "ascii", [
        ("vertex", XYZ, VERTS), ("face", [("vertex_indices", "list", "char", "int")], FACES)])
    p.write_text(p.read_text().replace("3 0 1 2\n", "-3 0 1 2\n"))
    check_error(p, ":16:", "negative length -3")


def test_ply_ascii_blank_lines_and_signs_are_read_as_mitsuba_reads_them(tmp_path):
    # Mitsuba reads an ascii body number by number: blank lines and a '+' change nothing.
    p = write_ply(tmp_path / "a.ply", "ascii", [("vertex", XYZ, VERTS),
                                                ("face", FACE_PROP, FACES)])
    p.write_text(p.read_text().replace("3 0 1 2\n", "\n  \n+3 +0 1 2\n"))
    m = load_mesh(p)
    np.testing.assert_array_equal(m.faces, [[0, 1, 2], [0, 2, 3], [0, 1, 4]])
    p.write_text(p.read_text().replace("3 0 1 4", "oops"))
    check_error(p, ":20:", "expected an integer", "'oops'")  # line numbers count blank lines


@pytest.mark.parametrize("edit,words", [
    (("format binary_little_endian 1.0", "format binary_little_endian 2.0"), (":2:", "1.0")),
    (("comment written by the tests", "colour red"), (":3:", "unknown keyword 'colour'")),
    (("comment written by the tests", "property float w"), (":3:", "before any element")),
    (("comment written by the tests", "format ascii 1.0"), (":3:", "second 'format'")),
    (("property float z", "property float z extra"), (":7:", "expected 'property")),
    (("property list uchar int", "property list uchar"), (":9:", "expected 'property list")),
    (("property list uchar int", "property list float int"), (":9:", "integer type")),
    (("property float y", "property float x"), (":6:", "two properties of the same name")),
    (("end_header\n", "end_header now\n"), ("'end_header' line",)),
    (("ply\n", "ply 1\n"), (":1:", "'ply' alone")),
])
def test_ply_header_lines_follow_the_format_to_the_letter(tmp_path, edit, words):
    p = write_ply(tmp_path / "a.ply", "binary_little_endian", [("vertex", XYZ, VERTS),
                                                               ("face", FACE_PROP, FACES)])
    data = p.read_bytes()
    assert edit[0].encode() in data
    p.write_bytes(data.replace(edit[0].encode(), edit[1].encode(), 1))
    check_error(p, *words)


@pytest.mark.parametrize("newline", [b"\r", b"\r\n", b"\n"])
def test_ply_header_end_is_a_line_of_its_own_and_the_body_starts_right_after(tmp_path,
                                                                             newline):
    # 'end_header' in a comment does not end the header; a binary body whose first byte
    # is a line feed keeps it after a header of CR lines (the x of vertex 0 here).
    x0 = struct.unpack("<f", b"\n\x00\x00\x00")[0]  # 1.4e-44, a float32 subnormal
    verts = [(x0, 0.0, 0.0)] + VERTS[1:]
    p = write_ply(tmp_path / "a.ply", "binary_little_endian", [("vertex", XYZ, verts),
                                                               ("face", FACE_PROP, FACES)])
    head, body = p.read_bytes().split(b"end_header\n", 1)
    head = head.replace(b"comment written by the tests", b"comment the last line: end_header")
    p.write_bytes(head.replace(b"\n", newline) + b"end_header" + newline + body)
    m = load_mesh(p)
    np.testing.assert_array_equal(m.vertices, np.float32(verts).astype(np.float64))


# --------------------------------------------------------------------------- errors


def check_error(path, *words):
    with pytest.raises(MeshError) as info:
        load_mesh(path)
    msg = str(info.value)
    assert isinstance(info.value, UserError)
    assert "\n" not in msg and str(path) in msg
    for w in words:
        assert w in msg, msg
    return msg


def test_missing_file_is_a_mesh_error_naming_it(tmp_path):
    check_error(tmp_path / "nothing.obj", "no such")


def test_unknown_format_is_a_mesh_error(tmp_path):
    check_error(write(tmp_path, "a.stl", "solid x\n"), "unknown mesh format")
    check_error(write(tmp_path, "b.ply", "v 0 0 0\n"), "not a PLY file")


@pytest.mark.parametrize("line,words", [
    ("f 1 2 9", ("bad index", "vertex 9")),
    ("f 1 2 0", ("bad index",)),
    ("f -1 -2 -7", ("bad index", "vertex -7")),
    ("f 1/5 2/1 3/1", ("bad index", "texture coordinate 5")),
    ("f 1//2 2//1 3//1", ("bad index", "normal 2")),
])
def test_obj_bad_index_names_file_line_and_index(tmp_path, line, words):
    path = write(tmp_path, "a.obj", SQUARE + "vt 0 0\nvn 0 0 1\n" + line + "\n")
    check_error(path, ":7:", *words)


@pytest.mark.parametrize("line", ["v 1 2", "v 1 x 2", "v nan 0 0", "vn 0 inf 0", "vt", "f 1 2",
                                  "f 1/1/1/1 2 3", "f 1 two 3", "f /1 2 3"])
def test_obj_malformed_line_names_file_and_line_number(tmp_path, line):
    path = write(tmp_path, "a.obj", SQUARE + "vt 0 0\nvn 0 0 1\n" + line + "\nf 1 2 3\n")
    check_error(path, ":7:", "malformed")


def test_obj_without_faces_is_a_mesh_error(tmp_path):
    check_error(write(tmp_path, "a.obj", SQUARE), "no faces")


def test_ply_problems_are_mesh_errors(tmp_path):
    good = [("vertex", XYZ, VERTS), ("face", FACE_PROP, FACES)]
    p = write_ply(tmp_path / "a.ply", "binary_little_endian", good)
    (tmp_path / "cut.ply").write_bytes(p.read_bytes()[:-5])
    check_error(tmp_path / "cut.ply", "ends inside element 'face'")
    (tmp_path / "tail.ply").write_bytes(p.read_bytes() + b"\x01\x02")
    check_error(tmp_path / "tail.ply", "after its last element")
    check_error(write_ply(tmp_path / "b.ply", "ascii",
                          [("vertex", XYZ, VERTS), ("face", FACE_PROP, [([0, 1, 9],)])]),
                "bad index", "vertex 9")
    check_error(write_ply(tmp_path / "c.ply", "ascii", [("vertex", XYZ, VERTS)]), "no faces")
    check_error(write_ply(tmp_path / "d.ply", "ascii",
                          [("vertex", XYZ, VERTS),
                           ("face", [("corners", "list", "uchar", "int")], FACES)]),
                "vertex_indices")
    check_error(write_ply(tmp_path / "e.ply", "ascii",
                          [("vertex", XYZ[:2], [v[:2] for v in VERTS]),
                           ("face", FACE_PROP, FACES)]), "no property 'z'")
    text = p.read_bytes().replace(b"property float y", b"property floot y")
    (tmp_path / "f.ply").write_bytes(text)
    check_error(tmp_path / "f.ply", "unknown PLY type")
    text = p.read_bytes().replace(b"format binary_little_endian", b"format binary_middle")
    (tmp_path / "g.ply").write_bytes(text)
    check_error(tmp_path / "g.ply", "malformed PLY header line", ":2:")
    bad = write_ply(tmp_path / "h.ply", "ascii", good)
    bad.write_text(bad.read_text().replace("0.5 0.5 1.0", "0.5 oops 1.0"))
    check_error(bad, "expected a number", "'oops'", ":15:")  # 10 header lines, 5th vertex


# --------------------------------------------------------------------------- normals


def uv_sphere(n_lon, n_lat):
    """Unit sphere: poles plus (n_lat - 1) rings of n_lon vertices, quads split in two."""
    theta = np.linspace(0, np.pi, n_lat + 1)[1:-1]
    phi = np.linspace(0, 2 * np.pi, n_lon, endpoint=False)
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    ring = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    v = np.vstack([[0, 0, 1], ring.reshape(-1, 3), [0, 0, -1]])
    south = len(v) - 1
    j = np.arange(n_lon)
    idx = lambda i, j: 1 + i * n_lon + j % n_lon  # noqa: E731
    faces = [np.stack([np.zeros_like(j), idx(0, j), idx(0, j + 1)], 1),
             np.stack([np.full_like(j, south), idx(n_lat - 2, j + 1), idx(n_lat - 2, j)], 1)]
    for i in range(n_lat - 2):
        a, b, c, d = idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)
        faces += [np.stack([a, b, c], 1), np.stack([a, c, d], 1)]
    return v, np.concatenate(faces)


def test_vertex_normals_of_a_fine_sphere_converge_to_the_analytic_normals():
    # Angle-weighted normals are second-order accurate on this tessellation: the
    # angle to the exact normal p / |p| is below C h^2, h the longest edge. C = 0.08
    # is measured here at three resolutions; 0.1 is asserted, and halving h must
    # divide the error by about 4 (at least 3.5).
    errors = []
    for n_lon, n_lat in ((64, 32), (128, 64)):
        v, f = uv_sphere(n_lon, n_lat)
        n = compute_vertex_normals(v, f)
        angle = np.arccos(np.clip(np.sum(n * v, axis=1), -1, 1)).max()
        h = np.linalg.norm(v[f[:, 1]] - v[f[:, 0]], axis=1).max()
        assert angle <= 0.1 * h * h
        errors.append(angle)
    assert errors[0] / errors[1] >= 3.5
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1, atol=1e-12)


def test_vertex_normals_weigh_faces_by_their_angle_at_the_vertex():
    # A vertex shared by a face of angle pi/2 (normal +z) and one of angle pi/4
    # (normal +x): the mean is (pi/4, 0, pi/2) normalized, whatever the areas.
    v = np.array([[0, 0, 0], [5, 0, 0], [0, 5, 0], [0, 0, -1], [0, 1, -1.0]])
    f = np.array([[0, 1, 2], [0, 3, 4]])
    n = compute_vertex_normals(v, f)
    fn = face_normals(v, f)
    np.testing.assert_allclose(fn, [[0, 0, 1], [1, 0, 0]], atol=1e-15)
    expected = np.array([np.pi / 4, 0, np.pi / 2])
    np.testing.assert_allclose(n[0], expected / np.linalg.norm(expected), atol=1e-12)


def test_degenerate_faces_add_nothing_and_isolated_vertices_get_mitsubas_placeholder():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 2, 2], [3, 3, 3.0]])
    f = np.array([[0, 1, 2], [3, 3, 4]])
    n = compute_vertex_normals(v, f)
    np.testing.assert_allclose(n[:3], np.tile([0, 0, 1.0], (3, 1)), atol=1e-15)
    np.testing.assert_array_equal(n[3:], [[1, 0, 0], [1, 0, 0]])
    np.testing.assert_array_equal(face_normals(v, f)[1], [0, 0, 0])


def test_vertex_normals_in_blocks_on_two_threads_are_the_whole_meshs_bit_for_bit(monkeypatch):
    """compute_vertex_normals works through the faces in blocks of NORMALS_BLOCK, every
    other one on a second thread, then sums per vertex as before: each face's normal and
    angles depend on that face alone, so any blocks give the same bits as the whole mesh
    at once. Here blocks of 7 faces (uneven: the last one short), degenerate faces among
    them, against one block."""
    from whitted.tracer import meshio

    rng = np.random.default_rng(17)
    v = rng.normal(size=(300, 3))
    f = rng.integers(0, 300, size=(1000, 3))
    f[::9, 2] = f[::9, 0]   # degenerate faces
    with monkeypatch.context() as m:
        m.setattr(meshio, "NORMALS_BLOCK", 7)
        blocks = compute_vertex_normals(v, f)
    np.testing.assert_array_equal(blocks, compute_vertex_normals(v, f))
    # and both are the sums the docstring defines, face by face (np.add.at, in face order)
    fn = face_normals(v, f)
    ref = np.zeros_like(v)
    for k in range(3):
        a = v[f[:, (k + 1) % 3]] - v[f[:, k]]
        b = v[f[:, (k + 2) % 3]] - v[f[:, k]]
        a /= np.maximum(np.linalg.norm(a, axis=1, keepdims=True), 1e-300)
        b /= np.maximum(np.linalg.norm(b, axis=1, keepdims=True), 1e-300)
        angle = 2 * np.arctan2(np.linalg.norm(a - b, axis=1), np.linalg.norm(a + b, axis=1))
        np.add.at(ref, f[:, k], angle[:, None] * fn)
    ref /= np.linalg.norm(ref, axis=1, keepdims=True)
    # Components of order 1, each a sum of a few terms rounded in float64 (about 1e-15);
    # 1e-12 leaves room for a vertex whose terms nearly cancel before the normalisation.
    np.testing.assert_allclose(blocks, ref, rtol=0, atol=1e-12)


def bumpy_grid(n, seed):
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    v = np.stack([x.ravel(), y.ravel(), 0.3 * rng.random(n * n)], 1)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    quads = np.stack([a, a + 1, a + n + 1, a + n], 1)
    return v, quads


def per_corner(normals, faces):
    return normals[faces].reshape(-1, 3)


def test_a_mesh_hits_face_normal_is_mitsubas_formula_bit_for_bit_and_survives_tiny_triangles(
        jit):
    # shapes.mesh.face_normal, computed where a hit is shaded: Mitsuba's mesh's
    # normalize(cross(p1 - p0, p2 - p0)) in float32, bit for bit, for triangles of every
    # size whose cross product float32 holds; within float32's rounding of the float64
    # normal; for triangles so small that the plain formula's cross product underflows
    # (1e-22 across), still the unit normal (the plain formula on the triangle scaled
    # up by 2^70, exactly); 0 for a degenerate one.
    import drjit as dr

    from whitted.tracer.shapes import mesh

    rng = np.random.default_rng(5)
    n = 3000
    p0, p1, p2 = (rng.normal(size=(n, 3)).astype(np.float32) for _ in range(3))
    size = np.float32(10.0) ** rng.integers(-6, 6, size=(n, 1)).astype(np.float32)
    p1, p2 = p0 + (p1 - p0) * size, p0 + (p2 - p0) * size
    p1[[3, 50]] = p0[[3, 50]]                               # degenerate: two corners equal

    def v3(a):
        return jit.Array3f(*(np.ascontiguousarray(a[:, k]) for k in range(3)))

    def got_of(q0, q1, q2):
        return np.stack([c.numpy() for c in mesh.face_normal(v3(q0), v3(q1), v3(q2))], 1)

    got = got_of(p0, p1, p2)
    plain = np.stack([c.numpy() for c in dr.normalize(dr.cross(v3(p1) - v3(p0),
                                                               v3(p2) - v3(p0)))], 1)
    fine = np.ones(n, bool)
    fine[[3, 50]] = False
    np.testing.assert_array_equal(got[fine].view(np.uint32), plain[fine].view(np.uint32))
    assert not got[[3, 50]].any()
    c = np.cross((p1 - p0).astype(np.float64), (p2 - p0).astype(np.float64))[fine]
    np.testing.assert_allclose(got[fine], c / np.linalg.norm(c, axis=1, keepdims=True),
                               atol=4e-7)
    tiny = [x * np.float32(2.0**-70) for x in (p0[:8], p1[:8], p2[:8])]
    tiny_plain = np.stack([c.numpy() for c in dr.normalize(dr.cross(
        v3(tiny[1]) - v3(tiny[0]), v3(tiny[2]) - v3(tiny[0])))], 1)
    assert not np.isfinite(tiny_plain[fine[:8]]).all() or not tiny_plain[fine[:8]].any()
    np.testing.assert_array_equal(got_of(*tiny)[fine[:8]], got[:8][fine[:8]])


def test_vertex_normals_equal_mitsubas_for_an_obj_mesh(tmp_path, mi):
    v, quads = bumpy_grid(7, 1)
    text = "".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in v.tolist())
    text += "".join("f " + " ".join(str(k + 1) for k in q) + "\n" for q in quads.tolist())
    path = write(tmp_path, "grid.obj", text)
    m = load_mesh(path)
    ours = compute_vertex_normals(m.vertices, m.faces)
    params = mi.traverse(mi.load_dict({"type": "obj", "filename": str(path),
                                       "face_normals": False}))
    theirs = np.array(params["vertex_normals"]).reshape(-1, 3)
    faces = np.array(params["faces"]).reshape(-1, 3)
    assert len(faces) == len(m.faces)
    # Compared per face corner, which does not depend on how either numbers vertices.
    np.testing.assert_allclose(per_corner(ours, m.faces), per_corner(theirs, faces),
                               atol=F32_TOL)


def test_vertex_normals_equal_mitsubas_for_a_ply_mesh(tmp_path, mi):
    v, quads = bumpy_grid(9, 2)
    tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    path = write_ply(tmp_path / "grid.ply", "binary_little_endian",
                     [("vertex", [("x", "double"), ("y", "double"), ("z", "double")],
                       [tuple(p) for p in v.tolist()]),
                      ("face", FACE_PROP, [(list(t),) for t in tris.tolist()])])
    m = load_mesh(path)
    ours = compute_vertex_normals(m.vertices, m.faces)
    params = mi.traverse(mi.load_dict({"type": "ply", "filename": str(path),
                                       "face_normals": False}))
    theirs = np.array(params["vertex_normals"]).reshape(-1, 3)
    faces = np.array(params["faces"]).reshape(-1, 3)
    np.testing.assert_allclose(per_corner(ours, m.faces), per_corner(theirs, faces),
                               atol=F32_TOL)


# --------------------------------------------------------------------------- both formats alike
# The tracer and Mitsuba store meshes in float32: a value float32 cannot hold, a normal it
# cannot normalise, an index that is not an integer, or a number Python reads but Mitsuba
# does not, is refused in one line whichever format it comes in.

NXYZ = XYZ + [("nx", "float"), ("ny", "float"), ("nz", "float")]


def ply_with_vertex_values(tmp_path, fmt, props, first_row_values, name="a.ply"):
    """VERTS with extra properties ``props``: 0, 0, 1 on every vertex except the first."""
    rows = [v + (tuple(first_row_values) if i == 0 else (0.0, 0.0, 1.0)[:len(props)])
            for i, v in enumerate(VERTS)]
    return write_ply(tmp_path / name, fmt, [("vertex", XYZ + props, rows),
                                            ("face", FACE_PROP, FACES)])


#: Normals float32 cannot normalise: NaN, infinite, zero, a square that underflows to 0
#: (Mitsuba's obj plugin refuses these), a square that overflows (it makes them zero).
BAD_NORMALS = {"nan": (math.nan, 0, 1), "inf": (0, math.inf, 0), "zero": (0, 0, 0),
               "underflow": (1e-30, 0, 0), "overflow": (0, 1e30, 0)}


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
@pytest.mark.parametrize("name", list(BAD_NORMALS))
def test_ply_normals_float32_cannot_normalise_are_refused(tmp_path, fmt, name):
    normal = [("nx", "double"), ("ny", "double"), ("nz", "double")]
    path = ply_with_vertex_values(tmp_path, fmt, normal, BAD_NORMALS[name])
    msg = check_error(path, "PLY vertex 0", "normal")
    if fmt == "ascii":
        assert ":14:" in msg  # 13 header lines, then the first vertex


@pytest.mark.parametrize("name", list(BAD_NORMALS))
def test_obj_normals_float32_cannot_normalise_are_refused(tmp_path, name):
    x, y, z = BAD_NORMALS[name]
    path = write(tmp_path, "a.obj", SQUARE + f"vn {x!r} {y!r} {z!r}\nvn 0 0 1\n"
                                             "f 1//1 2//2 3//2\n")
    check_error(path, ":5:")  # the vn line


def test_an_unused_zero_normal_is_not_refused(tmp_path):
    # Mitsuba's vertex table holds only the corners the faces use; so does ours.
    m = load_mesh(write(tmp_path, "a.obj", SQUARE + "vn 0 0 0\nvn 0 0 1\nf 1//2 2//2 3//2\n"))
    np.testing.assert_array_equal(m.normals, np.tile([0.0, 0, 1], (3, 1)))


@pytest.mark.parametrize("fmt", ["ascii", "binary_big_endian"])
@pytest.mark.parametrize("value", [math.nan, math.inf, 1e39])
def test_ply_uvs_and_positions_float32_cannot_hold_are_refused(tmp_path, fmt, value):
    uv = [("u", "double"), ("v", "double")]
    check_error(ply_with_vertex_values(tmp_path, fmt, uv, (0.5, value)), "PLY vertex 0",
                "texture coordinate")
    rows = [(value, 0.0, 0.0)] + VERTS[1:]
    path = write_ply(tmp_path / "p.ply", fmt, [("vertex", [("x", "double"), ("y", "double"),
                                                           ("z", "double")], rows),
                                               ("face", FACE_PROP, FACES)])
    check_error(path, "PLY vertex 0", "position")


@pytest.mark.parametrize("line,words", [("v 1e39 0 0", ("position", "float32")),
                                        ("vt 0.5 -1e39", ("texture coordinate", "float32"))])
def test_obj_used_values_float32_cannot_hold_are_refused(tmp_path, line, words):
    text = SQUARE + "vt 0 0\n" + line + "\n" + "f 1/1 2/1 -1/-1\n"
    check_error(write(tmp_path, "a.obj", text), ":6:", *words)


def test_ply_non_integer_face_indices_are_refused_not_truncated(tmp_path):
    good = [("vertex", XYZ, VERTS), ("face", FACE_PROP, FACES)]
    text = write_ply(tmp_path / "a.ply", "ascii", good).read_text()
    (tmp_path / "b.ply").write_text(text.replace("3 0 2 3\n", "3 0 2.5 3\n"))
    check_error(tmp_path / "b.ply", ":17:", "expected an integer", "'2.5'")  # face 1
    # A float-typed index list: integral values name vertices, others are refused.
    prop = [("vertex_indices", "list", "uchar", "float")]
    for fmt in ("ascii", "binary_little_endian"):
        ok = write_ply(tmp_path / "c.ply", fmt, [("vertex", XYZ, VERTS), ("face", prop, FACES)])
        np.testing.assert_array_equal(load_mesh(ok).faces, [[0, 1, 2], [0, 2, 3], [0, 1, 4]])
        bad = write_ply(tmp_path / "d.ply", fmt, [("vertex", XYZ, VERTS),
                                                  ("face", prop, [([0, 1.5, 2],)] + FACES)])
        check_error(bad, "face 0", "non-integer vertex index 1.5")


@pytest.mark.parametrize("count", [b"\xb2", "\u00b2".encode(), "\u0665".encode(), b"5_0",
                                   b"-5", b"+5", b"1000000000000"])
def test_ply_header_element_counts_must_be_plain_decimals_the_file_can_hold(tmp_path, count):
    # A superscript two (the byte 0xb2 in Latin-1) passes str.isdigit() but not int(); an
    # Arabic-Indic five passes both; Python's int() also reads '5_0' and '+5'.
    for fmt in ("ascii", "binary_little_endian"):
        p = write_ply(tmp_path / "a.ply", fmt, [("vertex", XYZ, VERTS),
                                                ("face", FACE_PROP, FACES)])
        p.write_bytes(p.read_bytes().replace(b"element vertex 5", b"element vertex " + count))
        check_error(p, ":4:")


@pytest.mark.parametrize("number", ["\u0663", "1_0", "\uff11"])
def test_numbers_must_be_plain_ascii_decimals_in_both_formats(tmp_path, number):
    # Python's float() reads each of these (3, 10, a full-width 1); Mitsuba does not.
    check_error(write(tmp_path, "a.obj", SQUARE + f"v {number} 0 0\nf 1 2 5\n"), ":5:",
                "malformed 'v' line")
    check_error(write(tmp_path, "b.obj", SQUARE + f"f 1 2 {number}\n"), ":5:")
    p = write_ply(tmp_path / "a.ply", "ascii", [("vertex", XYZ, VERTS),
                                                ("face", FACE_PROP, FACES)])
    p.write_text(p.read_text().replace("0.5 0.5 1.0", f"0.5 {number} 1.0"), encoding="utf-8")
    check_error(p, ":15:")  # the 5th vertex
    # Names and comments may hold anything.
    ok = "o Cube_1 \u00e9t\u00e9\nusemtl Material_001\n# \u0663_\n" + SQUARE + "f 1 2 3\n"
    assert len(load_mesh(write(tmp_path, "c.obj", ok)).faces) == 1


def test_ply_ascii_values_take_their_declared_type(tmp_path):
    # 'property float x' holds a float32, as in a binary file and in Mitsuba.
    p = write_ply(tmp_path / "a.ply", "ascii", [("vertex", XYZ, [(0.1, 0.2, 0.3)] + VERTS[1:]),
                                                ("face", FACE_PROP, FACES)])
    np.testing.assert_array_equal(load_mesh(p).vertices[0], np.float32([0.1, 0.2, 0.3]))


def test_ply_ascii_data_after_the_last_element_is_refused_with_its_line(tmp_path):
    p = write_ply(tmp_path / "a.ply", "ascii", [("vertex", XYZ, VERTS),
                                                ("face", FACE_PROP, FACES)])
    p.write_text(p.read_text() + "\n7 8 9\n")
    check_error(p, ":20:", "after its last element")


def test_ply_two_elements_of_one_name_are_refused(tmp_path):
    p = write_ply(tmp_path / "a.ply", "binary_little_endian",
                  [("vertex", XYZ, VERTS), ("face", FACE_PROP, FACES), ("face", FACE_PROP, [])])
    check_error(p, "same name")


def test_mesh_files_that_are_not_regular_files_are_refused(tmp_path):
    fifo = tmp_path / "pipe.ply"
    os.mkfifo(fifo)
    check_error(fifo, "FIFO")
    check_error(Path("/dev/zero"), "device")
    (tmp_path / "dir.obj").mkdir()
    check_error(tmp_path / "dir.obj", "folder")


def test_a_mesh_file_beyond_the_memory_limit_is_refused_before_reading(tmp_path, monkeypatch):
    path = write_ply(tmp_path / "a.ply", "binary_little_endian",
                     [("vertex", XYZ, VERTS), ("face", FACE_PROP, FACES)])
    monkeypatch.setenv("WHITTED_MAX_MEMORY", "1K")
    check_error(path, "WHITTED_MAX_MEMORY")


def test_bad_mesh_files_are_one_line_exit_2_through_the_command_line(tmp_path):
    from whitted.reference.cli import main

    cases = {
        "header.ply": ("\u00b2", None),
        "normal.ply": None,
        "index.ply": None,
        "normal.obj": SQUARE + "vn 0 0 0\nf 1//1 2//1 3//1\n",
    }
    p = write_ply(tmp_path / "header.ply", "ascii", [("vertex", XYZ, VERTS),
                                                     ("face", FACE_PROP, FACES)])
    p.write_bytes(p.read_bytes().replace(b"vertex 5", "vertex \u00b2".encode()))
    ply_with_vertex_values(tmp_path, "binary_little_endian", NXYZ[3:], (math.nan, 0, 1),
                           "normal.ply")
    idx = write_ply(tmp_path / "index.ply", "ascii", [("vertex", XYZ, VERTS),
                                                      ("face", FACE_PROP, FACES)])
    idx.write_text(idx.read_text().replace("3 0 1 2\n", "3 0 1.7 2\n"))
    write(tmp_path, "normal.obj", cases["normal.obj"])
    for name in cases:
        scene = write(tmp_path, "s.toml", MESH_SCENE.format(file=tmp_path / name))
        out = tmp_path / "out.exr"
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            rc = main(["render", str(scene), "-o", str(out)])
        lines = err.getvalue().strip("\n").split("\n")
        assert rc == 2 and len(lines) == 1 and name in lines[0], (name, err.getvalue())
        assert not out.exists()


MESH_SCENE = """
[film]
width = 8
height = 6
[camera]
origin = [0, 0, 5]
target = [0, 0, 0]
fov = 40
[materials.white]
type = "diffuse"
reflectance = 0.5
[[lights]]
type = "point"
position = [0, 0, 5]
intensity = 10
[[shapes]]
type = "mesh"
file = "{file}"
material = "white"
"""


# --------------------------------------------------------------------------- the cache


@pytest.fixture
def parses(monkeypatch):
    """Counts the files :func:`load_mesh` parses (cache misses), on an empty cache."""
    from whitted.tracer import meshio

    meshio.clear_cache()
    calls = []
    real = meshio._read_mesh

    def counting(path, *a, **k):
        calls.append(Path(path).name)
        return real(path, *a, **k)

    monkeypatch.setattr(meshio, "_read_mesh", counting)
    yield calls
    meshio.clear_cache()


def test_loading_an_unchanged_file_again_reuses_the_parsed_mesh(tmp_path, parses):
    path = write(tmp_path, "a.obj", SQUARE + "f 1 2 3\n")
    first = load_mesh(path)
    again = load_mesh(tmp_path / "." / "a.obj")  # another spelling of the same file
    assert parses == ["a.obj"] and again is first
    with pytest.raises(ValueError):
        first.vertices[0, 0] = 7.0  # shared, so read-only
    # Another reading of the texture coordinates is another mesh; both are kept.
    load_mesh(path, flip_tex_coords=False)
    assert load_mesh(path) is first and load_mesh(path, flip_tex_coords=False) is not first
    assert parses == ["a.obj", "a.obj"]
    # A changed file (size, modification time) is parsed again.
    path.write_text(SQUARE + "f 1 2 3\nf 1 3 4\n")
    assert len(load_mesh(path).faces) == 2
    assert parses == ["a.obj"] * 3


def test_loading_a_scene_twice_parses_its_mesh_once(tmp_path, parses):
    from whitted.tracer.scene import load_scene

    path = write_ply(tmp_path / "m.ply", "binary_little_endian",
                     [("vertex", XYZ, VERTS), ("face", FACE_PROP, FACES)])
    scene = write(tmp_path, "s.toml", MESH_SCENE.format(file=path))
    a, b = load_scene(scene), load_scene(scene)
    assert parses == ["m.ply"]
    np.testing.assert_array_equal(a.shapes[0].vertices, b.shapes[0].vertices)


def test_the_cache_is_bounded_least_recently_used_first_out(tmp_path, parses, monkeypatch):
    from whitted.tracer import meshio

    monkeypatch.setattr(meshio, "CACHE_MAX_MESHES", 2)
    files = [write(tmp_path, f"{k}.obj", SQUARE + "f 1 2 3\n") for k in "abc"]
    for f in files + files[2:] + files[:1]:   # a b c | c (hit) | a (evicted: parsed again)
        load_mesh(f)
    assert parses == ["a.obj", "b.obj", "c.obj", "a.obj"]
    monkeypatch.setattr(meshio, "CACHE_MAX_BYTES", 10)  # no mesh fits: nothing is kept
    meshio.clear_cache()
    load_mesh(files[1])
    load_mesh(files[1])
    assert parses[-2:] == ["b.obj", "b.obj"]


def test_a_file_changed_while_it_is_read_is_not_cached(tmp_path, parses, monkeypatch):
    from whitted.tracer import meshio

    path = write(tmp_path, "a.obj", SQUARE + "f 1 2 3\n")
    counting = meshio._read_mesh

    def read_then_edit(p, *a, **k):
        mesh = counting(p, *a, **k)
        path.write_text(SQUARE + "f 1 2 3\nf 1 3 4\n")  # another writer, mid-read
        return mesh

    monkeypatch.setattr(meshio, "_read_mesh", read_then_edit)
    assert len(load_mesh(path).faces) == 1
    monkeypatch.setattr(meshio, "_read_mesh", counting)
    assert len(load_mesh(path).faces) == 2 and parses == ["a.obj", "a.obj"]


# --------------------------------------------------------------------------- fuzzing
# Any damage to a valid file (bytes changed, inserted, deleted, the file cut short, a
# hostile token put in) must give a mesh the tracer can use or a one-line MeshError, and
# nothing else: no other exception, no NaN, no index out of range.


def _seed_files() -> list[tuple[str, bytes]]:
    import tempfile

    props = NXYZ + [("u", "float"), ("v", "float")]
    rows = [v + (0.0, 0.6, 0.8, 0.1 * i, 0.2) for i, v in enumerate(VERTS)]
    polys = [([0, 1, 2, 3],), ([0, 1, 4],), ([3, 2, 4, 1, 0],)]
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for fmt in ("ascii", "binary_little_endian", "binary_big_endian"):
            for faces, fprop in ((FACES, FACE_PROP),
                                 (polys, [("vertex_index", "list", "int", "uint")])):
                p = write_ply(Path(tmp) / "s.ply", fmt, [("vertex", props, rows),
                                                         ("face", fprop, faces)])
                out.append((".ply", p.read_bytes()))
    out.append((".obj", (SQUARE + "v 0.5 0.5 1\nvt 0 0\nvt 1 0\nvt 1 1\nvn 0 0 1\n"
                         "vn 0 0.6 0.8\nf 1/1/1 2/2/1 3/3/2 4/1/2\nf -1/-1/-1 -2/-2/-2 "
                         "-3/-3/-1\n# end\n").encode()))
    out.append((".obj", (SQUARE + "f 1 2 3\nf 1 3 4\n").encode()))
    return out


SEEDS = _seed_files()
#: Numbers a reader must refuse or read exactly: non-finite, beyond float32, subnormal,
#: non-integer where an index is due, out of range, not plain ASCII decimals.
NUMBERS = [b"nan", b"inf", b"-inf", b"1e39", b"-1e39", b"1e-45", b"1e-30", b"1.5", b"-7",
           b"0", b"999999", b"4294967295", b"\xd9\xa3", b"\xb2", b"1_0", b"0x10"]
HOSTILE = NUMBERS + [b"-", b".", b"\n", b"\r", b" ", b"/", b"//", b"#", b"f 1 2 3\n",
                     b"v 0 0\n", b"end_header\n", b"element face 9\n",
                     b"property list uchar float vertex_indices\n"]
#: Binary values written over one property of a binary PLY: NaN, infinities, a float
#: index, indices out of range, in both byte orders.
WORDS = [struct.pack(f, x) for x in (math.nan, math.inf, -math.inf, 1e-45, 1.5)
         for f in ("<f", ">f")] + [struct.pack(f, x) for x in (-1, 5, 10**6)
                                    for f in ("<i", ">i")]


@st.composite
def damaged_meshes(draw):
    suffix = draw(st.sampled_from([".ply", ".obj"]))  # as many OBJ cases as PLY ones
    data = draw(st.sampled_from([d for s, d in SEEDS if s == suffix]))
    data = bytearray(data)
    body = data.find(b"end_header\n") + len(b"end_header\n") if suffix == ".ply" else 0
    binary = suffix == ".ply" and b"format binary" in data[:body]
    for _ in range(draw(st.integers(1, 3))):
        op = draw(st.sampled_from(["value", "value", "value", "byte", "insert", "delete",
                                   "cut"]))
        at = draw(st.integers(0, max(len(data) - 1, 0)))
        if op == "value" and binary:  # one property (4 bytes, aligned) of the body
            k = draw(st.integers(0, max((len(data) - body) // 4 - 1, 0)))
            w = draw(st.sampled_from(WORDS))
            data[body + 4 * k:body + 4 * k + 4] = w
        elif op == "value":  # one number of the body replaced: the structure stays
            spans = [m.span() for m in re.finditer(rb"[^ \t\r\n/]+", data) if m.start() >= body
                     and m.group() not in (b"v", b"vt", b"vn", b"f")]
            a, b = spans[draw(st.integers(0, len(spans) - 1))] if spans else (0, 0)
            data[a:b] = draw(st.sampled_from(NUMBERS))
        elif op == "byte" and data:
            data[at] = draw(st.integers(0, 255))
        elif op == "insert":
            data[at:at] = draw(st.sampled_from(HOSTILE))
        elif op == "delete":
            del data[at:at + draw(st.integers(1, 12))]
        else:
            del data[at:]
    return suffix, bytes(data)


def mesh_contract(tmp_path_factory, suffix: str, data: bytes) -> None:
    from whitted.tracer import meshio

    path = tmp_path_factory.mktemp("mesh") / ("m" + suffix)
    path.write_bytes(data)
    meshio.clear_cache()
    try:
        m = load_mesh(path)
    except MeshError as e:
        assert "\n" not in str(e) and str(path) in str(e)
        return
    f32 = np.float32
    assert m.faces.ndim == 2 and m.faces.shape[1] == 3 and len(m.faces) > 0
    assert m.faces.min() >= 0 and m.faces.max() < len(m.vertices)
    for a in (m.vertices, m.normals, m.uvs):
        if a is not None:
            with np.errstate(over="ignore"):
                assert np.isfinite(a.astype(f32)).all()
    if m.normals is not None:
        np.testing.assert_allclose(np.linalg.norm(m.normals, axis=1), 1, rtol=1e-6)


@settings(settings(derandomize=True, deadline=None, database=None,
                   suppress_health_check=[HealthCheck.too_slow,
                                          HealthCheck.function_scoped_fixture]),
          max_examples=400)
@given(damaged_meshes())
def test_a_damaged_mesh_file_loads_as_a_usable_mesh_or_fails_in_one_line(tmp_path_factory,
                                                                         case):
    mesh_contract(tmp_path_factory, *case)


@pytest.mark.slow
@settings(deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                HealthCheck.function_scoped_fixture],
          max_examples=5000)
@given(damaged_meshes())
def test_a_damaged_mesh_file_loads_as_a_usable_mesh_or_fails_in_one_line_long(
        tmp_path_factory, case):
    mesh_contract(tmp_path_factory, *case)


@pytest.mark.parametrize("with_normals", [True, False])
def test_written_ply_reads_back_here_and_in_mitsuba(tmp_path, mi, with_normals):
    # tracer.meshio.write_ply is how LuxCore gets its meshes
    # (reference/renderers/luxcore/render.py): what
    # it writes must be the mesh given, as float32, to this reader and to another one.
    from whitted.tracer.meshio import write_ply as write_mesh

    rng = np.random.default_rng(11)
    v = rng.normal(size=(40, 3))
    f = rng.integers(0, len(v), size=(70, 3))
    n = rng.normal(size=(40, 3)) if with_normals else None
    path = tmp_path / "w.ply"
    write_mesh(path, v, f, n)
    m = load_mesh(path)
    f32 = v.astype(np.float32).astype(np.float64)
    np.testing.assert_array_equal(m.vertices, f32)
    np.testing.assert_array_equal(m.faces, f)
    if with_normals:
        n32 = n.astype(np.float32).astype(np.float64)
        np.testing.assert_allclose(m.normals, n32 / np.linalg.norm(n32, axis=1, keepdims=True),
                                   atol=F32_TOL)
    else:
        assert m.normals is None
    params = mi.traverse(mi.load_dict({"type": "ply", "filename": str(path)}))
    np.testing.assert_array_equal(np.array(params["faces"]).reshape(-1, 3), f)
    np.testing.assert_array_equal(np.array(params["vertex_positions"]).reshape(-1, 3), f32)


def test_written_ply_refuses_faces_out_of_range(tmp_path):
    from whitted.tracer.meshio import write_ply as write_mesh

    with pytest.raises(ValueError, match="out of range"):
        write_mesh(tmp_path / "w.ply", np.zeros((3, 3)), [[0, 1, 3]])


def test_row_lengths_are_numpys_norm_bit_for_bit():
    """meshio.row_lengths (column by column, issue 33) gives np.linalg.norm(a, axis=1)
    to the last bit, from lengths that underflow when squared to ones that overflow."""
    rng = np.random.default_rng(3)
    for scale in (1e-200, 1e-20, 1.0, 1e20, 1e160):
        a = rng.normal(size=(20000, 3)) * scale
        a[::5] *= rng.uniform(1e-8, 1e8, size=(4000, 1))
        a[::9, 1] = 0.0
        with np.errstate(over="ignore", under="ignore"):
            np.testing.assert_array_equal(row_lengths(a), np.linalg.norm(a, axis=1))
