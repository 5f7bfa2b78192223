"""Triangle meshes from Wavefront OBJ and Stanford PLY files, and their vertex normals.

A mesh means the same surface to the tracer and to the reference: what this
module makes of a file is what Mitsuba 3.9.1's ``obj`` and ``ply`` plugins
make of it (the tests compare the two):

* PLY files are parsed by `plyfile <https://github.com/dranjan/python-plyfile>`_
  (ascii, binary little and big endian, every PLY scalar type, lists of any
  integer length type; its header grammar and its errors with line, element,
  record and property); this module only maps its elements to a mesh. A
  triangle mesh (every face a 3-list, the only kind Mitsuba's ``ply`` plugin
  reads) is read in one piece through a memory map; polygon faces, which only
  the tracer reads, through plyfile's record-by-record path.
* OBJ files are parsed here: the OBJ readers on PyPI that were measured
  (tinyobjloader, trimesh, pywavefront, openmesh, meshio, libigl) each differ
  from Mitsuba's reading or refuse less than it does (negative indices taken
  from the end of the file, quads split another way, bad numbers read as 0,
  no line numbers, NumPy 2 arrays of zeros); the README says which and why.
  OBJ indexes positions, texture coordinates and normals separately; a vertex
  of the result is one distinct (position, uv, normal) index triple, numbered
  in order of first use, which is how Mitsuba's ``obj`` plugin builds its
  vertex table (a hash map from the triple to a new vertex id). A position used with two different
  normals therefore becomes two vertices, and the vertex normals computed
  later for a mesh without normals agree with Mitsuba's.
* Polygons are split into a triangle fan (v0, v_k, v_k+1), the order
  Mitsuba's ``obj`` plugin uses.
* Texture coordinates: Mitsuba flips v (v -> 1 - v) for OBJ files by default
  (``flip_tex_coords = true``, for consistency with Mitsuba 0.x and 1) and not
  for PLY files; :func:`load_mesh` does the same unless told otherwise.
* Normals read from a file are normalised, as Mitsuba does.
* Vertex normals of a mesh without them are angle-weighted averages of the
  face normals (:func:`compute_vertex_normals`), Mitsuba's
  ``Mesh::recompute_vertex_normals``.

Both formats are held to one rule, in the precision the tracer and Mitsuba
store meshes in (float32): every position, normal and texture coordinate of
the mesh's vertex table is finite in float32; every normal has a length that
float32 can normalise (its squared length, in float32, neither 0 nor
infinite: Mitsuba's ``obj`` plugin refuses such a normal, its ``ply`` plugin
makes NaN of it); face indices are integers that name a vertex of the file;
numbers are plain ASCII decimals (Python would read ``1_0`` or an
Arabic-Indic digit as a number, Mitsuba would not). Every problem with a file
is a :class:`MeshError` whose one-line message names the file and, where the
format has lines (OBJ, the PLY header, ascii PLY bodies), the line.

Parsed meshes are kept in a small cache (:data:`CACHE_MAX_MESHES` meshes,
:data:`CACHE_MAX_BYTES` bytes of arrays, least recently used first out),
keyed by the file's resolved path, device, inode, size and modification and
change times (nanoseconds): loading the same, unchanged file again returns the
same :class:`MeshData`, whose arrays are read-only.

References: the OBJ format is Wavefront's "Object Files (.obj)" appendix of
the Advanced Visualizer manual; the PLY format is Greg Turk's "The PLY Polygon
File Format" (1994).
"""

from __future__ import annotations

import io
import math
import os
import re
import stat
import sys
import warnings
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tracer.errors import UserError

__all__ = ["CACHE_MAX_BYTES", "CACHE_MAX_MESHES", "MeshData", "MeshError", "clear_cache",
           "compute_vertex_normals", "face_normals", "load_mesh"]

#: The largest finite float32: positions, normals and uvs beyond it are infinite to the tracer.
FLOAT32_MAX = float(np.finfo(np.float32).max)

#: Bytes of memory reading a mesh may take per byte of its file, as upper bounds for the
#: WHITTED_MAX_MEMORY check made before reading: text (OBJ, ascii PLY) and binary PLY.
#: Peaks measured with tracemalloc on 2.4-5 MB files: OBJ of v and f lines 23x its size,
#: of v/vt/vn lines 15x, ascii PLY 19x; binary PLY of triangles 3.3x, of mixed polygons
#: (read record by record) 16x. The bounds leave a margin of about 1.4 over the largest.
MEMORY_PER_FILE_BYTE = {"text": 32, "binary": 24}

#: The cache's bounds: at most this many meshes, and this many bytes of arrays in all.
CACHE_MAX_MESHES = 16
CACHE_MAX_BYTES = 512 << 20


class MeshError(UserError):
    """A mesh file that cannot be read; the message names the file and the problem."""

    def __init__(self, path: str | Path, message: str, line: int | None = None):
        self.path, self.line = str(path), line
        where = f"{path}:{line}: " if line is not None else f"{path}: "
        super().__init__(where + message)


@dataclass(frozen=True, eq=False)
class MeshData:
    """A triangle mesh as read from a file (object space, Mitsuba's vertex order).

    The arrays of a mesh returned by :func:`load_mesh` are read-only: the same
    object is handed to every caller that loads the same file.

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

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in (self.vertices, self.faces, self.normals, self.uvs)
                   if a is not None)


# ---------------------------------------------------------------------------
# Loading, and the cache of parsed meshes
# ---------------------------------------------------------------------------

_cache: OrderedDict[tuple, MeshData] = OrderedDict()


def clear_cache() -> None:
    """Forget every parsed mesh (the next :func:`load_mesh` of each file parses it again)."""
    _cache.clear()


def load_mesh(path: str | Path, *, flip_tex_coords: bool | None = None) -> MeshData:
    """Read an OBJ or PLY file (chosen by its contents, then by its suffix).

    A file loaded before and unchanged since (same resolved path, device,
    inode, size, modification and change time) is not parsed again: the
    cached :class:`MeshData` is returned.

    Parameters
    ----------
    path : the file.
    flip_tex_coords : replace v by 1 - v. None (the default) does what Mitsuba's
        plugin for the format does by default: flip for OBJ, keep for PLY.

    Raises
    ------
    MeshError
        When the file is missing or not a regular file, too large for the
        memory limit, of an unknown format, malformed, refers to a vertex it
        does not have, holds values float32 cannot represent, or has no faces.
    """
    path = Path(path)
    key = _identity(path) + (flip_tex_coords,)
    mesh = _cache.get(key)
    if mesh is not None:
        _cache.move_to_end(key)
        return mesh
    mesh = _read_mesh(path, key[3], flip_tex_coords)
    for a in (mesh.vertices, mesh.faces, mesh.normals, mesh.uvs):
        if a is not None:
            a.flags.writeable = False
    if _identity(path) == key[:-1]:  # not cached if the file changed while it was read
        _remember(key, mesh)
    return mesh


def _identity(path: Path) -> tuple:
    """(resolved path, device, inode, size, modification and change time in ns)."""
    st = _stat_regular(path)
    return (os.path.realpath(path), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns,
            st.st_ctime_ns)


def _remember(key: tuple, mesh: MeshData) -> None:
    """Cache ``mesh``, dropping older versions of the file and the least recently used
    meshes beyond the bounds."""
    for old in [k for k in _cache if k[0] == key[0] and k[1:-1] != key[1:-1]]:
        del _cache[old]  # an older version of the same file
    if mesh.nbytes > CACHE_MAX_BYTES:
        return
    _cache[key] = mesh
    while len(_cache) > CACHE_MAX_MESHES or sum(m.nbytes for m in _cache.values()) \
            > CACHE_MAX_BYTES:
        _cache.popitem(last=False)


def _stat_regular(path: Path) -> os.stat_result:
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise MeshError(path, "no such mesh file") from None
    except (OSError, ValueError) as e:  # too long, a loop of links, a NUL in the name, ...
        raise MeshError(path, f"cannot read the mesh file ({getattr(e, 'strerror', None) or e})"
                        ) from None
    if stat.S_ISDIR(st.st_mode):
        raise MeshError(path, "is a folder, expected a mesh file")
    if not stat.S_ISREG(st.st_mode):
        kind = ("a FIFO" if stat.S_ISFIFO(st.st_mode) else "a socket"
                if stat.S_ISSOCK(st.st_mode) else "a device")
        raise MeshError(path, f"is {kind}, expected a regular file (an OBJ or PLY mesh)")
    return st


def _read_mesh(path: Path, size: int, flip_tex_coords: bool | None) -> MeshData:
    """Parse the file (no cache): the format by its first bytes, then by its suffix."""
    from tracer.limits import check_memory

    def check(kind: str) -> None:
        try:
            check_memory(size * MEMORY_PER_FILE_BYTE[kind],
                         f"reading this {size:,}-byte mesh file")
        except UserError as e:
            raise MeshError(path, str(e)) from None

    try:
        with open(path, "rb") as fh:
            magic = fh.read(4)
            if magic[:3] == b"ply" and magic[3:4] in (b"\n", b"\r", b" ", b"\t"):
                check("binary")  # ascii PLY files are checked again once their header is read
                mesh = _read_ply(path, fh, size, bool(flip_tex_coords), check)
            elif path.suffix.lower() == ".obj":
                check("text")
                data = magic + fh.read()
                mesh = _read_obj(path, data, True if flip_tex_coords is None
                                 else flip_tex_coords)
            elif path.suffix.lower() == ".ply":
                raise MeshError(path, "not a PLY file (it does not start with 'ply')")
            else:
                raise MeshError(path, f"unknown mesh format {path.suffix!r} "
                                      "(expected .obj or .ply)")
    except OSError as e:
        raise MeshError(path, f"cannot read the mesh file ({e.strerror or e})") from None
    if len(mesh.faces) == 0:
        raise MeshError(path, "the mesh has no faces")
    return mesh


# ---------------------------------------------------------------------------
# Values the tracer can use (float32), for both formats
# ---------------------------------------------------------------------------


def _first_bad(a: np.ndarray, normal: bool = False) -> tuple[int, str] | None:
    """(row, reason) of the first row of ``a`` float32 cannot hold, or None.

    A row must be finite, and finite once rounded to float32; a normal's
    squared length, summed in float32 as Mitsuba normalises it, must be
    neither 0 (the normal is zero, or underflows) nor infinite.
    """
    a = np.asarray(a, dtype=np.float64)
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        finite = np.isfinite(a).all(axis=1)
        a32 = a.astype(np.float32)
        in_range = np.isfinite(a32).all(axis=1)
        ok = finite & in_range
        if normal:
            s = np.sum(a32 * a32, axis=1, dtype=np.float32)
            ok &= (s > 0) & np.isfinite(s)
    if ok.all():
        return None
    i = int(np.argmin(ok))
    if not finite[i]:
        why = "is not finite (in float32)"
    elif not in_range[i]:
        why = f"is beyond float32's range (up to {FLOAT32_MAX:.4g})"
    elif s[i] == 0:
        why = "is zero in float32 (a normal must have a direction)"
    else:
        why = "is too long for float32 to normalise (its squared length overflows)"
    return i, why


def _show_row(a: np.ndarray, i: int) -> str:
    return "(" + ", ".join(f"{float(x):.6g}" for x in a[i]) + ")"


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
    lines = text.splitlines()
    plain = text.isascii() and "_" not in text  # else each line of numbers is checked
    for lineno, raw in enumerate(lines, start=1):
        body = raw.split("#", 1)[0]  # '#' starts a comment, also after data
        parts = body.split()
        if not parts:
            continue
        kind = parts[0]
        if kind not in ("v", "vt", "vn", "f"):
            continue  # o, g, s, usemtl, mtllib, l, p, ...: not geometry we render
        try:
            if not plain and (not body.isascii() or "_" in body):
                # Python's float() and int() read '1_0' and non-ASCII digits; Mitsuba does not.
                raise ValueError("numbers must be plain ASCII decimals")
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
            else:
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

    p = np.asarray(pos, dtype=np.float64).reshape(-1, 3)
    _check_obj_table(path, lines, "v", "position", p, uniq[:, 0])
    vertices = p[uniq[:, 0]]
    uvs = normals = None
    if tex and (uniq[:, 1] >= 0).any():
        # Corners without a uv get (0, 0) (Mitsuba leaves them undefined).
        t = np.asarray(tex, dtype=np.float64).reshape(-1, 2)
        _check_obj_table(path, lines, "vt", "texture coordinate", t, uniq[:, 1])
        if flip:
            t[:, 1] = 1.0 - t[:, 1]
        uvs = np.where((uniq[:, 1] >= 0)[:, None], t[np.maximum(uniq[:, 1], 0)], 0.0)
    if nrm and (uniq[:, 2] >= 0).all():
        # Only when every corner has one; otherwise all are computed from the faces.
        n = np.asarray(nrm, dtype=np.float64)
        _check_obj_table(path, lines, "vn", "normal", n, uniq[:, 2])
        normals = _normalized(n[uniq[:, 2]])
    faces = _fan(corner_vertex, np.asarray(counts))
    return MeshData(vertices, faces, normals, uvs)


def _check_obj_table(path: Path, lines: list[str], kind: str, what: str, table: np.ndarray,
                     used: np.ndarray) -> None:
    """Refuse the first element of ``table`` the faces use that float32 cannot hold.

    Elements no face uses are not checked (Mitsuba's vertex table holds only
    the used ones), except for the finiteness every number of the file is
    checked for as it is read.
    """
    mask = np.zeros(len(table), dtype=bool)
    mask[used[used >= 0]] = True
    rows = np.flatnonzero(mask)
    bad = _first_bad(table[rows], normal=kind == "vn")
    if bad is None:
        return
    k = int(rows[bad[0]])
    line = _nth_line_of_kind(lines, kind, k)
    raise MeshError(path, f"the {what} {_show_row(table, k)} {bad[1]}", line)


def _nth_line_of_kind(lines: list[str], kind: str, k: int) -> int | None:
    """Line number of the k-th (0-based) ``kind`` statement, for messages."""
    seen = 0
    for lineno, raw in enumerate(lines, start=1):
        parts = raw.split("#", 1)[0].split(None, 1)
        if parts and parts[0] == kind:
            if seen == k:
                return lineno
            seen += 1
    return None


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
# PLY (through plyfile)
# ---------------------------------------------------------------------------

#: Names of the face element's index list, and of the texture coordinates in the order
#: of preference of Mitsuba's ply plugin.
_INDEX_NAMES = ("vertex_indices", "vertex_index")
_UV_NAMES = (("u", "v"), ("texture_u", "texture_v"), ("s", "t"))
#: A header longer than this is read whole only if needed (comments can be long).
_HEADER_CHUNK = 1 << 16


def _read_ply(path: Path, fh, size: int, flip: bool, check_memory) -> MeshData:
    """Parse an ascii or binary PLY file with plyfile; elements other than vertex and face
    are read and dropped."""
    from plyfile import PlyData, PlyElementParseError, PlyHeaderParseError

    fh.seek(0)
    head = fh.read(_HEADER_CHUNK)
    end = head.find(b"end_header")
    if end < 0 and len(head) == _HEADER_CHUNK:
        head += fh.read()
        end = head.find(b"end_header")
    if end < 0:
        raise MeshError(path, "PLY header has no 'end_header'")
    end += len(b"end_header")
    end += 2 if head[end:end + 2] == b"\r\n" else 1 if head[end:end + 1] in (b"\n", b"\r") else 0
    header = head[:end]  # with its last newline: LF, CRLF or CR, as plyfile reads them
    header_lines = len(header.splitlines())
    _check_ply_header(path, header, size)
    ascii_ = any(line.split()[:2] == [b"format", b"ascii"] for line in header.splitlines())
    body_lines: list[bytes] | None = None
    stream = fh
    if ascii_:
        check_memory("text")
        fh.seek(0)
        data = fh.read()
        body = data[len(header):]
        if not body.isascii():
            at = next(i for i, b in enumerate(body) if b > 127)
            raise MeshError(path, "the PLY body is not ASCII text (a number must be plain "
                                  "ASCII decimals)",
                            header_lines + len(body[:at + 1].splitlines()))
        if b"_" in body:  # Python (and so plyfile) reads '1_0' as 10; it is not a PLY number
            at = body.index(b"_")
            raise MeshError(path, "malformed number in the PLY body (a '_' in it)",
                            header_lines + len(body[:at + 1].splitlines()))
        body_lines = body.splitlines()
        # plyfile reads a text stream as it is (LF, CRLF or CR lines, as newline=None reads
        # them), where it would wrap a binary one in a decoder of its own.
        stream = io.StringIO(data.decode("ascii"), newline=None)

    def where(element: str, row: int | None) -> int | None:
        """Line of record ``row`` of ``element`` in an ascii file (one record a line)."""
        if body_lines is None or row is None:
            return None
        before = 0
        for el in ply_elements:
            if el[0] == element:
                return header_lines + before + row + 1
            before += el[1]
        return None

    ply_elements: list[tuple[str, int]] = []
    stream.seek(0)
    try:
        with warnings.catch_warnings():
            # plyfile reads an empty ascii list through numpy.loadtxt, which warns, and an
            # ascii 1e39 into a float32, which warns of the overflow (refused below).
            warnings.simplefilter("ignore", UserWarning)
            warnings.simplefilter("ignore", RuntimeWarning)
            try:
                # A triangle mesh's faces are read in one piece; other lists record by record.
                ply = PlyData.read(stream, mmap="c", known_list_len={
                    "face": dict.fromkeys(_INDEX_NAMES, 3)})
            except PlyElementParseError as e:
                if e.message != "unexpected list length":
                    raise
                stream.seek(0)
                ply = PlyData.read(stream, mmap=False)
        consumed = None if ascii_ else fh.tell()
    except PlyHeaderParseError as e:
        line = _header_line(header, e.line)
        msg = e.message
        if msg.startswith("field type"):  # "field type 'floot' not in [every type]"
            msg = "unknown PLY type " + msg.split()[2]
        raise MeshError(path, f"malformed PLY header line ({msg}): {line!r}", e.line) from None
    except PlyElementParseError as e:
        ply_elements = _declared_elements(header)
        name = e.element.name if e.element is not None else "?"
        line = where(name, e.row)
        raise MeshError(path, _element_message(e, name, body_lines, line, header_lines),
                        line) from None
    except (ValueError, MemoryError, OverflowError) as e:  # left after the header checks
        raise MeshError(path, f"cannot read the PLY file ({e})") from None

    ply_elements = [(el.name, el.count) for el in ply.elements]
    if ascii_:
        records = sum(n for _, n in ply_elements)
        rest = body_lines[records:]
        extra = next((i for i, b in enumerate(rest) if b.strip()), None)
        if extra is not None:
            raise MeshError(path, "PLY file has data after its last element",
                            header_lines + records + extra + 1)
    elif consumed is not None and consumed < size:
        fh.seek(consumed)
        tail = fh.read(min(size - consumed, 4096))
        # Mitsuba refuses trailing bytes too; a few newline bytes some writers append are fine.
        if size - consumed > 4096 or tail.strip(b"\r\n\x00 "):
            raise MeshError(path, "PLY file has data after its last element")
    return _ply_mesh(path, ply, flip, where)


def _check_ply_header(path: Path, header: bytes, size: int) -> None:
    """What plyfile lets through: non-ASCII bytes, and element counts that are not plain
    decimal integers (``5_0``, ``-5``, a superscript digit) or that the file cannot hold."""
    if not header.isascii():
        at = next(i for i, b in enumerate(header) if b > 127)
        line = len(header[:at + 1].splitlines())
        text = header.splitlines()[line - 1].decode("utf-8", errors="replace").strip()
        raise MeshError(path, f"PLY header line is not ASCII text: {text[:60]!r}", line)
    for line, (name, count) in _element_lines(header):
        if not re.fullmatch(rb"[0-9]+", count):
            raise MeshError(path, f"malformed PLY header line (element count "
                                  f"{count.decode()!r} is not a decimal integer): "
                                  f"{_header_line(header, line)!r}", line)
        if int(count) > size:  # every record takes at least one byte
            raise MeshError(path, f"PLY header declares {int(count):,} '{name.decode()}' "
                                  f"records, more than a {size:,}-byte file can hold", line)


def _element_lines(header: bytes) -> list[tuple[int, tuple[bytes, bytes]]]:
    out = []
    for i, raw in enumerate(header.splitlines(), start=1):
        tok = raw.split()
        if tok[:1] == [b"element"] and len(tok) == 3:
            out.append((i, (tok[1], tok[2])))
    return out


def _declared_elements(header: bytes) -> list[tuple[str, int]]:
    return [(n.decode(), int(c)) for _, (n, c) in _element_lines(header)]


def _header_line(header: bytes, line: int | None) -> str:
    lines = header.splitlines()
    if line is None or not 1 <= line <= len(lines):
        return ""
    return lines[line - 1].decode("ascii", errors="replace").strip()[:60]


def _element_message(e, name: str, body_lines, line, header_lines) -> str:
    """One line for a plyfile element error: what was wrong, in which record and property."""
    rec = f"element '{name}'" + (f", record {e.row}" if e.row is not None else "")
    prop = f", property '{e.prop.name}'" if e.prop is not None else ""
    if e.message == "early end-of-file":
        return f"PLY file ends inside element '{name}'" + (
            f" (after {e.row:,} of {e.element.count:,} records)" if e.row is not None else "")
    if e.message == "malformed input" and body_lines is not None and line is not None:
        integer = e.prop is not None and np.dtype(e.prop.val_dtype).kind in "iu"
        token = _bad_token(body_lines[line - header_lines - 1], integer)
        expected = "an integer" if integer else "a number"
        return f"expected {expected} in {rec}{prop}, got {token!r}"
    if e.message == "early end-of-line":
        return f"{rec}{prop}: the line ends early (a PLY record is one line)"
    if e.message == "expected end-of-line":
        return f"{rec}: more numbers on the line than the header declares"
    return f"malformed PLY {rec}{prop}: {e.message}"


def _bad_token(line: bytes, integer: bool) -> str:
    for tok in line.decode("ascii", errors="replace").split():
        try:
            int(tok) if integer else float(tok)
        except ValueError:
            return tok[:30]
    return line.decode("ascii", errors="replace").strip()[:30]


def _ply_mesh(path: Path, ply, flip: bool, where) -> MeshData:
    """The mesh of a parsed PLY file: its 'vertex' and 'face' elements, checked."""
    if "vertex" not in ply:
        raise MeshError(path, "PLY file has no 'vertex' element")
    vert = ply["vertex"].data
    names = vert.dtype.names or ()
    for c in "xyz":
        if c not in names:
            raise MeshError(path, f"PLY vertex element has no property '{c}'")

    def column_block(cols) -> np.ndarray:
        return np.stack([np.asarray(vert[c], dtype=np.float64) for c in cols], axis=1)

    def check(a, what, normal=False):
        bad = _first_bad(a, normal)
        if bad is not None:
            raise MeshError(path, f"PLY vertex {bad[0]}: the {what} {_show_row(a, bad[0])} "
                                  f"{bad[1]}", where("vertex", bad[0]))

    vertices = column_block("xyz")
    check(vertices, "position")
    normals = uvs = None
    if all(c in names for c in ("nx", "ny", "nz")):
        n = column_block(("nx", "ny", "nz"))
        check(n, "normal", normal=True)
        normals = _normalized(n)
    for un, vn in _UV_NAMES:
        if un in names and vn in names:
            uvs = column_block((un, vn))
            check(uvs, "texture coordinate")
            if flip:
                uvs[:, 1] = 1.0 - uvs[:, 1]
            break

    if "face" not in ply:
        raise MeshError(path, "the mesh has no faces (no 'face' element)")
    face = ply["face"]
    key = next((k for k in _INDEX_NAMES if k in (face.data.dtype.names or ())), None)
    prop = face.ply_property(key) if key is not None else None
    if prop is None or not hasattr(prop, "len_dtype"):
        raise MeshError(path, "PLY face element has no 'vertex_indices' (or 'vertex_index') "
                              "list")
    if np.dtype(prop.len_dtype).kind not in "iu":
        raise MeshError(path, f"PLY face list '{key}' has a length of type "
                              f"{np.dtype(prop.len_dtype).name}; a length must be an integer")
    col = face.data[key]
    if col.dtype != object:  # the one-piece read: a (F, 3) array
        counts = np.full(len(col), col.shape[1] if col.ndim == 2 else 0, dtype=np.int64)
        flat = np.asarray(col).reshape(-1)
    else:
        counts = np.fromiter((len(a) for a in col), dtype=np.int64, count=len(col))
        flat = (np.concatenate([np.asarray(a) for a in col]) if len(col)
                else np.zeros(0, dtype=np.int64))
    if len(counts) and counts.min() < 3:
        k = int(np.argmax(counts < 3))
        raise MeshError(path, f"PLY face {k} has fewer than 3 vertices", where("face", k))

    def face_of(i: int) -> int:
        return int(np.searchsorted(np.cumsum(counts), i, side="right"))

    if flat.dtype.kind == "f":  # a float index list: only integer values name a vertex
        bad = ~np.isfinite(flat) | (flat != np.floor(flat))
        if bad.any():
            i = int(np.argmax(bad))
            raise MeshError(path, f"PLY face {face_of(i)} has a non-integer vertex index "
                                  f"{float(flat[i]):g}", where("face", face_of(i)))
    nv = len(vertices)
    bad = (flat < 0) | (flat >= nv)
    if bad.any():
        i = int(np.argmax(bad))
        raise MeshError(path, f"bad index: face {face_of(i)} refers to vertex "
                              f"{flat[i]:g} but the file has {nv} vertices (0-based)",
                        where("face", face_of(i)))
    return MeshData(vertices, _fan(flat.astype(np.int64), counts), normals, uvs)


if __name__ == "__main__":  # pragma: no cover - a quick look at a file
    m = load_mesh(sys.argv[1])
    print(f"{len(m.vertices)} vertices, {len(m.faces)} triangles, "
          f"normals: {m.normals is not None}, uvs: {m.uvs is not None}")
