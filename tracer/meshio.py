"""Triangle meshes from Wavefront OBJ and Stanford PLY files, and their vertex normals.

Both readers are written here (no third-party mesh library) and follow what
Mitsuba 3.9.1's ``obj`` and ``ply`` plugins make of the same file, so that a
mesh means the same surface to the tracer and to the reference:

* OBJ indexes positions, texture coordinates and normals separately. A vertex
  of the result is one distinct (position, uv, normal) index triple, numbered
  in order of first use, which is how Mitsuba's ``obj`` plugin builds its
  vertex table (a hash map from the triple to a new vertex id). A position
  used with two different normals therefore becomes two vertices, and the
  vertex normals computed later for a mesh without normals agree with
  Mitsuba's, which are computed over the same vertex table.
* Polygons are split into a triangle fan (v0, v_k, v_k+1), the order
  Mitsuba's ``obj`` plugin uses.
* Texture coordinates: Mitsuba flips v (v -> 1 - v) for OBJ files by default
  (``flip_tex_coords = true``, for consistency with Mitsuba 0.x and 1) and not
  for PLY files; :func:`load_mesh` does the same unless told otherwise.
* Normals read from a file are normalised, as Mitsuba does.
* Vertex normals of a mesh without them are angle-weighted averages of the
  face normals (:func:`compute_vertex_normals`), Mitsuba's
  ``Mesh::recompute_vertex_normals``.

Every problem with a file is a :class:`MeshError` whose one-line message names
the file and, for a bad line of an OBJ file, its line number.

References: the OBJ format is Wavefront's "Object Files (.obj)" appendix of
the Advanced Visualizer manual; the PLY format is Greg Turk's "The PLY Polygon
File Format" (1994), with the type names of rply/Mitsuba (int8, uint8, ...,
float32, float64) accepted besides char, uchar, short, ushort, int, uint,
float and double.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tracer.errors import UserError

__all__ = ["MeshData", "MeshError", "compute_vertex_normals", "face_normals", "load_mesh"]


class MeshError(UserError):
    """A mesh file that cannot be read; the message names the file and the problem."""

    def __init__(self, path: str | Path, message: str, line: int | None = None):
        self.path, self.line = str(path), line
        where = f"{path}:{line}: " if line is not None else f"{path}: "
        super().__init__(where + message)


@dataclass(frozen=True, eq=False)
class MeshData:
    """A triangle mesh as read from a file (object space, Mitsuba's vertex order).

    Attributes
    ----------
    vertices : (V, 3) float64 positions.
    faces : (F, 3) int64 vertex indices of counter-clockwise triangles.
    normals : (V, 3) float64 unit vertex normals from the file, or None.
    uvs : (V, 2) float64 texture coordinates, or None.
    """
    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray | None = None
    uvs: np.ndarray | None = None


def load_mesh(path: str | Path, *, flip_tex_coords: bool | None = None) -> MeshData:
    """Read an OBJ or PLY file (chosen by its contents, then by its suffix).

    Parameters
    ----------
    path : the file.
    flip_tex_coords : replace v by 1 - v. None (the default) does what Mitsuba's
        plugin for the format does by default: flip for OBJ, keep for PLY.

    Raises
    ------
    MeshError
        When the file is missing, of an unknown format, malformed, refers to a
        vertex it does not have, or has no faces.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise MeshError(path, "no such mesh file") from None
    except OSError as e:
        raise MeshError(path, f"cannot read the mesh file ({e.strerror or e})") from None
    if data.startswith(b"ply") and data[3:4] in (b"\n", b"\r", b" ", b"\t"):
        mesh = _read_ply(path, data, bool(flip_tex_coords))
    elif path.suffix.lower() == ".obj":
        mesh = _read_obj(path, data, True if flip_tex_coords is None else flip_tex_coords)
    elif path.suffix.lower() == ".ply":
        raise MeshError(path, "not a PLY file (it does not start with 'ply')")
    else:
        raise MeshError(path, f"unknown mesh format {path.suffix!r} (expected .obj or .ply)")
    if len(mesh.faces) == 0:
        raise MeshError(path, "the mesh has no faces")
    return mesh


# ---------------------------------------------------------------------------
# Normals
# ---------------------------------------------------------------------------


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F, 3) unit normals normalize((p1 - p0) x (p2 - p0)) of counter-clockwise triangles.

    The right-hand rule orients the normal towards the side from which the
    corners appear counter-clockwise (Mitsuba's convention). A degenerate
    (zero-area) face gets the zero vector.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0)


def compute_vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3) unit vertex normals: face normals weighted by the face's angle at the vertex.

    This is Mitsuba 3's ``Mesh::recompute_vertex_normals``, which follows
    Thuermer and Wuethrich, "Computing Vertex Normals from Polygonal Facets",
    Journal of Graphics Tools 3(1), 1998: ``n_v = normalize(sum_f alpha_f(v) n_f)``
    with ``n_f`` the unit face normal and ``alpha_f(v)`` the interior angle of
    face f at v. Unlike area weighting, the result does not change when a
    polygon is split differently into triangles. As in Mitsuba, degenerate
    faces contribute nothing and a vertex whose sum vanishes gets (1, 0, 0).

    The angle between unit vectors a and b is computed as
    ``2 atan2(|a - b|, |a + b|)``, which is exact where ``acos(a . b)`` loses
    digits near 0 and pi (Kahan, "How Futile are Mindless Assessments of
    Roundoff in Floating-Point Computation?", 2006, section 12).
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    p = [v[f[:, k]] for k in range(3)]
    n = np.cross(p[1] - p[0], p[2] - p[0])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    valid = length[:, 0] > 0
    n = np.divide(n, length, out=np.zeros_like(n), where=length > 0)
    out = np.zeros_like(v)
    for k in range(3):
        a = _unit(p[(k + 1) % 3] - p[k])
        b = _unit(p[(k + 2) % 3] - p[k])
        angle = 2 * np.arctan2(np.linalg.norm(a - b, axis=1), np.linalg.norm(a + b, axis=1))
        w = np.where(valid, angle, 0.0)[:, None] * n
        for c in range(3):
            out[:, c] += np.bincount(f[:, k], weights=w[:, c], minlength=len(v))
    length = np.linalg.norm(out, axis=1, keepdims=True)
    out = np.divide(out, length, out=np.zeros_like(out), where=length > 0)
    out[length[:, 0] == 0] = (1.0, 0.0, 0.0)  # Mitsuba's placeholder for an isolated vertex
    return out


def _unit(a: np.ndarray) -> np.ndarray:
    length = np.linalg.norm(a, axis=1, keepdims=True)
    return np.divide(a, length, out=np.zeros_like(a), where=length > 0)


def _normalized(n: np.ndarray) -> np.ndarray:
    """Unit normals, as Mitsuba stores the normals it reads; zero vectors stay zero."""
    return _unit(np.asarray(n, dtype=np.float64))


def _fan(polygons: list[list[int]] | np.ndarray, counts: np.ndarray) -> np.ndarray:
    """(T, 3) triangles (v0, v_k, v_k+1) of polygons given as a flat corner list and counts.

    ``polygons`` is the flat array of corner indices, ``counts`` the number of
    corners of each polygon (all >= 3); a k-gon gives k - 2 triangles.
    """
    corners = np.asarray(polygons, dtype=np.int64)
    counts = np.asarray(counts, dtype=np.int64)
    if len(counts) and np.all(counts == 3):
        return corners.reshape(-1, 3)
    starts = np.cumsum(counts) - counts
    ntri = counts - 2
    # For triangle j of polygon i: corners start_i, start_i + j + 1, start_i + j + 2.
    poly = np.repeat(np.arange(len(counts)), ntri)
    j = np.arange(int(ntri.sum())) - np.repeat(np.cumsum(ntri) - ntri, ntri)
    s = starts[poly]
    return np.stack([corners[s], corners[s + j + 1], corners[s + j + 2]], axis=1)


# ---------------------------------------------------------------------------
# OBJ
# ---------------------------------------------------------------------------


def _read_obj(path: Path, data: bytes, flip: bool) -> MeshData:
    """Parse an OBJ file: ``v``, ``vt``, ``vn`` and ``f`` lines; other statements are ignored."""
    pos: list[list[float]] = []
    tex: list[list[float]] = []
    nrm: list[list[float]] = []
    # Per face corner: the (position, uv, normal) indices, 0-based, -1 where absent.
    cv: list[int] = []
    ct: list[int] = []
    cn: list[int] = []
    counts: list[int] = []

    text = data.decode("utf-8", errors="replace")
    for lineno, raw in enumerate(text.splitlines(), start=1):
        parts = raw.split("#", 1)[0].split()  # '#' starts a comment, also after data
        if not parts:
            continue
        kind = parts[0]
        try:
            if kind == "v":
                # x y z [w] or x y z r g b (vertex colours): the position is the first three.
                if len(parts) < 4:
                    raise ValueError("expected 'v x y z'")
                pos.append(_finite(parts[1:4]))
            elif kind == "vt":
                if len(parts) < 2:
                    raise ValueError("expected 'vt u [v [w]]'")
                tex.append(_finite((parts + ["0"])[1:3]))
            elif kind == "vn":
                if len(parts) < 4:
                    raise ValueError("expected 'vn x y z'")
                nrm.append(_finite(parts[1:4]))
            elif kind == "f":
                if len(parts) < 4:
                    raise ValueError("a face needs at least 3 vertices")
                np_, nt, nn = len(pos), len(tex), len(nrm)
                for corner in parts[1:]:
                    fields = corner.split("/")
                    if len(fields) > 3 or fields[0] == "":
                        raise ValueError(f"bad face vertex {corner!r} (expected v, v/vt, "
                                         "v//vn or v/vt/vn)")
                    cv.append(_obj_index(fields[0], np_, "vertex"))
                    ct.append(_obj_index(fields[1], nt, "texture coordinate")
                              if len(fields) > 1 and fields[1] else -1)
                    cn.append(_obj_index(fields[2], nn, "normal")
                              if len(fields) > 2 and fields[2] else -1)
                counts.append(len(parts) - 1)
            # o, g, s, usemtl, mtllib, l, p, comments, ...: not geometry we render.
        except ValueError as e:
            msg = str(e)
            if msg.startswith("refers to"):
                raise MeshError(path, f"bad index: face {msg}", lineno) from None
            if msg.startswith("could not convert") or msg.startswith("invalid literal"):
                msg = "expected numbers"
            raise MeshError(path, f"malformed '{kind}' line ({msg}): {raw.strip()[:60]!r}",
                            lineno) from None

    if not counts:
        raise MeshError(path, "the mesh has no faces")
    cv_a, ct_a, cn_a = (np.asarray(a, dtype=np.int64) for a in (cv, ct, cn))

    # One vertex per distinct index triple, numbered by first use (Mitsuba's vertex map).
    keys = np.stack([cv_a, ct_a, cn_a], axis=1)
    uniq, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    uniq = uniq[order]
    corner_vertex = rank[inverse.reshape(-1)]

    vertices = np.asarray(pos, dtype=np.float64).reshape(-1, 3)[uniq[:, 0]]
    uvs = normals = None
    if tex and (uniq[:, 1] >= 0).any():
        # Corners without a uv get (0, 0) (Mitsuba leaves them undefined).
        t = np.asarray(tex, dtype=np.float64).reshape(-1, 2)
        if flip:
            t[:, 1] = 1.0 - t[:, 1]
        uvs = np.where((uniq[:, 1] >= 0)[:, None], t[np.maximum(uniq[:, 1], 0)], 0.0)
    if nrm and (uniq[:, 2] >= 0).all():
        # Only when every corner has one; otherwise all are computed from the faces.
        normals = _normalized(np.asarray(nrm, dtype=np.float64)[uniq[:, 2]])
    faces = _fan(corner_vertex, np.asarray(counts))
    return MeshData(vertices, faces, normals, uvs)


def _finite(words: list[str]) -> list[float]:
    """The numbers of an OBJ line; NaN and infinity are refused, as Mitsuba refuses them."""
    values = [float(w) for w in words]
    if not all(math.isfinite(x) for x in values):
        raise ValueError("numbers must be finite")
    return values


def _obj_index(token: str, count: int, what: str) -> int:
    """0-based index of an OBJ reference: 1..n count from the first, -1..-n back from the last.

    ``count`` is the number of elements of the kind read so far: references
    must be to elements defined earlier in the file (relative ones by
    definition; absolute ones as Mitsuba's ``obj`` plugin requires).
    """
    k = int(token)
    i = k - 1 if k > 0 else count + k
    if k == 0 or not 0 <= i < count:
        raise ValueError(f"refers to {what} {k} but {count} {what}s are defined before it")
    return i


# ---------------------------------------------------------------------------
# PLY
# ---------------------------------------------------------------------------

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "long": "i8", "int64": "i8", "ulong": "u8", "uint64": "u8",
    "half": "f2", "float16": "f2",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}


@dataclass
class _Prop:
    name: str
    dtype: str              # numpy type code of the value (of the items, for a list)
    count_dtype: str | None = None  # numpy type code of a list's length; None: a scalar


@dataclass
class _Element:
    name: str
    count: int
    props: list[_Prop]


def _parse_ply_header(path: Path, data: bytes) -> tuple[str, list[_Element], int]:
    """(format, elements, offset of the body) of a PLY file."""
    end = data.find(b"end_header")
    if end < 0:
        raise MeshError(path, "PLY header has no 'end_header'")
    nl = data.find(b"\n", end)
    body = len(data) if nl < 0 else nl + 1
    fmt = None
    elements: list[_Element] = []
    lines = data[:end + len(b"end_header")].decode("latin-1").splitlines()
    for lineno, line in enumerate(lines, start=1):
        tok = line.split()
        if not tok or tok[0] in ("comment", "obj_info", "ply", "end_header"):
            continue
        bad = MeshError(path, f"malformed PLY header line: {line.strip()[:60]!r}", lineno)
        if tok[0] == "format":
            if len(tok) != 3 or tok[1] not in ("ascii", "binary_little_endian",
                                               "binary_big_endian"):
                raise bad
            fmt = tok[1]
        elif tok[0] == "element":
            if len(tok) != 3 or not tok[2].isdigit():
                raise bad
            elements.append(_Element(tok[1], int(tok[2]), []))
        elif tok[0] == "property":
            if not elements:
                raise bad
            if len(tok) == 5 and tok[1] == "list":
                if tok[2] not in _PLY_TYPES or tok[3] not in _PLY_TYPES:
                    raise MeshError(path, f"unknown PLY type in {line.strip()!r}", lineno)
                if _PLY_TYPES[tok[2]][0] == "f":
                    raise MeshError(path, f"a list length must be an integer type: "
                                          f"{line.strip()!r}", lineno)
                elements[-1].props.append(_Prop(tok[4], _PLY_TYPES[tok[3]], _PLY_TYPES[tok[2]]))
            elif len(tok) == 3:
                if tok[1] not in _PLY_TYPES:
                    raise MeshError(path, f"unknown PLY type in {line.strip()!r}", lineno)
                elements[-1].props.append(_Prop(tok[2], _PLY_TYPES[tok[1]]))
            else:
                raise bad
        else:
            raise bad
    if fmt is None:
        raise MeshError(path, "PLY header has no 'format' line")
    return fmt, elements, body


def _read_ply(path: Path, data: bytes, flip: bool) -> MeshData:
    """Parse an ascii or binary PLY file; elements other than vertex and face are skipped."""
    fmt, elements, body = _parse_ply_header(path, data)
    if fmt == "ascii":
        reader = _AsciiBody(path, data[body:], data[:body].count(b"\n"))
    else:
        reader = _BinaryBody(path, data, body, "<" if fmt == "binary_little_endian" else ">")
    values: dict[str, dict[str, np.ndarray]] = {}
    for el in elements:
        wanted = el.name in ("vertex", "face")
        values[el.name] = reader.element(el, keep=wanted)
    reader.finish()

    if "vertex" not in values:
        raise MeshError(path, "PLY file has no 'vertex' element")
    vert = values["vertex"]
    for c in "xyz":
        if c not in vert:
            raise MeshError(path, f"PLY vertex element has no property '{c}'")
    vertices = np.stack([vert[c] for c in "xyz"], axis=1).astype(np.float64)
    if not np.isfinite(vertices).all():
        bad = int(np.argmax(~np.isfinite(vertices).all(axis=1)))
        raise MeshError(path, f"PLY vertex {bad} has a coordinate that is not finite")
    normals = uvs = None
    if all(c in vert for c in ("nx", "ny", "nz")):
        normals = _normalized(np.stack([vert[c] for c in ("nx", "ny", "nz")], axis=1))
    # The texture-coordinate names Mitsuba's ply plugin accepts, in its order of preference.
    for un, vn in (("u", "v"), ("texture_u", "texture_v"), ("s", "t")):
        if un in vert and vn in vert:
            uvs = np.stack([vert[un], vert[vn]], axis=1).astype(np.float64)
            if flip:
                uvs[:, 1] = 1.0 - uvs[:, 1]
            break

    face = values.get("face")
    if face is None:
        raise MeshError(path, "the mesh has no faces (no 'face' element)")
    key = next((k for k in ("vertex_index", "vertex_indices") if k in face), None)
    if key is None:
        raise MeshError(path, "PLY face element has no 'vertex_indices' (or 'vertex_index') "
                              "list")
    counts, flat = face[key]
    if len(counts) and counts.min() < 3:
        raise MeshError(path, f"PLY face {int(np.argmax(counts < 3))} has fewer than 3 "
                              "vertices")
    flat = flat.astype(np.int64)
    bad = (flat < 0) | (flat >= len(vertices))
    if bad.any():
        raise MeshError(path, f"bad index: face refers to vertex {int(flat[np.argmax(bad)])} "
                              f"but the file has {len(vertices)} vertices (0-based)")
    return MeshData(vertices, _fan(flat, counts), normals, uvs)


class _BinaryBody:
    """Reads the elements of a binary PLY body one after the other."""

    def __init__(self, path: Path, data: bytes, offset: int, order: str):
        self.path, self.data, self.offset, self.order = path, data, offset, order

    def _need(self, nbytes: int, el: _Element) -> None:
        if self.offset + nbytes > len(self.data):
            raise MeshError(self.path, f"PLY file ends inside element '{el.name}'")

    def element(self, el: _Element, keep: bool) -> dict:
        o = self.order
        if not any(p.count_dtype for p in el.props):
            dt = np.dtype([(f"p{i}", o + p.dtype) for i, p in enumerate(el.props)])
            self._need(dt.itemsize * el.count, el)
            rec = np.frombuffer(self.data, dt, el.count, self.offset)
            self.offset += dt.itemsize * el.count
            return {p.name: rec[f"p{i}"] for i, p in enumerate(el.props)} if keep else {}
        # Lists: first assume every list has the length of the first record's list
        # (true of triangle or quad meshes), read all records at once and check that.
        fast = self._uniform(el, keep)
        if fast is not None:
            return fast
        return self._walk(el, keep)

    def _first_counts(self, el: _Element) -> list[int] | None:
        off, out = self.offset, []
        for p in el.props:
            if p.count_dtype:
                size = np.dtype(p.count_dtype).itemsize
                if off + size > len(self.data):
                    return None
                n = int(np.frombuffer(self.data, self.order + p.count_dtype, 1, off)[0])
                out.append(n)
                off += size + n * np.dtype(p.dtype).itemsize
            else:
                off += np.dtype(p.dtype).itemsize
        return out

    def _uniform(self, el: _Element, keep: bool) -> dict | None:
        if el.count == 0:
            return {p.name: (np.zeros(0, np.int64), np.zeros(0)) if p.count_dtype
                    else np.zeros(0) for p in el.props}
        first = self._first_counts(el)
        if first is None or min(first) < 0:
            return None
        o, fields, k = self.order, [], 0
        for i, p in enumerate(el.props):
            if p.count_dtype:
                fields += [(f"c{i}", o + p.count_dtype)]
                if first[k]:
                    fields += [(f"p{i}", o + p.dtype, (first[k],))]
                k += 1
            else:
                fields += [(f"p{i}", o + p.dtype)]
        dt = np.dtype(fields)
        if self.offset + dt.itemsize * el.count > len(self.data):
            return None
        rec = np.frombuffer(self.data, dt, el.count, self.offset)
        k = 0
        for i, p in enumerate(el.props):
            if p.count_dtype:
                if np.any(rec[f"c{i}"] != first[k]):
                    return None
                k += 1
        self.offset += dt.itemsize * el.count
        if not keep:
            return {}
        out, k = {}, 0
        for i, p in enumerate(el.props):
            if p.count_dtype:
                n = first[k]
                k += 1
                flat = rec[f"p{i}"].reshape(-1) if n else np.zeros(0, p.dtype)
                out[p.name] = (np.full(el.count, n, np.int64), flat)
            else:
                out[p.name] = rec[f"p{i}"]
        return out

    def _walk(self, el: _Element, keep: bool) -> dict:
        """Record by record, for lists of varying length (polygon meshes of mixed degree)."""
        cols: dict[str, list] = {p.name: [] for p in el.props}
        lens: dict[str, list] = {p.name: [] for p in el.props if p.count_dtype}
        data, o = self.data, self.order
        sizes = [(np.dtype(p.dtype).itemsize,
                  np.dtype(p.count_dtype).itemsize if p.count_dtype else 0) for p in el.props]
        off = self.offset
        for _ in range(el.count):
            for p, (size, csize) in zip(el.props, sizes, strict=True):
                if p.count_dtype:
                    self.offset = off
                    self._need(csize, el)
                    n = int(np.frombuffer(data, o + p.count_dtype, 1, off)[0])
                    off += csize
                    if n < 0:
                        raise MeshError(self.path, f"negative list length in '{el.name}'")
                    self.offset = off
                    self._need(n * size, el)
                    if keep:
                        cols[p.name].append(np.frombuffer(data, o + p.dtype, n, off))
                        lens[p.name].append(n)
                    off += n * size
                else:
                    self.offset = off
                    self._need(size, el)
                    if keep:
                        cols[p.name].append(np.frombuffer(data, o + p.dtype, 1, off))
                    off += size
        self.offset = off
        if not keep:
            return {}
        out = {}
        for p in el.props:
            flat = np.concatenate(cols[p.name]) if cols[p.name] else np.zeros(0, p.dtype)
            out[p.name] = (np.asarray(lens[p.name], np.int64), flat) if p.count_dtype else flat
        return out

    def finish(self) -> None:
        # Mitsuba refuses trailing bytes too; a few newline bytes some writers append are fine.
        if self.data[self.offset:].strip(b"\r\n\x00 "):
            raise MeshError(self.path, "PLY file has data after its last element")


class _AsciiBody:
    """Reads the elements of an ascii PLY body from its whitespace-separated tokens."""

    def __init__(self, path: Path, body: bytes, header_lines: int):
        self.path, self.body, self.header_lines = path, body, header_lines
        self.tokens = body.split()
        self.pos = 0

    def _numbers(self, n: int, el: _Element) -> np.ndarray:
        if self.pos + n > len(self.tokens):
            raise MeshError(self.path, f"PLY file ends inside element '{el.name}'")
        chunk = self.tokens[self.pos:self.pos + n]
        try:
            out = np.array(chunk, dtype=np.float64) if n else np.zeros(0)
        except ValueError:
            bad = next(i for i, t in enumerate(chunk) if not _is_number(t))
            raise MeshError(self.path, f"expected a number in element '{el.name}', got "
                                       f"{chunk[bad].decode('latin-1')[:30]!r}",
                            self._line_of(self.pos + bad)) from None
        self.pos += n
        return out

    def _line_of(self, token: int) -> int:
        """Line number (of the whole file) of the token with this index, for messages."""
        header_lines = self.header_lines
        count = 0
        for i, line in enumerate(self.body.splitlines(), start=1):
            count += len(line.split())
            if count > token:
                return header_lines + i
        return header_lines + len(self.body.splitlines())

    def element(self, el: _Element, keep: bool) -> dict:
        n_props = len(el.props)
        if not any(p.count_dtype for p in el.props):
            rec = self._numbers(el.count * n_props, el).reshape(el.count, n_props)
            return {p.name: rec[:, i] for i, p in enumerate(el.props)} if keep else {}
        # Try: all lists as long as the first record's (one record = fixed token count).
        uniform = self._uniform(el)
        if uniform is not None:
            width, list_at = uniform
            rec = self._numbers(el.count * width, el).reshape(el.count, width)
            out = {}
            for p, (start, n) in zip(el.props, list_at, strict=True):
                if p.count_dtype:
                    if np.any(rec[:, start] != n):
                        self.pos -= el.count * width
                        return self._walk(el, keep)
                    out[p.name] = (np.full(el.count, n, np.int64),
                                   rec[:, start + 1:start + 1 + n].reshape(-1))
                else:
                    out[p.name] = rec[:, start]
            return out if keep else {}
        return self._walk(el, keep)

    def _uniform(self, el: _Element) -> tuple[int, list[tuple[int, int]]] | None:
        pos, at, width = self.pos, [], 0
        for p in el.props:
            if p.count_dtype:
                if pos >= len(self.tokens) or not self.tokens[pos].isdigit():
                    return None
                n = int(self.tokens[pos])
                at.append((width, n))
                width += 1 + n
                pos += 1 + n
            else:
                at.append((width, 1))
                width += 1
                pos += 1
        if el.count == 0 or self.pos + width * el.count > len(self.tokens):
            return None
        return width, at

    def _walk(self, el: _Element, keep: bool) -> dict:
        cols: dict[str, list] = {p.name: [] for p in el.props}
        lens: dict[str, list] = {p.name: [] for p in el.props if p.count_dtype}
        for _ in range(el.count):
            for p in el.props:
                if p.count_dtype:
                    n = self._numbers(1, el)[0]
                    if n < 0 or n != int(n):
                        raise MeshError(self.path, f"bad list length {n} in '{el.name}'",
                                        self._line_of(self.pos - 1))
                    cols[p.name].append(self._numbers(int(n), el))
                    lens[p.name].append(int(n))
                else:
                    cols[p.name].append(self._numbers(1, el))
        if not keep:
            return {}
        out = {}
        for p in el.props:
            flat = np.concatenate(cols[p.name]) if cols[p.name] else np.zeros(0)
            out[p.name] = (np.asarray(lens[p.name], np.int64), flat) if p.count_dtype else flat
        return out

    def finish(self) -> None:
        if self.pos != len(self.tokens):
            raise MeshError(self.path, "PLY file has data after its last element",
                            self._line_of(self.pos))


def _is_number(token: bytes) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


if __name__ == "__main__":  # pragma: no cover - a quick look at a file
    m = load_mesh(sys.argv[1])
    print(f"{len(m.vertices)} vertices, {len(m.faces)} triangles, "
          f"normals: {m.normals is not None}, uvs: {m.uvs is not None}")
