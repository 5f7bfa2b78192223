"""Parsed meshes and built BVHs kept on disk (issue 33): data only, checked when read.

A process that loads a large mesh another process loaded before reads the parse
(tracer/meshio.py) and the tree (tracer/bvh.py) from ``~/.cache/whitted`` instead
of making them again. The laws, as for the other caches (test_cache_safety.py):
an entry is used only when it holds what the reader or the builder could have
made; anything else is made again and replaced, never fatal. The thresholds
(a 1 MiB file, 32,768 triangles) are lowered here so that small meshes use the
caches.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from whitted.tracer import bvh, cache, meshio
from whitted.tracer.meshio import load_mesh


@pytest.fixture
def home(tmp_path, monkeypatch):
    """whitted's cache folder in tmp_path, the thresholds at zero, memory caches empty."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    monkeypatch.setattr(meshio, "DISK_MIN_BYTES", 0)
    monkeypatch.setattr(meshio, "DISK_MIN_FACES", 0)
    monkeypatch.setattr(bvh, "DISK_MIN_TRIANGLES", 0)
    meshio.clear_cache()
    bvh._RECENT.clear()
    yield tmp_path / "xdg" / "whitted"
    meshio.clear_cache()
    bvh._RECENT.clear()


def _sphere_obj(path, n=12):
    """A UV sphere as OBJ (v, vt, vn, v/vt/vn faces): positions, uvs and normals to keep."""
    th, ph = np.meshgrid(np.linspace(0.1, 3.0, n), np.linspace(0, 2 * np.pi, n, endpoint=False),
                         indexing="ij")
    p = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1).reshape(-1, 3)
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in p]
    lines += [f"vt {i / len(p):.6f} 0.5" for i in range(len(p))]
    lines += [f"vn {x:.6f} {y:.6f} {z:.6f}" for x, y, z in p]
    for i in range(n - 1):
        for j in range(n):
            a, b = i * n + j + 1, i * n + (j + 1) % n + 1
            c, d = a + n, b + n
            lines += [f"f {a}/{a}/{a} {b}/{b}/{b} {d}/{d}/{d}",
                      f"f {a}/{a}/{a} {d}/{d}/{d} {c}/{c}/{c}"]
    path.write_text("\n".join(lines) + "\n")
    return path


def _entries(folder):
    return sorted(folder.glob("*.arrays")) if folder.exists() else []


def _no_parse(monkeypatch):
    def refuse(*a, **k):
        raise AssertionError("parsed again")
    monkeypatch.setattr(meshio, "_read_mesh", refuse)


# ------------------------------------------------------------------ meshes


def test_a_mesh_read_again_comes_from_its_entry_and_equals_the_parse(home, tmp_path,
                                                                     monkeypatch):
    path = _sphere_obj(tmp_path / "s.obj")
    first = load_mesh(path)
    [entry] = _entries(home / "meshes")
    assert os.stat(entry).st_mode & 0o777 == 0o600
    meshio.clear_cache()
    with monkeypatch.context() as m:
        _no_parse(m)
        again = load_mesh(path)
    for a, b in ((first.vertices, again.vertices), (first.faces, again.faces),
                 (first.normals, again.normals), (first.uvs, again.uvs)):
        np.testing.assert_array_equal(a, b)
        assert not b.flags.writeable
    # the flip option is part of the key: another entry, the parse's own uvs
    meshio.clear_cache()
    kept = load_mesh(path, flip_tex_coords=False)
    np.testing.assert_array_equal(kept.uvs[:, 1], 1 - first.uvs[:, 1])
    assert len(_entries(home / "meshes")) == 2


@pytest.mark.parametrize("kind", ["obj", "ply"])
def test_a_mesh_kept_on_disk_is_read_once_hashed_and_parsed_from_the_same_bytes(
        home, tmp_path, monkeypatch, kind):
    # A file that misses the cache is read once: the bytes hashed for its entry are the
    # bytes parsed. Its parse equals the reader's own, without the cache.
    import builtins

    path = _sphere_obj(tmp_path / "s.obj")
    if kind == "ply":
        m = load_mesh(path, flip_tex_coords=False)
        meshio.write_ply(tmp_path / "s.ply", m.vertices, m.faces)
        path = tmp_path / "s.ply"
    meshio.clear_cache()
    opened, real_open = [], builtins.open

    def counting_open(file, *a, **k):
        if os.fspath(file) == os.fspath(path):
            opened.append(file)
        return real_open(file, *a, **k)

    with monkeypatch.context() as m:
        m.setattr(builtins, "open", counting_open)
        cached = load_mesh(path)
    assert len(opened) == 1
    assert len(_entries(home / "meshes")) == (2 if kind == "ply" else 1)
    plain = meshio._read_mesh(path, os.stat(path).st_size, None)
    for a, b in ((plain.vertices, cached.vertices), (plain.faces, cached.faces),
                 (plain.normals, cached.normals), (plain.uvs, cached.uvs)):
        np.testing.assert_array_equal(a, b)


def test_a_copy_of_the_file_elsewhere_uses_the_same_entry(home, tmp_path, monkeypatch):
    path = _sphere_obj(tmp_path / "s.obj")
    load_mesh(path)
    copy = tmp_path / "elsewhere" / "copy.obj"
    copy.parent.mkdir()
    copy.write_bytes(path.read_bytes())
    with monkeypatch.context() as m:
        _no_parse(m)
        load_mesh(copy)
    assert len(_entries(home / "meshes")) == 1


def _tamper_mesh(entry, how):
    a = cache.read_arrays(entry, meshio._DISK_KINDS, meshio._DISK_OPTIONAL)
    a = {k: np.array(v) for k, v in a.items()}
    if how == "index out of range":
        a["faces"][3, 1] = len(a["vertices"])
    elif how == "negative index":
        a["faces"][0, 0] = -1
    elif how == "not finite":
        a["vertices"][2, 0] = np.nan
    elif how == "beyond float32":
        a["vertices"][2, 0] = 1e39
    elif how == "zero normal":
        a["normals"][1] = 0
    elif how == "uvs of another shape":
        a["uvs"] = a["uvs"][:-1]
    elif how == "faces as float":
        a["faces"] = a["faces"].astype(np.float64)
    if how == "truncated":
        data = cache.pack_arrays(a)[:-8]
    elif how == "table claims more":
        data = cache.pack_arrays(a) + b"\0" * 8
    else:
        try:
            data = cache.pack_arrays(a)
        except ValueError:
            return False
    entry.write_bytes(data)
    return True


@pytest.mark.parametrize("how", ["index out of range", "negative index", "not finite",
                                 "beyond float32", "zero normal", "uvs of another shape",
                                 "faces as float", "truncated", "table claims more"])
def test_a_tampered_mesh_entry_is_parsed_again_and_replaced(home, tmp_path, how):
    path = _sphere_obj(tmp_path / "s.obj")
    good = load_mesh(path)
    [entry] = _entries(home / "meshes")
    assert _tamper_mesh(entry, how)
    assert meshio._disk_read(entry) is None
    meshio.clear_cache()
    again = load_mesh(path)
    np.testing.assert_array_equal(again.faces, good.faces)
    np.testing.assert_array_equal(again.vertices, good.vertices)
    assert meshio._disk_read(entry) is not None   # replaced by the new parse


def test_an_entry_others_may_write_is_not_read(home, tmp_path, monkeypatch):
    path = _sphere_obj(tmp_path / "s.obj")
    load_mesh(path)
    [entry] = _entries(home / "meshes")
    os.chmod(entry, 0o666)
    assert meshio._disk_read(entry) is None
    os.chmod(entry, 0o600)
    os.chmod(entry.parent, 0o777)
    assert meshio._disk_read(entry) is None


def test_small_files_stay_off_the_disk(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    meshio.clear_cache()
    load_mesh(_sphere_obj(tmp_path / "s.obj"))
    assert not (tmp_path / "xdg" / "whitted" / "meshes").exists()
    meshio.clear_cache()


def test_vertex_normals_come_from_their_entry_and_a_wrong_one_is_computed_again(
        home, tmp_path, monkeypatch):
    m = load_mesh(_sphere_obj(tmp_path / "s.obj"))
    v = m.vertices * 2.0 + 1.0          # as a placed mesh's vertices
    first = meshio.vertex_normals(v, m.faces)
    np.testing.assert_array_equal(first, meshio.compute_vertex_normals(v, m.faces))
    entries = set(_entries(home / "meshes"))
    with monkeypatch.context() as mp:
        mp.setattr(meshio, "compute_vertex_normals", lambda *a: pytest.fail("computed"))
        np.testing.assert_array_equal(meshio.vertex_normals(v, m.faces), first)
    [entry] = [e for e in entries if cache.read_arrays(e, {"normals": "<f8"}) is not None]
    bad = first.copy()
    bad[0] *= 1.5                         # not a unit normal: not what the code computes
    entry.write_bytes(cache.pack_arrays({"normals": bad}))
    np.testing.assert_array_equal(meshio.vertex_normals(v, m.faces), first)
    np.testing.assert_array_equal(cache.read_arrays(entry, {"normals": "<f8"})["normals"],
                                  first)
    # other vertices (another placement): another entry
    meshio.vertex_normals(v * 3.0, m.faces)
    assert len(_entries(home / "meshes")) == len(entries) + 1


# ------------------------------------------------------------------ trees


def _knot_corners(tmp_path):
    import sys

    from conftest import SCENES
    sys.path.insert(0, str(SCENES / "meshes"))
    from generate import torus_knot
    v, f = torus_knot(40, 12)
    return [np.asarray(v, np.float64)[f[:, k]] for k in range(3)]


def test_a_tree_read_again_comes_from_its_entry_and_equals_the_build(home, tmp_path,
                                                                     monkeypatch):
    p = _knot_corners(tmp_path)
    built = bvh.shared_bvh(*p)
    [entry] = _entries(home / "bvh")
    bvh._RECENT.clear()
    with monkeypatch.context() as m:
        m.setattr(bvh, "build_bvh", lambda *a, **k: pytest.fail("built again"))
        read = bvh.shared_bvh(*p)
    for k in ("lo", "hi", "left", "right", "start", "count", "order"):
        np.testing.assert_array_equal(getattr(built.arrays, k), getattr(read.arrays, k))
    assert read.depth == built.depth
    np.testing.assert_array_equal(built.nodes.numpy(), read.nodes.numpy())
    # other corners: another entry
    bvh._RECENT.clear()
    bvh.shared_bvh(*[q + 1.0 for q in p])
    assert len(_entries(home / "bvh")) == 2


def _mutations(b: bvh.BVHArrays, n: int, corners):
    """(what, arrays) with one invariant of a tree broken, each a way a walk goes wrong
    (``corners``: the triangles' p0, p1, p2)."""
    inner = np.flatnonzero(b.left >= 0)
    leaves = np.flatnonzero(b.left < 0)

    def changed(**kw):
        arrays = {k: np.array(getattr(b, k)) for k in ("lo", "hi", "left", "right", "start",
                                                       "count", "order")}
        for k, f in kw.items():
            f(arrays[k]) if callable(f) else arrays.__setitem__(k, f)
        return bvh.BVHArrays(**arrays, depth=kw.get("depth_", b.depth), seconds=0.0)

    i, j = inner[-1], leaves[0]
    yield "child before its parent (a cycle)", changed(left=lambda a: a.__setitem__(i, 0))
    yield "child out of range", changed(right=lambda a: a.__setitem__(i, len(a)))
    yield "a node with two parents", changed(right=lambda a: a.__setitem__(
        inner[0], b.left[inner[0]] if b.left[inner[0]] > inner[0] else a[inner[0]]))
    yield "children swapped (not depth-first)", changed(
        left=lambda a: a.__setitem__(inner[0], b.right[inner[0]]),
        right=lambda a: a.__setitem__(inner[0], b.left[inner[0]]))
    yield "leaf past the triangles", changed(start=lambda a: a.__setitem__(j, n))
    two = leaves[b.count[leaves] == b.count[j]][:2]   # two leaves of one size, ranges swapped
    yield "leaves' ranges out of node order", changed(
        start=lambda a: a.__setitem__(two, a[two[::-1]]))
    yield "empty leaf", changed(count=lambda a: a.__setitem__(j, 0))
    yield "leaf over the count field", changed(count=lambda a: a.__setitem__(j, 8))
    yield "order not a permutation", changed(order=lambda a: a.__setitem__(0, a[1]))
    yield "order out of range", changed(order=lambda a: a.__setitem__(0, n))
    yield "a leaf's box misses a triangle", changed(hi=lambda a: a.__setitem__(
        (j, 0), np.nextafter(_leaf_corner_x(b, corners, j), -np.inf, dtype=np.float32)))
    yield "a child outside its parent's box", changed(lo=lambda a: a.__setitem__(
        (b.left[i], 1), np.float32(a[i, 1] - 1)))
    yield "a right child outside its parent's box", changed(hi=lambda a: a.__setitem__(
        (b.right[inner[0]], 2), np.float32(a[inner[0], 2] + 1)))
    yield "a box not finite", changed(lo=lambda a: a.__setitem__((0, 2), np.nan))
    yield "arrays of another length", changed(order=lambda a: None, count=b.count[:-1].copy())


def _leaf_corner_x(b: bvh.BVHArrays, corners, j: int) -> np.float32:
    """The largest x of leaf ``j``'s triangles' corners, rounded to float32 as the
    traversal's records hold them."""
    tris = b.order[b.start[j]:b.start[j] + b.count[j]]
    return max(np.float32(c[t, 0]) for c in corners for t in tris)


def test_every_broken_invariant_fails_the_check(tmp_path):
    """Each broken invariant fails the check, and a leaf's box that meets its triangles'
    largest float32 corner exactly still holds them."""
    p = _knot_corners(tmp_path)
    b = bvh.build_bvh(*p)
    assert bvh.valid_arrays(b, *p)
    for what, bad in _mutations(b, len(p[0]), p):
        assert not bvh.valid_arrays(bad, *p), what
    deeper = bvh.BVHArrays(b.lo, b.hi, b.left, b.right, b.start, b.count, b.order,
                           b.depth + 1, 0.0)
    assert not bvh.valid_arrays(deeper, *p), "depth"   # the traversal stack's size
    # the same tree over moved triangles: boxes no longer hold them
    assert not bvh.valid_arrays(b, *[q + 0.01 for q in p])
    j = np.flatnonzero(b.left < 0)[0]
    tight = bvh.BVHArrays(b.lo, b.hi.copy(), b.left, b.right, b.start, b.count, b.order,
                          b.depth, 0.0)
    tight.hi[j, 0] = _leaf_corner_x(b, p, j)
    assert bvh.valid_arrays(tight, *p)


def test_a_tampered_tree_is_built_again_and_replaced(home, tmp_path, monkeypatch):
    p = _knot_corners(tmp_path)
    built = bvh.shared_bvh(*p)
    [entry] = _entries(home / "bvh")
    a = cache.read_arrays(entry, bvh._ARRAY_KINDS)
    a = {k: np.array(v) for k, v in a.items()}
    a["hi"][np.flatnonzero(a["right"] < 0)[0]] -= 0.5   # a leaf's box misses its triangles
    entry.write_bytes(cache.pack_arrays(a))
    bvh._RECENT.clear()
    calls = []
    real = bvh.build_bvh
    monkeypatch.setattr(bvh, "build_bvh", lambda *x, **k: calls.append(1) or real(*x, **k))
    again = bvh.shared_bvh(*p)
    assert calls == [1]
    np.testing.assert_array_equal(again.arrays.hi, built.arrays.hi)
    stored = cache.read_arrays(entry, bvh._ARRAY_KINDS)
    np.testing.assert_array_equal(stored["hi"], built.arrays.hi)


def test_pack_arrays_refuses_objects_and_read_arrays_refuses_other_names(tmp_path):
    with pytest.raises(ValueError):
        cache.pack_arrays({"x": np.array([object()])})
    path = tmp_path / "e.arrays"
    path.write_bytes(cache.pack_arrays({"x": np.arange(3.0)}))
    os.chmod(path, 0o600)
    assert cache.read_arrays(path, {"x": "<f8"})["x"].tolist() == [0.0, 1.0, 2.0]
    assert cache.read_arrays(path, {"y": "<f8"}) is None
    assert cache.read_arrays(path, {"x": "<f4"}) is None
    assert cache.read_arrays(path, {"x": "<f8"}, limit=16) is None
    path.write_bytes(b"\x93NUMPY" + path.read_bytes())
    assert cache.read_arrays(path, {"x": "<f8"}) is None
    # written from each array's memory, the same bytes as pack_arrays
    arrays = {"a": np.arange(5, dtype=np.int64)[::2], "b": np.zeros((0, 3)),
              "c": np.ones((2, 3), np.float32)}
    streamed = tmp_path / "s.arrays"
    assert cache.write_arrays(streamed, arrays)
    assert streamed.read_bytes() == cache.pack_arrays(arrays)
    assert os.stat(streamed).st_mode & 0o777 == 0o600
    assert not cache.write_arrays(tmp_path / "o.arrays", {"x": np.array([object()])})
    assert not (tmp_path / "o.arrays").exists()


def test_prune_keeps_the_cache_under_its_bound_dropping_the_least_recently_used(tmp_path):
    folder = tmp_path / "c"
    folder.mkdir()
    for k in range(4):
        (folder / f"{k}.arrays").write_bytes(b"x" * 100)
        os.utime(folder / f"{k}.arrays", ns=(k * 10**9, k * 10**9))
    cache.prune(folder, 250, keep=folder / "0.arrays")
    assert sorted(p.name for p in folder.iterdir()) == ["0.arrays", "3.arrays"]


# ------------------------------------------------------------------ placed meshes


def test_a_placed_mesh_keys_its_normals_and_tree_by_its_file_and_its_placement(
        home, tmp_path, monkeypatch):
    """A mesh file kept parsed on disk carries that entry's key (MeshData.key); a placed
    mesh's key (shapes.mesh._placed_key) hashes it with to_world, and keys its vertex
    normals and its tree instead of a hash of the arrays (issue 33). Two placements of
    one file under different non-uniform scales have other vertices and other normals:
    read back from the disk, each still gets its own, and a new file its own key."""
    from whitted.tracer import load_scene
    from whitted.tracer.shapes import mesh

    rng = np.random.default_rng(4)
    v = rng.normal(size=(60, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)            # points on a sphere
    f = np.array([[0, i, i + 1] for i in range(1, 59)] + [[5, 17, 40], [3, 9, 33]])
    meshio.write_ply(tmp_path / "blob.ply", v, f)
    (tmp_path / "s.toml").write_text(
        "[camera]\norigin = [0, 0, 5]\ntarget = [0, 0, 0]\nfov = 40\n"
        "[materials.m]\ntype = \"diffuse\"\nreflectance = 0.5\n"
        + "".join(f"[[shapes]]\ntype = \"mesh\"\nfile = \"blob.ply\"\nmaterial = \"m\"\n"
                  f"to_world = [ {{ scale = {s} }} ]\n"
                  for s in ("[1, 1, 3]", "[3, 1, 1]")))

    def meshes():
        meshio.clear_cache()
        return [s for s in load_scene(tmp_path / "s.toml").shapes if isinstance(s, mesh.Mesh)]

    first = meshes()
    assert first[0].key and first[1].key and first[0].key != first[1].key
    assert meshio.load_mesh(tmp_path / "blob.ply").key is not None
    with monkeypatch.context() as mp:     # from the disk, keyed by file and placement
        mp.setattr(meshio, "compute_vertex_normals", lambda *a: pytest.fail("computed"))
        again = meshes()
    for a, b in zip(first, again, strict=True):
        assert a.key == b.key
        want = meshio.compute_vertex_normals(b.vertices, b.faces)
        want /= np.maximum(np.linalg.norm(want, axis=1, keepdims=True), 1e-30)
        np.testing.assert_array_equal(b.normals, want)
    assert not np.allclose(again[0].normals, again[1].normals)
    # the tree of each placement is its own (a mesh's block keys it by mesh.key)
    trees = [mesh.Block(m).bvh for m in again]
    assert trees[0] is not trees[1]
    # another file: another key
    meshio.write_ply(tmp_path / "blob.ply", v * 2.0, f)
    assert meshes()[0].key != first[0].key


def test_a_meshs_tree_takes_its_records_from_the_uploaded_vertices(home, tmp_path, monkeypatch):
    """shared_mesh_bvh gathers the triangle records from the mesh's float32 vertices and
    faces as uploaded: the records of the corners' way (shared_bvh) bit for bit, built or
    read from disk, with no float64 corners gathered for a tree read back."""
    import sys

    from conftest import SCENES
    sys.path.insert(0, str(SCENES / "meshes"))
    from generate import torus_knot

    from whitted.tracer.backend import jit
    from whitted.tracer.shapes import base

    v, f = torus_knot(40, 12)
    v = np.asarray(v, np.float64) * 1.37 + 0.1   # corners not exactly float32
    f = np.asarray(f)
    p, faces = base.v3(v), base.uints(f.reshape(-1))
    corners = [v[f[:, k]] for k in range(3)]
    by_corners = bvh.BVH(*corners)
    key = cache.content_key(v, f)
    built = bvh.shared_mesh_bvh(v, f, key, p, faces)
    np.testing.assert_array_equal(built.tris.numpy(), by_corners.tris.numpy())
    bvh._RECENT.clear()
    real = bvh._Triangles
    monkeypatch.setattr(bvh, "_Triangles", lambda count, corners, records: real(
        count, lambda: pytest.fail("corners gathered"), records))
    read = bvh.shared_mesh_bvh(v, f, key, p, faces)
    assert len(_entries(home / "bvh")) == 1 and read is not built
    np.testing.assert_array_equal(read.tris.numpy(), by_corners.tris.numpy())
    np.testing.assert_array_equal(read.nodes.numpy(), by_corners.nodes.numpy())
    assert isinstance(read.perm, jit.UInt32)


def test_a_settled_file_is_known_by_its_identity_and_a_change_is_seen(home, tmp_path,
                                                                     monkeypatch):
    """A file whose times are settled (SETTLED_NS old) has its identity noted beside its
    entry: read again, its bytes are neither read nor hashed. A change of the file (here
    the same size, its modification time put back) changes its change time, and so its
    identity: the new bytes are read, hashed and parsed. A file just written (times not
    settled) is not noted."""
    import builtins
    import time

    path = _sphere_obj(tmp_path / "s.obj")
    load_mesh(path)
    assert not list((home / "meshes").glob("*.identity"))   # just written: not settled
    monkeypatch.setattr(meshio, "SETTLED_NS", 0)
    meshio.clear_cache()
    first = load_mesh(path)
    [note] = list((home / "meshes").glob("*.identity"))
    assert os.stat(note).st_mode & 0o777 == 0o600
    meshio.clear_cache()
    real_open = builtins.open

    def no_read(file, *a, **k):
        assert os.fspath(file) != os.fspath(path), "the file was read"
        return real_open(file, *a, **k)

    with monkeypatch.context() as m:
        m.setattr(builtins, "open", no_read)
        _no_parse(m)
        again = load_mesh(path)
    assert again.key == first.key
    np.testing.assert_array_equal(again.vertices, first.vertices)
    # the same size, other bytes, the modification time put back: another identity (the
    # change time a clock tick later: the file system's clock may be as coarse as 10 ms)
    time.sleep(0.05)
    before = os.stat(path)
    text = path.read_bytes().replace(b"v 0.", b"v 1.", 1)
    assert len(text) == before.st_size
    path.write_bytes(text)
    os.utime(path, ns=(before.st_atime_ns, before.st_mtime_ns))
    meshio.clear_cache()
    changed = load_mesh(path)
    assert changed.key != first.key
    assert not np.array_equal(changed.vertices, first.vertices)


@pytest.mark.parametrize("how", ["not hex", "too short", "another kind"])
def test_a_wrong_identity_note_is_not_used(home, tmp_path, monkeypatch, how):
    """A note that does not hold one entry's name (64 hex digits) is passed over: the
    file is read and hashed, and its own entry used."""
    monkeypatch.setattr(meshio, "SETTLED_NS", 0)
    path = _sphere_obj(tmp_path / "s.obj")
    first = load_mesh(path)
    [note] = list((home / "meshes").glob("*.identity"))
    arrays = {"not hex": {"entry": np.frombuffer(b"g" * 64, np.uint8)},
              "too short": {"entry": np.frombuffer(b"a" * 63, np.uint8)},
              "another kind": {"entry": np.zeros(64, np.float64)}}[how]
    note.write_bytes(cache.pack_arrays(arrays))
    os.chmod(note, 0o600)
    meshio.clear_cache()
    assert meshio._known_bytes(meshio._identity(path) + (None,)) is None
    again = load_mesh(path)
    assert again.key == first.key
