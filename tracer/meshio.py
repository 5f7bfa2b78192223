"""Triangle meshes from Wavefront OBJ and Stanford PLY files, and their vertex normals.

A mesh means the same surface to the tracer and to the reference: what this
module makes of a file is what Mitsuba 3.9.1's ``obj`` and ``ply`` plugins
make of it (the tests compare the two):

* PLY files are parsed here, after Turk's description of the format: the
  header to the letter (one ``format`` line of version 1.0, ``element`` and
  ``property`` lines of known types, list lengths of integer types), then the
  body, ascii (one record a line, each number of its declared type: integers
  plain decimal integers in range, ``float`` values rounded to float32) or
  binary of either byte order, with lists of any integer length type. The
  permissively licensed PLY readers on PyPI that were measured (meshio,
  trimesh, pyvista-miniply, VTK, Open3D, point-cloud-utils, pyntcloud) each
  misread valid files or accept broken ones, even behind a wrapper, and
  plyfile is GPL-licensed; the README says which case each gets wrong.
  Triangle and quad meshes are read in one piece; mixed polygons record by
  record for their list lengths, then in one piece.
* OBJ files are parsed here, the whole file at once (NumPy's C parser reads the
  numbers of each statement's lines; a file it cannot vouch for is read line by
  line, which names a problem's line): the OBJ readers on PyPI that were measured
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
* Normals read from a file are normalised, as Mitsuba does. PLY positions,
  normals and uvs are rounded to float32 (a ``double`` too), as Mitsuba
  stores them.
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
same :class:`MeshData`, whose arrays are read-only. Files of
:data:`DISK_MIN_BYTES` or more are also kept parsed on disk, in
``~/.cache/whitted/meshes`` (:mod:`tracer.cache`'s rules: data only, this user's,
checked when read as the reader's own output is), keyed by a SHA-256 of the file's
bytes and of this module's source, so that a new process, or a copy of the file
elsewhere, skips the parse.

References: the OBJ format is Wavefront's "Object Files (.obj)" appendix of
the Advanced Visualizer manual; the PLY format is Greg Turk's "The PLY Polygon
File Format" (1994).
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import struct
import sys
import time
import warnings
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from whitted.tracer.errors import UserError
from whitted.tracer.files import special_kind

__all__ = ["CACHE_MAX_BYTES", "CACHE_MAX_MESHES", "MeshData", "MeshError", "clear_cache",
           "compute_vertex_normals", "face_normals", "load_mesh", "row_lengths",
           "vertex_normals"]

#: The largest finite float32: positions, normals and uvs beyond it are infinite to the tracer.
FLOAT32_MAX = float(np.finfo(np.float32).max)

#: Bytes of memory reading a mesh may take per byte of its file, as upper bounds for the
#: WHITTED_MAX_MEMORY check made before reading: text (OBJ, ascii PLY) and binary PLY.
#: Peaks measured with tracemalloc on 2.4-6.3 MB files: OBJ of v and f lines 23x its size,
#: of v/vt/vn lines 15x, ascii PLY 16x (triangles; mixed triangles and quads 14x); binary
#: PLY of triangles 4.2x, of mixed triangles and quads (their list lengths found record by
#: record) 9.6x. The bounds leave a margin of about 1.4 over the largest.
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
    key : for a file kept parsed on disk (:data:`DISK_MIN_BYTES` or more), the key of
        that entry: a hash of the file's bytes, the reading options and this module's
        source, so of everything the arrays are made from; else None.
    """
    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray | None = None
    uvs: np.ndarray | None = None
    key: str | None = None

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in (self.vertices, self.faces, self.normals, self.uvs)
                   if a is not None)


def write_ply(path: str | Path, vertices: np.ndarray, faces: np.ndarray,
              normals: np.ndarray | None = None) -> None:
    """Write a triangle mesh as a binary little-endian PLY: float32 ``x y z`` (and ``nx ny
    nz`` where ``normals`` are given) per vertex, a ``vertex_indices`` list (uchar count,
    int32 indices) per face; the layout :func:`load_mesh` reads back and LuxCore's reader
    takes (reference/renderers/luxcore/render.py hands LuxCore its meshes this way, and
    scenes/meshes/generate.py writes the built-in knot)."""
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    f = np.asarray(faces).reshape(-1, 3)
    if len(f) and (f.min() < 0 or f.max() >= len(v)):
        raise ValueError("face indices out of range")
    names = ["x", "y", "z"] + (["nx", "ny", "nz"] if normals is not None else [])
    rows = np.empty(len(v), dtype=[(k, "<f4") for k in names])
    cols = v.T if normals is None else np.concatenate(
        [v, np.asarray(normals, dtype=np.float64).reshape(-1, 3)], axis=1).T
    for k, c in zip(names, cols, strict=True):
        rows[k] = c
    tris = np.empty(len(f), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    tris["n"], tris["i"] = 3, f
    header = ("ply\nformat binary_little_endian 1.0\ncomment generated by whitted\n"
              f"element vertex {len(v)}\n" + "".join(f"property float {k}\n" for k in names)
              + f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n")
    with open(path, "wb") as fh:
        fh.write(header.encode("ascii"))
        fh.write(rows.tobytes())
        fh.write(tris.tobytes())


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
    disk, data = _disk_entry(path, key) if key[3] >= DISK_MIN_BYTES else (None, None)
    mesh = _disk_read(disk) if disk is not None else None
    if mesh is None:   # parsed from the bytes just hashed, where they were read
        mesh = _read_mesh(path, key[3], flip_tex_coords, data)
        if disk is not None and _identity(path) == key[:-1]:
            _disk_write(disk, mesh)
    del data
    if disk is not None:
        mesh = dataclasses.replace(mesh, key=disk.stem)
    for a in (mesh.vertices, mesh.faces, mesh.normals, mesh.uvs):
        if a is not None:
            a.flags.writeable = False
    if _identity(path) == key[:-1]:  # not cached if the file changed while it was read
        _remember(key, mesh)
    return mesh


# ---------------------------------------------------------------------------
# The cache on disk: parsed meshes, keyed by the file's bytes
# ---------------------------------------------------------------------------

#: Files at least this large are kept parsed on disk (smaller ones parse in milliseconds).
DISK_MIN_BYTES = 1 << 20
#: The disk cache's bound, all meshes together; the least recently used go first.
DISK_MAX_BYTES = 2 << 30


def disk_folder() -> Path:
    """``$XDG_CACHE_HOME/whitted/meshes``: parsed mesh files (:mod:`tracer.cache`'s rules)."""
    from whitted.tracer import cache

    return cache.home() / "meshes"


def _disk_entry(path: Path, key: tuple) -> tuple[Path | None, bytes | None]:
    """(where the parse of this file's bytes, with this flip option, is kept; those bytes,
    or None where the file's identity named the entry and they were not read), or
    (None, None) when the file cannot be read whole or changed while it was hashed."""
    from whitted.tracer.cache import content_key, source_digest

    flip = {None: "default", True: "flip", False: "keep"}[key[-1]]
    known = _known_bytes(key)
    if known is not None:
        return disk_folder() / f"{known}.arrays", None
    try:
        with open(path, "rb") as fh:
            data = fh.read(key[3] + 1)
    except OSError:
        return None, None   # the reader names the problem
    if len(data) != key[3] or _identity(path) != key[:-1]:
        return None, None
    stem = content_key(source_digest(__file__), flip, data)
    _know_bytes(key, stem)
    return disk_folder() / f"{stem}.arrays", data


#: A file whose modification and change times are at least this old (nanoseconds) when
#: its bytes are hashed has its identity (:func:`_identity`) noted beside its entry.
SETTLED_NS = 2_000_000_000


def _identity_entry(key: tuple) -> Path:
    """Where the entry's name of the file of ``key`` (its identity and flip option) is
    noted (:func:`_know_bytes`)."""
    from whitted.tracer.cache import content_key, source_digest

    name = content_key(source_digest(__file__), "identity", repr(key))
    return disk_folder() / f"{name}.identity"


def _known_bytes(key: tuple) -> str | None:
    """The entry's name noted for the file of ``key`` (its identity and flip option), or
    None: the file then is read and hashed. Hashing the 1,000,000-triangle knot's 19 MB
    took about 15 ms of each start, and reading it about as much (issue 33)."""
    from whitted.tracer import cache

    a = cache.read_entry(_identity_entry(key), {"entry": "|u1"})
    if a is None or a["entry"].shape != (64,):
        return None
    stem = a["entry"].tobytes()
    if not all(c in b"0123456789abcdef" for c in stem):
        return None
    return stem.decode()


def _know_bytes(key: tuple, stem: str) -> None:
    """Note ``stem`` (the entry's name of the bytes just hashed) for the file of ``key``,
    where the file's times are settled (:data:`SETTLED_NS` old). A write changes a file's
    change time (which no program can set back), and a new file at the same inode has
    its own. With the times at least 2 s older than the hashing, a later change gets a
    later time on any file system whose clock ticks at most every 2 s (FAT's does, for
    its modification time): the change shows in the identity. Git's index treats a file
    written within its clock's tick as changed for the same reason ("racy git")."""
    from whitted.tracer import cache

    _, _, _, _, mtime, ctime = key[:-1]
    if time.time_ns() - max(mtime, ctime) < SETTLED_NS:
        return
    cache.keep_entry(_identity_entry(key), {"entry": np.frombuffer(stem.encode(), np.uint8)},
                     DISK_MAX_BYTES)


_DISK_KINDS = {"vertices": "<f8", "faces": "<i8"}
_DISK_OPTIONAL = {"normals": "<f8", "uvs": "<f8"}


def _disk_read(entry: Path) -> MeshData | None:
    """The mesh kept at ``entry`` if it holds what the reader could have made, else None.

    Checked as the reader's own output is: shapes, at least one face, indices that
    name a vertex, values float32 can hold, normals float32 can normalise.
    """
    from whitted.tracer import cache

    a = cache.read_entry(entry, _DISK_KINDS, _DISK_OPTIONAL)
    if a is None:
        return None
    v, f = a["vertices"], a["faces"]
    n, uv = a.get("normals"), a.get("uvs")
    if (v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 or len(f) == 0
            or int(f.min()) < 0 or int(f.max()) >= len(v)
            or (n is not None and n.shape != v.shape)
            or (uv is not None and uv.shape != (len(v), 2))
            or _first_bad(v) is not None or (uv is not None and _first_bad(uv) is not None)
            or (n is not None and _first_bad(n, normal=True) is not None)):
        return None
    cache.touch(entry)
    return MeshData(v, f, n, uv)


#: Meshes of at least this many faces keep their computed vertex normals on disk.
DISK_MIN_FACES = 1 << 15


def vertex_normals(vertices: np.ndarray, faces: np.ndarray, key: str | None = None
                   ) -> np.ndarray:
    """:func:`compute_vertex_normals`, kept on disk (beside the parsed meshes) for meshes
    of :data:`DISK_MIN_FACES` faces or more, keyed by a SHA-256 of this module's source
    and ``key``, else of the vertices and the faces. ``key``, where the caller has one,
    is a hash of what the vertices and faces are made from (a file kept parsed on disk,
    :attr:`MeshData.key`, and how it is placed): hashing the arrays themselves took
    about 19 ms for the 1,000,000-triangle knot. An entry is used only when it has one
    unit normal (or Mitsuba's placeholder) per vertex."""
    from whitted.tracer import cache

    v = np.ascontiguousarray(vertices, dtype=np.float64)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    if len(f) < DISK_MIN_FACES:
        return compute_vertex_normals(v, f)
    made_of = ("of", key) if key is not None else (v, f)
    key = cache.content_key(cache.source_digest(__file__), "normals", *made_of)
    entry = disk_folder() / f"{key}.arrays"
    a = cache.read_entry(entry, {"normals": "<f8"})
    if a is not None and a["normals"].shape == v.shape:
        n = a["normals"]
        with np.errstate(invalid="ignore"):
            unit = np.abs(row_lengths(n) - 1.0) <= 1e-12
        if unit.all():
            cache.touch(entry)
            return n.copy()
    n = compute_vertex_normals(v, f)
    cache.keep_entry(entry, {"normals": n}, DISK_MAX_BYTES)
    return n


def _disk_write(entry: Path, mesh: MeshData) -> None:
    """Keep ``mesh`` at ``entry``; a cache only saves time, so a failure is silent."""
    from whitted.tracer import cache

    arrays = {"vertices": mesh.vertices, "faces": np.asarray(mesh.faces, dtype=np.int64)}
    arrays.update({k: v for k, v in (("normals", mesh.normals), ("uvs", mesh.uvs))
                   if v is not None})
    cache.keep_entry(entry, arrays, DISK_MAX_BYTES)


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
    kind = special_kind(st)
    if kind == "a folder":
        raise MeshError(path, "is a folder, expected a mesh file")
    if kind is not None:
        raise MeshError(path, f"is {kind}, expected a regular file (an OBJ or PLY mesh)")
    return st


def _read_mesh(path: Path, size: int, flip_tex_coords: bool | None,
               data: bytes | None = None) -> MeshData:
    """Parse the file (no cache): the format by its first bytes, then by its suffix.
    ``data``: the file's bytes, already read (to hash them for the cache on disk)."""
    import io

    from whitted.tracer.limits import check_memory

    def check(kind: str) -> None:
        try:
            check_memory(size * MEMORY_PER_FILE_BYTE[kind],
                         f"reading this {size:,}-byte mesh file")
        except UserError as e:
            raise MeshError(path, str(e)) from None

    try:
        with open(path, "rb") if data is None else io.BytesIO(data) as fh:
            magic = fh.read(4)
            if magic[:3] == b"ply" and magic[3:4] in (b"\n", b"\r", b" ", b"\t"):
                check("binary")  # ascii PLY files are checked again once their header is read
                mesh = _read_ply(path, fh, size, bool(flip_tex_coords), check)
            elif path.suffix.lower() == ".obj":
                check("text")
                text = data if data is not None else magic + fh.read()
                mesh = _read_obj(path, text, True if flip_tex_coords is None
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
        a32 = a.astype(np.float32)
        finite32 = np.isfinite(a32)
        if normal:
            s = np.sum(a32 * a32, axis=1, dtype=np.float32)
            lengths_ok = (s > 0) & np.isfinite(s)
        # Every number finite in float32 means finite in float64 too (an infinity or a
        # NaN stays one when rounded): one pass over the numbers for a good array, the
        # rows only for a bad one (the 1,000,000-triangle knot's vertices in about 4 ms
        # rather than 13 ms).
        if finite32.all() and (not normal or lengths_ok.all()):
            return None
        finite = np.isfinite(a).all(axis=1)
        in_range = finite32.all(axis=1)
        ok = finite & in_range
        if normal:
            ok &= lengths_ok
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
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    n = np.empty(f.shape, np.float64)   # unit face normals
    w = np.empty(f.shape, np.float64)   # the weight of face j at its corner k, as f is laid out
    blocks = [slice(s, s + NORMALS_BLOCK) for s in range(0, len(f), NORMALS_BLOCK)]

    columns = [np.ascontiguousarray(v[:, c]) for c in range(3)]
    corners = f.reshape(-1)

    def some(part):
        for b in part:
            _face_terms(columns, f[b], n[b], w[b])

    def summed(c):   # component c of each vertex's sum, the corners added in order
        return np.bincount(corners, weights=(w * n[:, c:c + 1]).reshape(-1), minlength=len(v))

    if len(blocks) < 2:
        some(blocks)
        sums = [summed(c) for c in range(3)]
    else:
        # Every other block on a second thread, then two of the three components' sums
        # there: numpy's loops (bincount's too) let go of Python's lock.
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(max_workers=1) as pool:
            odd = pool.submit(some, blocks[1::2])
            some(blocks[0::2])
            odd.result()
            xz = pool.submit(lambda: (summed(0), summed(2)))
            y = summed(1)
            x, z = xz.result()
        sums = [x, y, z]
    length = _length3(*sums)
    ok = length > 0
    out = np.zeros_like(v)
    for c in range(3):
        np.divide(sums[c], length, out=out[:, c], where=ok)
    out[~ok] = (1.0, 0.0, 0.0)  # Mitsuba's placeholder for an isolated vertex
    return out


#: Faces a block of :func:`compute_vertex_normals`' per-face work. Its temporaries (a
#: dozen arrays of a row a face) then stay small, and later blocks reuse the memory of
#: earlier ones: on the 1,000,000-triangle knot, the whole mesh at once touched a few
#: hundred MB of fresh pages, and the first call of a process took more than twice as
#: long as later ones (a throwaway script).
NORMALS_BLOCK = 1 << 15


def _face_terms(v: list, f: np.ndarray, n_out: np.ndarray, w_out: np.ndarray) -> None:
    """For faces ``f`` of vertices ``v`` (its x, y and z columns, each contiguous): unit
    normals into ``n_out`` (zero for a degenerate face) and corner angles into ``w_out``
    (zero for a degenerate face), row for row. Each face's numbers depend on that face
    alone, so blocks give the whole mesh's bit for bit.

    Written on columns: numpy's operations on rows of three (``np.cross``, an einsum's
    lengths, a (N, 1) divisor) took twice as long, 279 ms against 136 ms for the
    1,000,000-triangle knot on one thread (a throwaway script, issue 33). The numbers
    are those of the row-wise code bit for bit (compared on the knot and on random
    meshes): the same products and differences as ``np.cross``, and each length sums
    its squares as that einsum did here (:func:`_length3`)."""
    p = [[c[f[:, k]] for c in v] for k in range(3)]   # p[k][axis]: corner k
    e = [[p[(k + 1) % 3][a] - p[k][a] for a in range(3)]   # edge k: corner k to k + 1
         for k in range(3)]
    a0, a1, a2 = e[0]
    b0, b1, b2 = (-x for x in e[2])
    n = (a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0)   # e0 x -e2
    length = _length3(*n)
    valid = length > 0
    for c in range(3):
        out = n_out[:, c]
        np.divide(n[c], length, out=out, where=valid)
        out[~valid] = 0.0
    u = []
    for x in e:
        ln = _length3(*x)
        u.append([np.divide(c, ln, out=np.zeros_like(c), where=ln > 0) for c in x])
    for k in range(3):   # the angle at corner k, between edge k and edge k - 1 reversed
        a, b = u[k], [-c for c in u[(k + 2) % 3]]
        w_out[:, k] = np.where(valid, 2 * np.arctan2(_length3(*(a[c] - b[c] for c in range(3))),
                                                     _length3(*(a[c] + b[c] for c in range(3)))),
                               0.0)


def _length3(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The Euclidean lengths of the vectors (x, y, z), given as columns, the squares summed
    as (x^2 + z^2) + y^2: the order in which numpy's einsum (``"ij,ij->i"``), which the
    vertex normals used before, summed a row of three on the AVX-512 machine this was
    measured on (all of 3,000,000 random rows at three scales). Written out, the vertex
    normals no longer depend on how a numpy build's einsum orders its sum."""
    s = x * x
    s += z * z
    s += y * y
    return np.sqrt(s, out=s)


def row_lengths(a: np.ndarray) -> np.ndarray:
    """The Euclidean length of each row of an (N, 3) float64 array, bit for bit
    ``np.linalg.norm(a, axis=1)`` (which sums x^2 + y^2 + z^2 in that order), written
    column by column: numpy's reduction along a row of three is about three times as
    long (the 1,000,000-triangle knot's 500,000 normals: 14 ms against 4.5 ms). Not
    :func:`_length3`, which sums in another order (other last bits), the one the vertex
    normals keep."""
    s = a[:, 0] * a[:, 0]
    s += a[:, 1] * a[:, 1]
    s += a[:, 2] * a[:, 2]
    return np.sqrt(s, out=s)


def _unit(a: np.ndarray) -> np.ndarray:
    length = row_lengths(a)[:, None]
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
    """Parse an OBJ file: ``v``, ``vt``, ``vn`` and ``f`` lines; other statements are ignored.

    The whole file is read at once (:func:`_read_obj_fast`); a file that reading
    cannot vouch for (a problem, or a layout it does not handle) is read line by
    line (:func:`_read_obj_lines`), which gives the same arrays or names the problem.
    """
    mesh = _read_obj_fast(data, flip)
    return mesh if mesh is not None else _read_obj_lines(path, data, flip)


#: Bytes that end a line for str.splitlines() but not for bytes (VT, FF, FS, GS, RS; NEL,
#: LS and PS in UTF-8), and US, which str.split() splits at and bytes.split() does not.
_OBJ_ODD = (b"\x0b", b"\x0c", b"\x1c", b"\x1d", b"\x1e", b"\x1f")
_OBJ_ODD_UTF8 = (b"\xc2\x85", b"\xe2\x80\xa8", b"\xe2\x80\xa9")
_OBJ_SPACES = re.compile(rb" {2,}")
#: A sign not at the start of an index, or not followed by a digit: int() refuses it,
#: NumPy's integer parser would not.
_OBJ_BAD_SIGN = re.compile(rb"(?<![ /])[+-]|[+-](?![0-9])")
_OBJ_TO_SPACE = {kind: bytes.maketrans(chars, b" " * len(chars))
                 for kind, chars in ((b"v", b"v"), (b"vt", b"vt"), (b"vn", b"vn"),
                                     (b"f", b"f/"))}


def _parse_numbers(text: bytes, dtype) -> np.ndarray | None:
    """The numbers of a whitespace-separated text (C-parsed by NumPy: a float as float()
    reads it, correctly rounded), or None if a token is not one number."""
    if not text.strip():
        return None  # NumPy reads an empty text as one number
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a token it cannot read ends the parse with a warning
        try:
            return np.fromstring(text, dtype=dtype, sep=" ")
        except (ValueError, DeprecationWarning):
            return None


def _single_spaced(chunk: bytes) -> bytes:
    """The lines with single spaces between tokens and none at their ends."""
    return _OBJ_SPACES.sub(b" ", chunk).replace(b" \n", b"\n")


def _obj_numbers(chunk: bytes, kind: bytes, n: int) -> np.ndarray | None:
    """(n, k) values of the n ``v``, ``vt`` or ``vn`` lines ``chunk`` (each ending in a
    newline) if each holds k numbers that float() reads; None otherwise.

    The skeleton of the lines (their text once the characters of numbers are
    deleted) must be the keyword and k spaces a line: every other character
    (a letter of 'nan', an underscore, a second keyword) stays in it. A line
    then holds at most k numbers (NumPy's parser needs a space between two),
    so n k numbers in all means k on every line.
    """
    return _respaced(_obj_numbers_spaced, chunk, kind, n)


def _respaced(read, chunk: bytes, *args):
    """``read(chunk, *args)``, or, where that is None, the same of the lines single-spaced."""
    out = read(chunk, *args)
    if out is None and (b"  " in chunk or b" \n" in chunk):
        out = read(_single_spaced(chunk), *args)
    return out


def _obj_numbers_spaced(chunk: bytes, kind: bytes, n: int) -> np.ndarray | None:
    skel = chunk.translate(None, b"0123456789.eE+-")
    k = skel.index(b"\n") - len(kind)
    if k <= 0 or skel != (kind + b" " * k + b"\n") * n:
        return None
    values = _parse_numbers(chunk.translate(_OBJ_TO_SPACE[kind]), np.float64)
    return None if values is None or len(values) != n * k else values.reshape(n, k)


def _obj_corners(chunk: bytes, n: int
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None] | None:
    """(corners of each line, then the position, uv and normal indices as written, None
    where the form has none) of the n ``f`` lines ``chunk`` if their corners all have
    one form (v, v/vt, v//vn or v/vt/vn) with no field empty but v//vn's middle one, and
    every index is an integer int() reads; None otherwise.

    The skeleton (digits and signs deleted) is 'f', then ' ', ' /' or ' //' a
    corner; a corner holds at most as many numbers as it has fields, so the
    count of numbers read says that none is empty.
    """
    return _respaced(_obj_corners_spaced, chunk, n)


def _obj_corners_spaced(chunk: bytes, n: int):
    skel = chunk.translate(None, b"0123456789+-")
    first = skel[:skel.index(b"\n")].split(b" ")
    form = first[1] if len(first) > 1 else None
    corners = skel.count(b" ")
    ok = form in (b"", b"/", b"//") and (
        b"/" not in skel if form == b"" else
        skel.count(b" " + form) == corners and skel.count(b"/") == len(form) * corners)
    if ok:
        bare = skel.translate(None, b"/") if form else skel
        if bare == b"f   \n" * n:
            counts = np.full(n, 3, dtype=np.int64)
        elif bare.translate(None, b"f \n") or bare.count(b"f") != n:
            ok = False
        else:
            counts = np.diff(np.flatnonzero(np.frombuffer(bare, dtype=np.uint8) == 10),
                             prepend=-1) - 2
            ok = counts.min() >= 3
    if not ok:
        return None
    if (b"-" in chunk or b"+" in chunk) and _OBJ_BAD_SIGN.search(chunk):
        return None
    values = _parse_numbers(chunk.translate(_OBJ_TO_SPACE[b"f"]), np.int64)
    if values is None:
        return None
    fields = (True, form != b"", form == b"//")
    if len(values) == 2 * corners and form == b"//" and chunk.count(b"//") == corners:
        fields = (True, False, True)  # v//vn on every corner
    elif len(values) != sum(fields) * corners:
        return None
    cols = iter(values.reshape(corners, sum(fields)).T)
    return counts, next(cols), *(next(cols) if has else None for has in fields[1:])


def _read_obj_fast(data: bytes, flip: bool) -> MeshData | None:
    """The mesh of an OBJ file read whole, or None where :func:`_read_obj_lines` must read it.

    The lines are classified by their first bytes; each statement's lines
    (``v``, ``vt``, ``vn``, ``f``) are joined into one text, whose skeleton
    (the text once the characters of numbers are deleted) shows in a
    comparison or two whether every line holds the same count of well-formed
    tokens; NumPy's C parser then reads the numbers (as float() and int() read
    them, the tokens being plain decimals). Anything else (a line indented, a
    number Python would refuse, a vertex of another form, an index out of
    range, a value float32 cannot hold) gives None, and the line-by-line reader
    reads the file or names its problem: the arrays are the same either way.
    """
    if any(b in data for b in _OBJ_ODD) or (not data.isascii() and
                                            any(b in data for b in _OBJ_ODD_UTF8)):
        return None
    if b"\r" in data:
        data = data.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
    if b"#" in data:  # a comment runs to the end of its line
        head, *rest = data.split(b"#")
        data = b"".join([head] + [r[r.find(b"\n"):] if b"\n" in r else b"" for r in rest])
    if b"\t" in data:
        data = data.replace(b"\t", b" ")
    if not data.endswith(b"\n"):
        data += b"\n"
    c = np.frombuffer(data + b"\0\0", dtype=np.uint8)
    ends = np.flatnonzero(c == 10)  # the newline of each line
    starts = np.concatenate(([0], ends[:-1] + 1))
    c0, c1, c2 = c[starts], c[starts + 1], c[starts + 2]
    sep1, sep2 = (c1 == 32) | (c1 == 10), (c2 == 32) | (c2 == 10)
    kind = np.zeros(len(starts), dtype=np.int8)  # 1 v, 2 vt, 3 vn, 4 f, 0 anything else
    is_v = c0 == ord("v")
    kind[is_v & sep1] = 1
    kind[is_v & (c1 == ord("t")) & sep2] = 2
    kind[is_v & (c1 == ord("n")) & sep2] = 3
    kind[(c0 == ord("f")) & sep1] = 4
    # Indented lines, and lines with non-ASCII bytes (which str.split() may split at):
    # looked at one by one; a statement among them is left to the line-by-line reader.
    odd = np.flatnonzero(c0 == 32)
    if not data.isascii():
        odd = np.union1d(odd, np.searchsorted(ends, np.flatnonzero(c[:len(data)] >= 128)))
    for i in odd.tolist():
        words = data[starts[i]:ends[i]].decode("utf-8", errors="replace").split()
        if words and words[0] in ("v", "vt", "vn", "f"):
            return None

    def text_of(k: int, lines: np.ndarray) -> bytes:
        """The lines of statement k, joined (runs of adjacent lines sliced whole)."""
        breaks = np.flatnonzero(np.diff(lines) != 1)
        if len(breaks) < 256:
            firsts = np.concatenate(([lines[0]], lines[breaks + 1])).tolist()
            lasts = np.concatenate((lines[breaks], [lines[-1]])).tolist()
            return b"".join(data[starts[a]:ends[b] + 1] for a, b in zip(firsts, lasts, strict=True))
        return c[:len(data)][np.repeat(kind == k, ends - starts + 1)].tobytes()

    tables = []
    for k, word, least in ((1, b"v", 3), (2, b"vt", 1), (3, b"vn", 3)):
        lines = np.flatnonzero(kind == k)
        if len(lines) == 0:
            tables.append(np.zeros((0, 2 if k == 2 else 3)))
            continue
        a = _obj_numbers(text_of(k, lines), word, len(lines))
        if a is None or a.shape[1] < least:
            return None
        if k == 2:  # 'vt u' is (u, 0), as Python's reader pads it
            a = a[:, :2] if a.shape[1] >= 2 else np.concatenate([a, np.zeros_like(a)], 1)
        else:
            a = a[:, :3]
        if not np.isfinite(a).all():
            return None
        tables.append(np.ascontiguousarray(a))
    p, t, n = tables
    faces = np.flatnonzero(kind == 4)
    if len(faces) == 0:
        return None
    read = _obj_corners(text_of(4, faces), len(faces))
    if read is None:
        return None
    counts, *written = read

    def resolve(k: np.ndarray | None, statement: int) -> np.ndarray | None:
        """0-based indices (-1 absent) of written ones, counted among the statements
        read before each face's line; None if one names no such element."""
        if k is None:
            return np.full(len(written[0]), -1, dtype=np.int64)
        before = np.cumsum(kind == statement)[faces]
        if before[0] != before[-1]:
            before = np.repeat(before, counts)
        else:
            before = before[0]
        i = np.where(k > 0, k - 1, before + k)
        if ((k == 0) | (i < 0) | (i >= before)).any():
            return None
        return i

    cv, ct, cn = (resolve(k, s) for k, s in zip(written, (1, 2, 3), strict=True))
    if cv is None or ct is None or cn is None:
        return None
    first, corner_vertex = _first_uses(cv, ct, cn, len(p), len(t), len(n))
    uniq = np.stack([cv[first], ct[first], cn[first]], axis=1)
    if _first_bad(p[uniq[:, 0]]) is not None:
        return None
    vertices = p[uniq[:, 0]]
    uvs = normals = None
    if len(t) and (uniq[:, 1] >= 0).any():
        if _first_bad(t[uniq[uniq[:, 1] >= 0, 1]]) is not None:
            return None
        if flip:
            t[:, 1] = 1.0 - t[:, 1]
        uvs = np.where((uniq[:, 1] >= 0)[:, None], t[np.maximum(uniq[:, 1], 0)], 0.0)
    if len(n) and (uniq[:, 2] >= 0).all():
        if _first_bad(n[uniq[:, 2]], normal=True) is not None:
            return None
        normals = _normalized(n[uniq[:, 2]])
    return MeshData(vertices, _fan(corner_vertex, counts), normals, uvs)


def _first_uses(cv: np.ndarray, ct: np.ndarray, cn: np.ndarray, nv: int, nt: int, nn: int
                ) -> tuple[np.ndarray, np.ndarray]:
    """(the corner of each distinct (position, uv, normal) triple's first use, in order of
    first use; each corner's vertex: the rank of its triple), Mitsuba's vertex map."""
    corners = len(cv)
    # A position always used with the same uv and normal: its triples are its positions.
    same = True
    for other in (ct, cn):
        seen = np.empty(nv, dtype=np.int64)
        seen[cv] = other
        same = same and bool((seen[cv] == other).all())
    size = nv if same else nv * (nt + 1) * (nn + 1)
    if size >= 1 << 62:  # the triple as one integer would overflow: the rows themselves
        key = np.stack([cv, ct, cn], axis=1)
        _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    else:
        key = cv if same else (cv * (nt + 1) + (ct + 1)) * (nn + 1) + (cn + 1)
    if size <= max(4 * corners, 1 << 20):
        first_of = np.full(size, corners, dtype=np.int64)
        np.minimum.at(first_of, key, np.arange(corners))
        used = np.flatnonzero(first_of < corners)
        first = np.sort(first_of[used])
        rank = np.empty(size, dtype=np.int64)
        rank[key[first]] = np.arange(len(first))
        return first, rank[key]
    if size < 1 << 62:
        _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return first[order], rank[inverse.reshape(-1)]


def _read_obj_lines(path: Path, data: bytes, flip: bool) -> MeshData:
    """Parse an OBJ file line by line (the reference reading, and the one that names a
    problem's line)."""
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
# PLY
# ---------------------------------------------------------------------------

#: PLY's scalar types (Turk's names and the sized aliases), and the unofficial 64-bit and
#: half types Mitsuba's ply plugin also reads, as NumPy type codes (byte order added later).
_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "long": "i8", "int64": "i8", "ulong": "u8", "uint64": "u8",
    "half": "f2", "float16": "f2",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_PLY_FORMATS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}
#: Names of the face element's index list, and of the texture coordinates in the order
#: of preference of Mitsuba's ply plugin.
_INDEX_NAMES = ("vertex_indices", "vertex_index")
_UV_NAMES = (("u", "v"), ("texture_u", "texture_v"), ("s", "t"))
#: Elements whose data makes the mesh; the others are read (ascii: checked) and dropped.
_KEPT = ("vertex", "face")
#: A token of an integer-typed ascii property: optional sign, decimal digits.
_NOT_INTEGER = re.compile(rb"[^0-9+\-\s]")


@dataclass
class _Prop:
    name: str
    type: str               # the PLY type of the value (of the items, for a list)
    count_type: str | None  # the PLY type of a list's length; None for a scalar

    @property
    def integer(self) -> bool:
        return _PLY_TYPES[self.type][0] in "iu"


@dataclass
class _Element:
    name: str
    count: int
    props: list[_Prop]


#: What is read of one element: per property, a column of values (a scalar) or the
#: (counts, flat items) of its lists; and, for an ascii file, the line of each record.
_Columns = dict[str, "np.ndarray | tuple[np.ndarray, np.ndarray]"]


def _read_ply(path: Path, fh, size: int, flip: bool, check_memory) -> MeshData:
    """Parse an ascii or binary PLY file (Turk's format): its header to the letter, then
    the body, every element in turn; elements other than vertex and face are dropped."""
    fh.seek(0)
    data = fh.read(size)  # a sized read: several times faster than reading to the end
    fmt, elements, body, header_lines = _parse_ply_header(path, data, size)
    if fmt == "ascii":
        check_memory("text")
        reader = _PlyAscii(path, data[body:], header_lines)
    else:
        reader = _PlyBinary(path, data, body, _PLY_FORMATS[fmt])
    kept: dict[str, _Columns] = {}
    lines: dict[str, np.ndarray | None] = {}
    for el in elements:
        cols, rec_lines = reader.element(el, keep=el.name in _KEPT)
        if el.name in _KEPT:
            kept[el.name], lines[el.name] = cols, rec_lines
    reader.finish()
    elements_by_name = {el.name: el for el in elements}

    def where(element: str, row: int | None) -> int | None:
        """Line of record ``row`` of ``element`` in an ascii file."""
        rec = lines.get(element)
        return None if rec is None or row is None else int(rec[row])

    return _ply_mesh(path, kept, elements_by_name, flip, where)


def _parse_ply_header(path: Path, data: bytes, size: int
                      ) -> tuple[str, list[_Element], int, int]:
    """(format, elements, offset of the body, number of header lines) of a PLY file.

    Lines end in LF, CRLF or CR (the first line's ending is the file's); the
    grammar is Turk's: ``ply``, one ``format <ascii|binary_little_endian|
    binary_big_endian> 1.0``, then ``element <name> <count>`` lines each
    followed by its ``property <type> <name>`` and ``property list
    <length type> <item type> <name>`` lines, ``comment`` and ``obj_info``
    lines anywhere, and ``end_header``.
    """
    found = re.search(rb"(?:\A|[\r\n])end_header[ \t]*(\r\n|\r|\n|\Z)", data)
    if found is None:
        raise MeshError(path, "PLY header has no 'end_header' line")
    end, body = found.start(1), found.end(1)
    if found.group(1) == b"\r\n" and data[3:5] != b"\r\n":
        body -= 1  # lines end in CR: the LF is the body's first byte
    header = data[:end]
    lines = header.splitlines()
    if not header.isascii():
        at = next(i for i, b in enumerate(header) if b > 127)
        n = len(header[:at + 1].splitlines())
        text = lines[n - 1].decode("utf-8", errors="replace").strip()
        raise MeshError(path, f"PLY header line is not ASCII text: {text[:60]!r}", n)
    fmt = None
    elements: list[_Element] = []
    for lineno, raw in enumerate(lines, start=1):
        tok = raw.decode("ascii").split()
        text = raw.decode("ascii").strip()[:60]

        def bad(why: str, lineno: int = lineno, text: str = text) -> MeshError:
            return MeshError(path, f"malformed PLY header line ({why}): {text!r}", lineno)

        if lineno == 1:
            if tok != ["ply"]:
                raise bad("the first line must be 'ply' alone")
            continue
        if not tok or tok[0] in ("comment", "obj_info"):
            continue
        key = tok[0]
        if key == "end_header":
            if len(tok) != 1 or lineno != len(lines):
                raise bad("'end_header' stands alone on the last header line")
        elif key == "format":
            if fmt is not None:
                raise bad("a second 'format' line")
            if elements:
                raise bad("'format' must come before the elements")
            if len(tok) != 3 or tok[1] not in _PLY_FORMATS:
                raise bad("expected 'format ascii|binary_little_endian|binary_big_endian 1.0'")
            if tok[2] != "1.0":
                raise bad(f"PLY version {tok[2]!r}, only '1.0' exists")
            fmt = tok[1]
        elif key == "element":
            if len(tok) != 3:
                raise bad("expected 'element <name> <count>'")
            if not re.fullmatch(r"[0-9]+", tok[2]):
                raise bad(f"element count {tok[2]!r} is not a decimal integer")
            if any(el.name == tok[1] for el in elements):
                raise bad(f"two elements of the same name '{tok[1]}'")
            count = int(tok[2])
            if count > size:  # every record takes at least one byte
                raise MeshError(path, f"PLY header declares {count:,} '{tok[1]}' records, "
                                      f"more than a {size:,}-byte file can hold", lineno)
            elements.append(_Element(tok[1], count, []))
        elif key == "property":
            if not elements:
                raise bad("a property before any element")
            if len(tok) >= 2 and tok[1] == "list":
                if len(tok) != 5:
                    raise bad("expected 'property list <length type> <item type> <name>'")
                types, name = tok[2:4], tok[4]
            elif len(tok) == 3:
                types, name = tok[1:2], tok[2]
            else:
                raise bad("expected 'property <type> <name>'")
            for t in types:
                if t not in _PLY_TYPES:
                    raise bad(f"unknown PLY type {t!r}")
            if len(types) == 2 and _PLY_TYPES[types[0]][0] not in "iu":
                raise bad(f"a list's length must be of an integer type, not {types[0]!r}")
            if any(p.name == name for p in elements[-1].props):
                raise bad(f"two properties of the same name '{name}'")
            elements[-1].props.append(_Prop(name, types[-1],
                                            types[0] if len(types) == 2 else None))
        else:
            raise bad(f"unknown keyword {key!r}")
        if key != "format" and fmt is None:
            raise bad("the 'format' line must come first, after 'ply'")
    if fmt is None:
        raise MeshError(path, "PLY header has no 'format' line")
    return fmt, elements, body, len(lines)


def _record_layout(el: _Element) -> tuple[list[_Prop], int | None]:
    """(the list properties, the position of the only list among the properties or None)."""
    lists = [p for p in el.props if p.count_type]
    only = el.props.index(lists[0]) if len(lists) == 1 else None
    return lists, only


class _PlyBinary:
    """Reads the elements of a binary PLY body one after the other.

    Records of fixed size, and records whose lists all have the length of
    the first record's (triangle or quad meshes), are read in one piece;
    others (mixed polygons) record by record for their list lengths, then
    gathered in one piece.
    """

    def __init__(self, path: Path, data: bytes, offset: int, order: str):
        self.path, self.data, self.offset, self.order = path, data, offset, order
        self.buf = np.frombuffer(data, dtype=np.uint8)

    def _dtype(self, t: str) -> np.dtype:
        return np.dtype(self.order + _PLY_TYPES[t])

    def _ends(self, el: _Element, row: int) -> MeshError:
        return MeshError(self.path, f"PLY file ends inside element '{el.name}' (after "
                                    f"{row:,} of {el.count:,} records)")

    def element(self, el: _Element, keep: bool) -> tuple[_Columns, None]:
        lists, _ = _record_layout(el)
        if not lists or el.count == 0:
            return self._fixed(el, [None] * len(el.props), keep), None
        first = self._first_lengths(el)
        if first is not None:
            cols = self._fixed(el, first, keep, check=True)
            if cols is not None:
                return cols, None
        return self._walk(el, keep), None

    def _first_lengths(self, el: _Element) -> list[int | None] | None:
        """Lengths of the first record's lists (None for scalars), or None if it is cut."""
        off, out = self.offset, []
        for p in el.props:
            if p.count_type:
                dt = self._dtype(p.count_type)
                if off + dt.itemsize > len(self.data):
                    return None
                n = int(np.frombuffer(self.data, dt, 1, off)[0])
                if n < 0:
                    return None
                out.append(n)
                off += dt.itemsize + n * self._dtype(p.type).itemsize
            else:
                out.append(None)
                off += self._dtype(p.type).itemsize
        return out

    def _fixed(self, el: _Element, lengths: list[int | None], keep: bool,
               check: bool = False) -> _Columns | None:
        """Every record laid out alike (lists of the given lengths): one structured read.
        With ``check``, None when some list's length differs (or the body is too short
        to tell)."""
        fields, itemsize = [], 0
        for i, (p, n) in enumerate(zip(el.props, lengths, strict=True)):
            if n is None:
                fields.append((f"p{i}", self._dtype(p.type)))
                itemsize += self._dtype(p.type).itemsize
            else:
                fields.append((f"c{i}", self._dtype(p.count_type)))
                itemsize += self._dtype(p.count_type).itemsize + n * self._dtype(p.type).itemsize
                if n:
                    fields.append((f"p{i}", self._dtype(p.type), (n,)))
        left = len(self.data) - self.offset
        if itemsize == 0:  # an element without properties holds no bytes
            return {}
        if itemsize * el.count > left:
            if check:
                return None
            raise self._ends(el, left // itemsize)
        rec = np.frombuffer(self.data, np.dtype(fields), el.count, self.offset)
        for i, n in enumerate(lengths):
            if n is not None and np.any(rec[f"c{i}"] != n):
                return None
        self.offset += itemsize * el.count
        if not keep:
            return {}
        out: _Columns = {}
        for i, (p, n) in enumerate(zip(el.props, lengths, strict=True)):
            if n is None:
                out[p.name] = rec[f"p{i}"]
            else:
                flat = (rec[f"p{i}"].reshape(-1) if n else np.zeros(0, self._dtype(p.type)))
                out[p.name] = (np.full(el.count, n, dtype=np.int64), flat)
        return out

    def _walk(self, el: _Element, keep: bool) -> _Columns:
        """Records with lists of varying lengths: the offsets found record by record (the
        lengths decide where the next value is), the values then gathered at once."""
        data, n_bytes = self.data, len(self.data)
        # The record as runs: bytes of scalars, then a list (length unpacker, sizes), ...
        steps: list[tuple[int, object, int, int]] = []
        fixed = 0
        for p in el.props:
            if p.count_type:
                cdt = self._dtype(p.count_type)
                steps.append((fixed, struct.Struct(self.order + cdt.char).unpack_from,
                              cdt.itemsize, self._dtype(p.type).itemsize))
                fixed = 0
            else:
                fixed += self._dtype(p.type).itemsize
        tail = fixed
        k = len(steps)
        starts = np.empty((el.count, k), dtype=np.int64)  # offset of each list's length
        lengths = np.empty((el.count, k), dtype=np.int64)
        off = self.offset
        for r in range(el.count):
            for j, (before, unpack, csize, isize) in enumerate(steps):
                off += before
                if off + csize > n_bytes:
                    raise self._ends(el, r)
                n = unpack(data, off)[0]
                if n < 0:
                    raise MeshError(self.path, f"PLY element '{el.name}', record {r}: a list "
                                               f"of negative length {n}")
                starts[r, j], lengths[r, j] = off, n
                off += csize + n * isize
            off += tail
            if off > n_bytes:
                raise self._ends(el, r)
        record_start = starts[:, 0] - steps[0][0]
        self.offset = off
        if not keep:
            return {}
        out: _Columns = {}
        at = record_start  # offset of the current property in each record
        j = 0
        for p in el.props:
            dt = self._dtype(p.type)
            if p.count_type:
                _, _, csize, isize = steps[j]
                n = lengths[:, j]
                first = starts[:, j] + csize
                total = int(n.sum())
                item = np.arange(total) - np.repeat(np.cumsum(n) - n, n)
                out[p.name] = (n, self._gather(np.repeat(first, n) + item * isize, dt))
                at = first + n * isize
                j += 1
            else:
                out[p.name] = self._gather(at, dt)
                at = at + dt.itemsize
        return out

    def _gather(self, offsets: np.ndarray, dt: np.dtype) -> np.ndarray:
        """The values of type ``dt`` at these byte offsets of the file."""
        idx = offsets[:, None] + np.arange(dt.itemsize)
        return self.buf[idx].reshape(-1).view(dt)

    def finish(self) -> None:
        # Mitsuba refuses trailing bytes too; a few newline bytes some writers append are fine.
        tail = self.data[self.offset:self.offset + 4097]
        if len(tail) > 4096 or tail.strip(b"\r\n\x00 "):
            raise MeshError(self.path, "PLY file has data after its last element")


class _PlyAscii:
    """Reads the elements of an ascii PLY body: one record a line (blank lines skipped),
    each number of the type the header declares for it."""

    def __init__(self, path: Path, body: bytes, header_lines: int):
        self.path, self.header_lines = path, header_lines
        if not body.isascii():
            at = next(i for i, b in enumerate(body) if b > 127)
            raise MeshError(path, "the PLY body is not ASCII text (a number must be plain "
                                  "ASCII decimals)", header_lines + len(body[:at + 1].splitlines()))
        if b"_" in body:  # Python reads '1_0' as 10; it is not a PLY number
            at = body.index(b"_")
            raise MeshError(path, "malformed number in the PLY body (a '_' in it)",
                            header_lines + len(body[:at + 1].splitlines()))
        # One pass over the bytes: where each token starts, on which line, so that the
        # records (non-blank lines) and their widths are known before any number is read.
        body = body.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
        self.body = body
        self.tokens = body.split()
        c = np.frombuffer(body, dtype=np.uint8)
        space = (c == 32) | ((c >= 9) & (c <= 12))  # what bytes.split() splits at
        first = ~space
        first[1:] &= space[:-1]
        newlines = np.flatnonzero(c == 10)
        line = np.searchsorted(newlines, np.flatnonzero(first), side="right")
        widths = np.bincount(line, minlength=len(newlines) + 1)
        self.records = np.flatnonzero(widths)  # the body lines that hold a record
        self.widths = widths[self.records]
        self.first_token = np.concatenate(([0], np.cumsum(self.widths)))
        self.line_start = np.concatenate(([0], newlines + 1))  # byte offset of each line
        self.next = 0  # the next record (index into self.records)

    def element(self, el: _Element, keep: bool) -> tuple[_Columns, np.ndarray]:
        a, b = self.next, self.next + el.count
        if b > len(self.records):
            raise MeshError(self.path, f"PLY file ends inside element '{el.name}' (after "
                                       f"{len(self.records) - a:,} of {el.count:,} records)")
        self.next = b
        rows = self.records[a:b]
        lines = self.header_lines + rows + 1  # 1-based line of each record
        widths = self.widths[a:b]
        tokens = self.tokens[self.first_token[a]:self.first_token[b]]
        span = ((int(self.line_start[rows[0]]), int(self.line_start[rows[-1] + 1])
                 if rows[-1] + 1 < len(self.line_start) else len(self.body))
                if len(rows) else (0, 0))
        starts = self.first_token[a:b] - self.first_token[a]  # each record's first token
        record = np.repeat(np.arange(el.count), widths)  # record of each token
        prop, is_count, lengths = self._layout(el, tokens, widths, starts, record, lines)
        values = self._numbers(el, tokens, span, record, prop, is_count, lengths, lines)
        if not keep:
            return {}, lines
        cols: _Columns = {}
        for i, p in enumerate(el.props):
            if p.count_type:
                cols[p.name] = (lengths[p.name], values[(prop == i) & ~is_count])
            else:
                cols[p.name] = values[prop == i]
        return cols, lines

    def _fail(self, el: _Element, r: int, message: str, lines: np.ndarray) -> MeshError:
        return MeshError(self.path, f"element '{el.name}', record {r}: {message}",
                         int(lines[r]))

    def _layout(self, el, tokens, widths, starts, record, lines):
        """(property of each token, whether it is a list's length, each list property's
        lengths): from the line widths alone when a record has at most one list (its
        length is what the line holds beyond the scalars), record by record otherwise."""
        lists, only = _record_layout(el)
        scalars = len(el.props) - len(lists)
        short = "the line ends early (a PLY record is one line)"
        extra = "more numbers on the line than the header declares"
        j = np.arange(len(tokens)) - starts[record]  # position of each token in its record
        if not lists:
            bad = widths != scalars
            if bad.any():
                r = int(np.argmax(bad))
                raise self._fail(el, r, short if widths[r] < scalars else extra, lines)
            return j, np.zeros(len(tokens), dtype=bool), {}
        if only is not None:
            if (widths < scalars + 1).any():
                raise self._fail(el, int(np.argmax(widths < scalars + 1)), short, lines)
            n = widths - scalars - 1  # checked against the lengths written, once read
            nr = n[record]
            prop = np.where(j <= only, j, np.where(j <= only + nr, only, j - nr))
            return prop, j == only, {lists[0].name: n}
        # Several lists a record: walk each record.
        prop = np.empty(len(tokens), dtype=np.int64)
        is_count = np.zeros(len(tokens), dtype=bool)
        lengths: dict[str, list[int]] = {p.name: [] for p in lists}
        for r in range(el.count):
            k, end = int(starts[r]), int(starts[r] + widths[r])
            for i, p in enumerate(el.props):
                if k >= end:
                    raise self._fail(el, r, short, lines)
                prop[k] = i
                if p.count_type:
                    is_count[k] = True
                    try:
                        n = int(tokens[k])
                    except ValueError:
                        n = 0  # not an integer: refused with the numbers below
                    if n < 0 or k + 1 + n > end:
                        raise self._fail(el, r, short if n >= 0 else
                                         f"a list of negative length {n}", lines)
                    prop[k + 1:k + 1 + n] = i
                    lengths[p.name].append(n)
                    k += 1 + n
                else:
                    k += 1
            if k != end:
                raise self._fail(el, r, extra, lines)
        return prop, is_count, {name: np.asarray(v, dtype=np.int64)
                                for name, v in lengths.items()}

    def _numbers(self, el, tokens, span, record, prop, is_count, lengths, lines
                 ) -> np.ndarray:
        """The tokens as numbers of their declared types (float64 holding them): integers
        plain decimal integers in their type's range, floats rounded to their type. The
        first bad token is refused naming its record, property and line; a list whose
        written length is not what its line holds, naming its record and line."""
        type_of = {}  # (property, is a length) -> PLY type
        for i, p in enumerate(el.props):
            type_of[i, False] = p.type
            if p.count_type:
                type_of[i, True] = p.count_type
        codes = sorted(set(type_of.values()))
        code = np.zeros(len(tokens), dtype=np.int64)  # index into codes of each token
        for (i, count), t in type_of.items():
            code[(prop == i) & (is_count == count)] = codes.index(t)
        integer = np.array([_PLY_TYPES[t][0] in "iu" for t in codes])[code] if len(tokens) \
            else np.zeros(0, dtype=bool)

        def refuse(k: int, why: str | None = None) -> MeshError:
            r, p = int(record[k]), el.props[int(prop[k])]
            tok = tokens[k].decode("ascii")[:30]
            what = f"a list length of '{p.name}'" if is_count[k] else f"property '{p.name}'"
            if why is None:
                why = (f"expected {'an integer' if integer[k] else 'a number'} in {what}, "
                       f"got {tok!r}")
            return self._fail(el, r, why, lines)

        try:
            values = np.array(tokens, dtype=np.float64) if tokens else np.zeros(0)
        except ValueError:
            for k, tok in enumerate(tokens):
                try:
                    float(tok)
                except ValueError:
                    raise refuse(k) from None
            raise
        def lengths_match(final: bool) -> None:
            """Each list as long as its line says (before the type checks: where the
            written length is a count at all; after them: everywhere)."""
            for name, n in lengths.items():
                i = next(i for i, p in enumerate(el.props) if p.name == name)
                stated = values[(prop == i) & is_count]
                bad = stated != n
                if not final:
                    bad &= (stated >= 0) & (stated == np.floor(stated))
                if bad.any():
                    r = int(np.argmax(bad))
                    raise self._fail(el, r, f"a list of negative length {stated[r]:g}"
                                     if stated[r] < 0 else
                                     "the line ends early (a PLY record is one line)"
                                     if stated[r] > n[r] else
                                     "more numbers on the line than the header declares",
                                     lines)

        lengths_match(final=False)
        if integer.any():
            if integer.all():
                plain = _NOT_INTEGER.search(self.body, *span) is None
                ok = np.ones(len(tokens), dtype=bool) if plain else np.array(
                    [_NOT_INTEGER.search(t) is None for t in tokens])
            else:
                ok = np.ones(len(tokens), dtype=bool)
                sel = np.flatnonzero(integer)
                ok[sel] = [_NOT_INTEGER.search(tokens[k]) is None for k in sel.tolist()]
            if not ok.all():
                raise refuse(int(np.argmin(ok)))
        for c, t in enumerate(codes):
            dt = np.dtype(_PLY_TYPES[t])
            sel = code == c
            if dt.kind in "iu":
                info = np.iinfo(dt)
                out = sel & ((values < info.min) | (values > info.max))
                if out.any():
                    k = int(np.argmax(out))
                    raise refuse(k, f"{tokens[k].decode('ascii')[:30]} does not fit the "
                                    f"PLY type '{t}' of "
                                    + (f"a list length of '{el.props[int(prop[k])].name}'"
                                       if is_count[k] else
                                       f"property '{el.props[int(prop[k])].name}'"))
            elif dt != np.float64 and sel.any():
                with np.errstate(over="ignore"):
                    values[sel] = values[sel].astype(dt)
        lengths_match(final=True)
        return values

    def finish(self) -> None:
        if self.next < len(self.records):
            raise MeshError(self.path, "PLY file has data after its last element",
                            self.header_lines + int(self.records[self.next]) + 1)


def _ply_mesh(path: Path, elements: dict[str, _Columns], declared: dict[str, _Element],
              flip: bool, where) -> MeshData:
    """The mesh of a parsed PLY file: its 'vertex' and 'face' elements, checked, values
    rounded to float32 as Mitsuba stores them."""
    if "vertex" not in elements:
        raise MeshError(path, "PLY file has no 'vertex' element")
    vert = elements["vertex"]
    for c in "xyz":
        if not isinstance(vert.get(c), np.ndarray):
            raise MeshError(path, f"PLY vertex element has no property '{c}'")

    def column_block(cols) -> np.ndarray:
        return np.stack([np.asarray(vert[c], dtype=np.float64) for c in cols], axis=1)

    def checked(cols, what, normal=False) -> np.ndarray:
        a = column_block(cols)
        bad = _first_bad(a, normal)
        if bad is not None:
            raise MeshError(path, f"PLY vertex {bad[0]}: the {what} {_show_row(a, bad[0])} "
                                  f"{bad[1]}", where("vertex", bad[0]))
        if all(vert[c].dtype == np.float32 for c in cols):
            return a  # float32 values already
        return a.astype(np.float32).astype(np.float64)

    def scalar(name: str) -> bool:
        return isinstance(vert.get(name), np.ndarray)

    vertices = checked("xyz", "position")
    normals = uvs = None
    if all(scalar(c) for c in ("nx", "ny", "nz")):
        normals = _normalized(checked(("nx", "ny", "nz"), "normal", normal=True))
    for un, vn in _UV_NAMES:
        if scalar(un) and scalar(vn):
            uvs = checked((un, vn), "texture coordinate")
            if flip:
                uvs[:, 1] = 1.0 - uvs[:, 1]
            break

    if "face" not in elements:
        raise MeshError(path, "the mesh has no faces (no 'face' element)")
    face = elements["face"]
    key = next((k for k in _INDEX_NAMES if isinstance(face.get(k), tuple)), None)
    if key is None:
        raise MeshError(path, "PLY face element has no 'vertex_indices' (or 'vertex_index') "
                              "list")
    counts, flat = face[key]
    counts = np.asarray(counts, dtype=np.int64)
    if len(counts) and counts.min() < 3:
        k = int(np.argmax(counts < 3))
        raise MeshError(path, f"PLY face {k} has fewer than 3 vertices", where("face", k))

    def face_of(i: int) -> int:
        return int(np.searchsorted(np.cumsum(counts), i, side="right"))

    item_type = next(p.type for p in declared["face"].props if p.name == key)
    if _PLY_TYPES[item_type][0] == "f":  # a float index list: only integers name a vertex
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
