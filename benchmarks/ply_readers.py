"""PLY readers on PyPI against whitted's: which files each reads right, and how fast.

Each candidate is put behind the thinnest wrapper that could make it right:
whitted's checks of the header's element counts, then the candidate's
reading, then a triangle fan (v0, v_k, v_k+1) of its raw polygons where it
gives them, the index and uv names Mitsuba reads, indices that are integers
naming a vertex, lists of at least 3 corners, values finite and rounded to
float32. It then reads the cases below: valid files (every format and list
type, polygons, a 130-gon with a uchar length, normals, uvs, doubles, other
properties and elements, line endings) that must give the same vertices,
faces, normals and uvs as Mitsuba's reading, bit for bit; and broken ones
(cut short, trailing data, a non-integer or out-of-range index, bad numbers,
bad header lines) that must be refused. Each candidate runs in its own
process: a crash counts as a wrong answer. Then the 144,000-triangle binary
knot and its 5.5 MB ascii twin (as ``bench_mesh_load.py`` writes them) are
read ``--repeat`` times by each candidate that reads them, with the median,
minimum and maximum time.

Candidates that are not installed are skipped; to measure them all, in a
scratch environment beside the project's (they are not whitted's
dependencies)::

    pip install meshio==5.3.5 trimesh==5.2.0 pyvista-miniply==0.5.2 vtk==9.7.1 \\
        pyntcloud==0.3.1 point-cloud-utils==0.34.0 plyfile==1.1.5
    pip install --no-deps open3d==0.20.0 && pip install plotly dash
    python benchmarks/ply_readers.py [--only NAME ...] [--repeat 5] [-v]
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import struct
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

# --------------------------------------------------------------------------- the cases

_FMT = {"char": "b", "uchar": "B", "short": "h", "ushort": "H", "int": "i", "uint": "I",
        "float": "f", "double": "d", "int8": "b", "uint8": "B", "int16": "h",
        "uint16": "H", "int32": "i", "uint32": "I", "float32": "f", "float64": "d"}
FORMATS = {"ascii": "asc", "binary_little_endian": "le", "binary_big_endian": "be"}
XYZ = [("x", "float"), ("y", "float"), ("z", "float")]
VERTS = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, 1.0, 0.0), (0.0, 1.0, 0.0), (0.5, 0.5, 1.0)]
TRIS = [([0, 1, 2],), ([0, 2, 3],), ([0, 1, 4],)]
TRI_FACES = [t[0] for t in TRIS]
POLYS = [([0, 1, 2, 3],), ([0, 1, 4],), ([3, 2, 4, 1, 0],)]
POLY_FAN = [[0, 1, 2], [0, 2, 3], [0, 1, 4], [3, 2, 4], [3, 4, 1], [3, 1, 0]]
FP = [("vertex_indices", "list", "uchar", "int")]


def ply(fmt: str, elements) -> bytes:
    """A PLY file: elements as (name, [(prop, type) or (prop, 'list', len_t, item_t)], rows)."""
    head = ["ply", f"format {fmt} 1.0", "comment cases"]
    for name, props, rows in elements:
        head.append(f"element {name} {len(rows)}")
        head += [f"property list {p[2]} {p[3]} {p[0]}" if p[1] == "list"
                 else f"property {p[1]} {p[0]}" for p in props]
    out = ("\n".join(head + ["end_header"]) + "\n").encode()
    order = "<" if fmt == "binary_little_endian" else ">"
    for _, props, rows in elements:
        for row in rows:
            if fmt == "ascii":
                words = []
                for p, v in zip(props, row, strict=True):
                    words += [str(len(v)), *map(repr, v)] if p[1] == "list" else [repr(v)]
                out += (" ".join(words) + "\n").encode()
                continue
            for p, v in zip(props, row, strict=True):
                if p[1] == "list":
                    out += struct.pack(order + _FMT[p[2]], len(v))
                    out += struct.pack(order + _FMT[p[3]] * len(v), *v)
                else:
                    out += struct.pack(order + _FMT[p[1]], v)
    return out


def _f32(a):
    return np.asarray(a, dtype=np.float64).astype(np.float32).astype(np.float64)


def expect(v, f, n=None, uv=None) -> dict:
    """Mitsuba's reading: float32 values, faces fanned, normals as written (unnormalised)."""
    return {"vertices": _f32(v), "faces": np.asarray(f, dtype=np.int64),
            "normals": None if n is None else _f32(n), "uvs": None if uv is None else _f32(uv)}


def cases() -> list[tuple[str, bytes, dict | None]]:
    """(name, file, expected reading or None for a file to refuse)."""
    out = []
    for fmt, s in FORMATS.items():
        base = [("vertex", XYZ, VERTS)]
        out.append((f"triangles {s}", ply(fmt, base + [("face", FP, TRIS)]),
                    expect(VERTS, TRI_FACES)))
        for ct, it in (("uchar", "int"), ("uint8", "uint32"), ("ushort", "ushort"),
                       ("int", "short"), ("char", "uint"), ("uint", "int")):
            out.append((f"polygons, vertex_index {ct}/{it} {s}",
                        ply(fmt, base + [("face", [("vertex_index", "list", ct, it)], POLYS)]),
                        expect(VERTS, POLY_FAN)))
        out.append((f"polygons, vertex_indices uchar/int {s}",
                    ply(fmt, base + [("face", FP, POLYS)]), expect(VERTS, POLY_FAN)))
        out.append((f"quads only {s}",
                    ply(fmt, base + [("face", FP, [([0, 1, 2, 3],), ([1, 2, 3, 4],)])]),
                    expect(VERTS, [[0, 1, 2], [0, 2, 3], [1, 2, 3], [1, 3, 4]])))
        ring = [(float(np.cos(2 * np.pi * k / 130)), float(np.sin(2 * np.pi * k / 130)), 0.0)
                for k in range(130)]
        out.append((f"a 130-gon (uchar length > 127) {s}",
                    ply(fmt, [("vertex", XYZ, ring), ("face", FP, [(list(range(130)),)])]),
                    expect(ring, [[0, k, k + 1] for k in range(1, 129)])))
        dprops = [("x", "double"), ("y", "double"), ("z", "double"), ("nx", "float"),
                  ("ny", "float"), ("nz", "float"), ("u", "double"), ("v", "double")]
        rng = np.random.default_rng(7)
        rows = [tuple(float(x) for x in rng.normal(size=8)) for _ in VERTS]
        out.append((f"double xyz, normals, uv {s}",
                    ply(fmt, [("vertex", dprops, rows), ("face", FP, TRIS)]),
                    expect([r[:3] for r in rows], TRI_FACES, [r[3:6] for r in rows],
                           [r[6:] for r in rows])))
        for un, vn in (("s", "t"), ("texture_u", "texture_v")):
            rows2 = [v + (0.1 * i, 0.3) for i, v in enumerate(VERTS)]
            out.append((f"uvs named {un} {vn} {s}",
                        ply(fmt, [("vertex", XYZ + [(un, "float"), (vn, "float")], rows2),
                                  ("face", FP, TRIS)]),
                        expect(VERTS, TRI_FACES, None, [r[3:] for r in rows2])))
        other = ("material", [("ids", "list", "int", "uchar"), ("shine", "float")],
                 [([1, 2], 0.5), ([], 1.0), ([3], 2.0)])
        vprops = [("confidence", "double"), *XYZ, ("red", "uchar"),
                  ("tags", "list", "uchar", "short")]
        vrows = [(0.5, *v, 200, [1, 2, 3][:i % 4]) for i, v in enumerate(VERTS)]
        out.append((f"other properties and elements {s}",
                    ply(fmt, [other, ("vertex", vprops, vrows),
                              ("edge", [("a", "int"), ("b", "int")], [(0, 1), (1, 2)]),
                              ("face", [("flags", "ushort"), *FP, ("quality", "float")],
                               [(7, t[0], 0.5) for t in TRIS]),
                              ("material_2", *other[1:])]),
                    expect(VERTS, TRI_FACES)))
        out.append((f"two lists a face (indices, texcoord) {s}",
                    ply(fmt, base + [("face", [*FP, ("texcoord", "list", "uchar", "float")],
                                      [(p[0], [0.5] * 2 * len(p[0])) for p in POLYS])]),
                    expect(VERTS, POLY_FAN)))
        out.append((f"float-typed index list {s}",
                    ply(fmt, base + [("face", [("vertex_indices", "list", "uchar", "float")],
                                      TRIS)]),
                    expect(VERTS, TRI_FACES)))
        out.append((f"'end_header' inside a comment {s}",
                    ply(fmt, base + [("face", FP, TRIS)]).replace(
                        b"comment cases", b"comment see end_header below"),
                    expect(VERTS, TRI_FACES)))
    good = ply("ascii", [("vertex", XYZ, VERTS), ("face", FP, TRIS)])
    out.append(("ascii float 0.1 read as float32 0.1",
                ply("ascii", [("vertex", XYZ, [(0.1, 0.2, 0.3)] + VERTS[1:]), ("face", FP, TRIS)]),
                expect([(0.1, 0.2, 0.3)] + VERTS[1:], TRI_FACES)))
    out.append(("ascii blank lines between records",
                good.replace(b"\n3 0 1 2", b"\n\n  \n3 0 1 2"), expect(VERTS, TRI_FACES)))
    out.append(("ascii CRLF lines", good.replace(b"\n", b"\r\n"), expect(VERTS, TRI_FACES)))
    out.append(("ascii CR lines", good.replace(b"\n", b"\r"), expect(VERTS, TRI_FACES)))
    binle = ply("binary_little_endian", [("vertex", XYZ, VERTS), ("face", FP, TRIS)])
    head, body = binle.split(b"end_header\n")
    out.append(("binary, CRLF header", head.replace(b"\n", b"\r\n") + b"end_header\r\n" + body,
                expect(VERTS, TRI_FACES)))

    # Files to refuse.
    out += [("binary cut short (5 bytes)", binle[:-5], None),
            ("binary cut inside the vertices", binle[:len(head) + 41], None),
            ("binary with trailing bytes", binle + b"\x01\x02", None)]
    polys = ply("binary_little_endian", [("vertex", XYZ, VERTS), ("face", FP, POLYS)])
    out.append(("binary polygons cut short", polys[:-3], None))
    for name, text in (
            ("ascii without its last face", good[:good.rindex(b"3 0 1 4")]),
            ("ascii cut inside a line", good[:-4]),
            ("ascii cut inside the vertices", good[:good.index(b"0.5 0.5 1.0")]),
            ("ascii face index 1.7", good.replace(b"3 0 1 2\n", b"3 0 1.7 2\n")),
            ("ascii word 'oops' for a number", good.replace(b"0.5 0.5 1.0", b"0.5 oops 1.0")),
            ("ascii extra number on a line", good.replace(b"3 0 1 2\n", b"3 0 1 2 7\n")),
            ("ascii vertex line one number short", good.replace(b"0.5 0.5 1.0", b"0.5 0.5")),
            ("ascii data after the last element", good + b"7 8 9\n"),
            ("ascii list length 2.5", good.replace(b"3 0 1 2\n", b"2.5 0 1 2\n")),
            ("ascii index beyond int's range", good.replace(b"3 0 1 2\n",
                                                            b"3 0 1 4294967296\n"))):
        out.append((name, text, None))
    for fmt in ("ascii", "binary_little_endian"):
        s = FORMATS[fmt]
        b = ply(fmt, [("vertex", XYZ, VERTS), ("face", FP, TRIS)])
        out += [
            (f"index 9 of 5 vertices {s}",
             ply(fmt, [("vertex", XYZ, VERTS), ("face", FP, [([0, 1, 9],)])]), None),
            (f"index -1 {s}", ply(fmt, [("vertex", XYZ, VERTS), ("face", FP, [([0, 1, -1],)])]),
             None),
            (f"unknown type 'floot' {s}", b.replace(b"property float y", b"property floot y"),
             None),
            (f"format binary_middle {s}", b.replace(f"format {fmt}".encode(),
                                                    b"format binary_middle"), None),
            (f"format version 2.0 {s}", b.replace(b" 1.0\n", b" 2.0\n", 1), None),
            (f"element count 5_0 {s}", b.replace(b"element vertex 5", b"element vertex 5_0"),
             None),
            (f"element count -5 {s}", b.replace(b"element vertex 5", b"element vertex -5"), None),
            (f"no end_header {s}", b.replace(b"end_header", b"end_headr"), None),
            (f"property before any element {s}",
             b.replace(b"comment cases\n", b"comment cases\nproperty float w\n"), None),
            (f"unknown header keyword {s}",
             b.replace(b"comment cases\n", b"comment cases\nfoo bar\n"), None),
            (f"a face of 2 vertices {s}",
             ply(fmt, [("vertex", XYZ, VERTS), ("face", FP, [([0, 1],)] + TRIS)]), None),
            (f"a list length of type float {s}",
             b.replace(b"property list uchar int", b"property list float int"), None),
            (f"no face element {s}", ply(fmt, [("vertex", XYZ, VERTS)]), None)]
    return out


# --------------------------------------------------------------------------- the wrapper


class Refused(Exception):
    """The wrapper refuses what the candidate returned."""


def precheck(path) -> None:
    """whitted's header checks a wrapper adds: element counts plain decimals the file can hold."""
    data = Path(path).read_bytes()
    end = data.find(b"end_header")
    if end < 0:
        raise Refused("no end_header")
    for line in data[:end].splitlines():
        tok = line.split()
        if tok[:1] == [b"element"] and len(tok) == 3:
            if not re.fullmatch(rb"[0-9]+", tok[2]) or int(tok[2]) > len(data):
                raise Refused("bad element count")


def mesh(cols: dict, counts, flat) -> dict:
    """The mesh of vertex columns (name -> values) and raw polygons (lengths, flat corners)."""
    from whitted.tracer.meshio import _fan

    for c in "xyz":
        if c not in cols:
            raise Refused(f"no {c}")

    def block(names):
        if all(c in cols for c in names):
            return np.stack([np.asarray(cols[c], np.float64) for c in names], 1)
        return None

    v, n = block("xyz"), block(("nx", "ny", "nz"))
    uv = next((b for b in map(block, (("u", "v"), ("texture_u", "texture_v"), ("s", "t")))
               if b is not None), None)
    for a in (v, n, uv):
        with np.errstate(over="ignore"):
            if a is not None and not np.isfinite(a.astype(np.float32)).all():
                raise Refused("a value float32 cannot hold")
    counts, flat = np.asarray(counts, dtype=np.int64), np.asarray(flat)
    if len(counts) == 0 or counts.min() < 3 or len(flat) != counts.sum():
        raise Refused("no faces, a face of fewer than 3 corners, or lengths that do not add up")
    if flat.dtype.kind == "f" and (~np.isfinite(flat) | (flat != np.floor(flat))).any():
        raise Refused("a non-integer index")
    if ((flat < 0) | (flat >= len(v))).any():
        raise Refused("an index out of range")
    return {"vertices": _f32(v), "faces": _fan(flat.astype(np.int64), counts),
            "normals": None if n is None else _f32(n), "uvs": None if uv is None else _f32(uv)}


def _lists(lists) -> tuple[list[int], np.ndarray]:
    lists = [np.asarray(a).reshape(-1) for a in lists]
    return [len(a) for a in lists], (np.concatenate(lists) if lists else np.zeros(0))


# --------------------------------------------------------------------------- candidates
# Each returns mesh(...) of what the candidate read, or raises.


def read_whitted(path):
    from whitted.tracer import meshio

    meshio.clear_cache()
    m = meshio.load_mesh(path)
    return {"vertices": m.vertices, "faces": m.faces, "normals": m.normals, "uvs": m.uvs,
            "normalized": True}


def read_plyfile(path):
    from plyfile import PlyData, PlyElementParseError

    precheck(path)
    try:  # triangles in one piece, as whitted's plyfile-based reader did
        p = PlyData.read(str(path), known_list_len={
            "face": {"vertex_indices": 3, "vertex_index": 3}})
    except PlyElementParseError:
        p = PlyData.read(str(path))
    vert, face = p["vertex"].data, p["face"].data
    col = face[next(k for k in ("vertex_indices", "vertex_index") if k in face.dtype.names)]
    cols = {k: vert[k] for k in vert.dtype.names}
    if col.dtype != object:  # the one-piece read: an (F, 3) array
        return mesh(cols, [3] * len(col), np.asarray(col).reshape(-1))
    return mesh(cols, *_lists(list(col)))


def read_meshio(path):
    import meshio

    precheck(path)
    m = meshio.ply.read(str(path))
    cols = {"x": m.points[:, 0], "y": m.points[:, 1]}
    if m.points.shape[1] > 2:
        cols["z"] = m.points[:, 2]
    cols.update(m.point_data)
    counts, flat = [], []
    for block in m.cells:  # runs of one polygon size, in the file's order
        d = np.asarray(block.data)
        counts += [d.shape[1]] * len(d)
        flat.append(d.reshape(-1))
    return mesh(cols, counts, np.concatenate(flat) if flat else np.zeros(0))


def read_trimesh_raw(path):
    """trimesh's own PLY parser (header and body), before any processing."""
    from trimesh.exchange import ply as tp

    precheck(path)
    with open(path, "rb") as fh:
        elements, is_ascii, _ = tp._parse_header(fh)
        (tp._ply_ascii if is_ascii else tp._ply_binary)(elements, fh)
    vdata, fdata = elements["vertex"]["data"], elements["face"]["data"]
    cols = ({k: np.asarray(v).reshape(-1) for k, v in vdata.items()}
            if isinstance(vdata, dict) else {k: vdata[k] for k in vdata.dtype.names})
    if isinstance(fdata, dict):
        col = fdata[next(k for k in ("vertex_indices", "vertex_index") if k in fdata)]
        if isinstance(col, np.ndarray) and col.dtype != object:
            return mesh(cols, [col.shape[1]] * len(col), col.reshape(-1))
        return mesh(cols, *_lists(list(col)))
    col = fdata[next(k for k in ("vertex_indices", "vertex_index") if k in fdata.dtype.names)]
    col = col["f1"].reshape(len(col), -1)
    return mesh(cols, [col.shape[1]] * len(col), col.reshape(-1))


def read_trimesh(path):
    import trimesh

    precheck(path)
    m = trimesh.load(str(path), process=False, maintain_order=True, force="mesh")
    v, f = np.asarray(m.vertices), np.asarray(m.faces)
    return mesh({"x": v[:, 0], "y": v[:, 1], "z": v[:, 2]}, [3] * len(f), f.reshape(-1))


def read_miniply(path):
    import pyvista_miniply

    precheck(path)
    v, idx, n, uv, _ = pyvista_miniply.read(str(path))
    cols = {"x": v[:, 0], "y": v[:, 1], "z": v[:, 2]}
    if n is not None and n.size:
        cols.update(nx=n[:, 0], ny=n[:, 1], nz=n[:, 2])
    if uv is not None and uv.size:
        cols.update(u=uv[:, 0], v=uv[:, 1])
    idx = np.asarray(idx).reshape(-1, 3)
    return mesh(cols, [3] * len(idx), idx.reshape(-1))


def read_vtk(path):
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkCommonCore import vtkObject
    from vtkmodules.vtkIOPLY import vtkPLYReader

    precheck(path)
    vtkObject.GlobalWarningDisplayOff()
    r = vtkPLYReader()
    r.SetFileName(str(path))
    r.Update()
    if r.GetErrorCode():
        raise Refused(f"VTK error code {r.GetErrorCode()}")
    pd = r.GetOutput()
    if pd.GetPoints() is None:
        raise Refused("no points")
    v = vtk_to_numpy(pd.GetPoints().GetData())
    cols = {"x": v[:, 0], "y": v[:, 1], "z": v[:, 2]}
    if pd.GetPointData().GetNormals() is not None:
        n = vtk_to_numpy(pd.GetPointData().GetNormals())
        cols.update(nx=n[:, 0], ny=n[:, 1], nz=n[:, 2])
    if pd.GetPointData().GetTCoords() is not None:
        t = vtk_to_numpy(pd.GetPointData().GetTCoords())
        cols.update(u=t[:, 0], v=t[:, 1])
    polys = pd.GetPolys()  # raw polygons, fanned by the wrapper
    return mesh(cols, np.diff(vtk_to_numpy(polys.GetOffsetsArray())),
                vtk_to_numpy(polys.GetConnectivityArray()))


def read_open3d(path):
    import open3d

    precheck(path)
    m = open3d.io.read_triangle_mesh(str(path), enable_post_processing=False)
    v, f = np.asarray(m.vertices), np.asarray(m.triangles)
    if len(v) == 0:
        raise Refused("an empty mesh")
    cols = {"x": v[:, 0], "y": v[:, 1], "z": v[:, 2]}
    if m.has_vertex_normals():
        n = np.asarray(m.vertex_normals)
        cols.update(nx=n[:, 0], ny=n[:, 1], nz=n[:, 2])
    return mesh(cols, [3] * len(f), f.reshape(-1))


def read_pyntcloud(path):
    from pyntcloud.io.ply import read_ply

    precheck(path)
    d = read_ply(str(path))
    if "mesh" not in d:
        raise Refused("no faces")
    f = d["mesh"][["v1", "v2", "v3"]].to_numpy()
    return mesh({c: d["points"][c].to_numpy() for c in d["points"].columns}, [3] * len(f),
                f.reshape(-1))


def read_pcu(path):
    import point_cloud_utils as pcu

    precheck(path)
    m = pcu.load_triangle_mesh(str(path))
    v, f = np.asarray(m.vertex_data.positions), np.asarray(m.face_data.vertex_ids)
    if v.ndim != 2 or len(v) == 0:
        raise Refused("an empty mesh")
    cols = {"x": v[:, 0], "y": v[:, 1], "z": v[:, 2]}
    for names, a in ((("nx", "ny", "nz"), m.vertex_data.normals),
                     (("u", "v"), m.vertex_data.texcoords)):
        if a is not None and np.ndim(a) == 2 and len(a):
            cols.update({c: a[:, k] for k, c in enumerate(names)})
    return mesh(cols, [f.shape[1]] * len(f) if f.ndim == 2 else [], f.reshape(-1))


#: name -> (distribution whose metadata gives the licence, module to import, reader)
CANDIDATES = {
    "whitted": ("whitted", "tracer", read_whitted),
    "plyfile": ("plyfile", "plyfile", read_plyfile),
    "meshio": ("meshio", "meshio", read_meshio),
    "trimesh (parser)": ("trimesh", "trimesh", read_trimesh_raw),
    "trimesh.load": ("trimesh", "trimesh", read_trimesh),
    "pyvista-miniply": ("pyvista-miniply", "pyvista_miniply", read_miniply),
    "vtk": ("vtk", "vtkmodules", read_vtk),
    "open3d": ("open3d", "open3d", read_open3d),
    "pyntcloud": ("pyntcloud", "pyntcloud", read_pyntcloud),
    "point-cloud-utils": ("point-cloud-utils", "point_cloud_utils", read_pcu),
}


# --------------------------------------------------------------------------- running


def differs(got: dict, exp: dict) -> str | None:
    if got.get("normalized") and exp["normals"] is not None:
        from whitted.tracer.meshio import _normalized

        exp = dict(exp, normals=_normalized(exp["normals"]))
    for k in ("vertices", "faces", "normals", "uvs"):
        a, b = got[k], exp[k]
        if (a is None) != (b is None):
            return f"{k} {'missing' if a is None else 'where the file has none'}"
        if a is None:
            continue
        if a.shape != b.shape:
            return f"{k} of shape {a.shape}, expected {b.shape}"
        if not np.array_equal(a, b):
            i = tuple(int(x) for x in np.argwhere(a != b)[0])
            return f"{k}{list(i)} = {a[i]:.9g}, expected {b[i]:.9g}"
    return None


def child(name: str, folder: str, start: int, n_cases: int, repeat: int) -> None:
    """Runs in its own process: prints one JSON line per case, then the timings."""
    read = CANDIDATES[name][2]
    expected = [c[2] for c in cases()]
    for i in range(start, n_cases):
        print(json.dumps(["start", i]), flush=True)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                got, err = read(Path(folder) / f"case{i}.ply"), None
        except Exception as e:  # noqa: BLE001 - any refusal counts as one
            got, err = None, f"{type(e).__name__}: {str(e).splitlines()[0][:70] if str(e) else ''}"
        exp = expected[i]
        if exp is None:
            res = ("ok", "refused") if err else ("wrong", f"read {len(got['faces'])} triangles")
        elif err:
            res = ("wrong", err)
        else:
            d = differs(got, exp)
            res = ("ok", "") if d is None else ("wrong", d)
        print(json.dumps(["case", i, *res]), flush=True)
    ref = {}
    for f in ("knot.ply", "knot_ascii.ply"):
        path = Path(folder) / f
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                got = read(path)
                ts = []
                for _ in range(repeat):
                    t0 = time.perf_counter()
                    read(path)
                    ts.append(time.perf_counter() - t0)
            ref = read_whitted(path)
            same = all(np.array_equal(got[k], ref[k]) for k in ("vertices", "faces"))
            print(json.dumps(["time", f, ts, same]), flush=True)
        except Exception as e:  # noqa: BLE001
            print(json.dumps(["time", f, None, f"{type(e).__name__}"]), flush=True)


def licence(dist: str) -> str:
    from importlib.metadata import metadata

    m = metadata(dist)
    text = m.get("License-Expression") or next(
        (c.split(" :: ")[-1] for c in m.get_all("Classifier") or [] if c.startswith("License")),
        None) or (m.get("License") or "?").splitlines()[0]
    return text[:60]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--only", nargs="*", help="candidates to run (default: every installed one)")
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("-v", "--verbose", action="store_true", help="also list the right answers")
    p.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    all_cases = cases()
    if args.child:
        child(args.child[0], args.child[1], int(args.child[2]), len(all_cases), args.repeat)
        return 0
    import importlib.util

    import bench_mesh_load

    names = [n for n in (args.only or CANDIDATES)
             if importlib.util.find_spec(CANDIDATES[n][1]) is not None]
    print(f"{len(all_cases)} cases ({sum(c[2] is not None for c in all_cases)} to read, "
          f"{sum(c[2] is None for c in all_cases)} to refuse); times: median [min-max] of "
          f"{args.repeat} reads (a shared machine: compare within one run)")
    summary = []
    with tempfile.TemporaryDirectory() as folder:
        for i, (_, data, _) in enumerate(all_cases):
            (Path(folder) / f"case{i}.ply").write_bytes(data)
        for f in bench_mesh_load.write_files(Path(folder), 1200, 60)[:2]:
            print(f"  {f.name}: {f.stat().st_size / 1e6:.1f} MB")
        for name in names:
            results, times, start = {}, {}, 0
            while start <= len(all_cases):
                proc = subprocess.run([sys.executable, __file__, "--child", name, folder,
                                       str(start), "--repeat", str(args.repeat)],
                                      capture_output=True, text=True, timeout=1800)
                current = start
                for line in proc.stdout.splitlines():
                    try:
                        msg = json.loads(line)
                    except ValueError:
                        continue
                    if msg[0] == "start":
                        current = msg[1]
                    elif msg[0] == "case":
                        results[msg[1]] = (msg[2], msg[3])
                    elif msg[0] == "time":
                        times[msg[1]] = (msg[2], msg[3])
                if proc.returncode == 0:
                    break
                if current not in results:  # the candidate took the process down
                    results[current] = ("wrong", f"crashed the interpreter (signal "
                                                 f"{-proc.returncode})" if proc.returncode < 0
                                        else f"exit {proc.returncode}")
                start = current + 1
            wrong = sorted(i for i, r in results.items() if r[0] != "ok")
            print(f"\n{name} ({licence(CANDIDATES[name][0])}): "
                  f"{len(all_cases) - len(wrong)}/{len(all_cases)} right")
            for i in sorted(results) if args.verbose else wrong:
                print(f"  {'ok   ' if results[i][0] == 'ok' else 'WRONG'} "
                      f"{all_cases[i][0]:44s} {results[i][1]}")
            cells = []
            for f in ("knot.ply", "knot_ascii.ply"):
                ts, same = times.get(f, (None, "not reached"))
                cells.append(f"{f} " + (f"{statistics.median(ts) * 1e3:8.1f} ms "
                                        f"[{min(ts) * 1e3:.1f}-{max(ts) * 1e3:.1f}]"
                                        + ("" if same is True else " (not whitted's arrays)")
                                        if ts else f"failed ({same})"))
            print("  " + "; ".join(cells))
            summary.append((name, len(wrong)))
    print("\nwrong answers: " + ", ".join(f"{n} {w}" for n, w in summary))
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    sys.exit(main())
