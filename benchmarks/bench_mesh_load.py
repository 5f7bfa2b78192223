"""Time reading mesh files (tracer/meshio.py): parsed, and loaded again from the cache.

Writes the benchmark's torus knot (2 x segments x sides triangles, default
144,000) as a binary PLY, an ascii PLY and an OBJ, plus a 2.9 MB OBJ of v and
f lines and a 2.8 MB one of v/vt/vn lines (smaller knots, the latter with a uv
grid and normals), the big knot as a binary PLY of alternate quads and
triangles (lists of two lengths), and the meshes of ``bench_speed.py
process``: a 160,000-triangle torus as an OBJ of v, vt, vn and v/vt/vn
corners, and a 1,000,000-triangle knot as a binary PLY; and prints for each the
median, minimum and maximum time of ``--repeat`` parses (the cache cleared
before each) and of loads of the same unchanged file (cache hits). Then the
time to load a scene with the 2.9 MB OBJ ten times (the cache cleared first).

``--old FILE`` also times another version of the reader, a ``meshio.py``
taken from the project's history (``git show REV:tracer/meshio.py > FILE``),
on the same files in the same run (the two readers alternating), and says whether both give the same
vertices, faces, normals and uvs, bit for bit (the ascii PLY's positions
differ where an older reader kept the text's float64 value of a coordinate
declared ``float``; this one rounds it to float32, as binary files and
Mitsuba do).

    python benchmarks/bench_mesh_load.py [--segments 1200] [--sides 60] [--repeat 7] [--old FILE]
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import struct
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from whitted import tracer  # noqa: E402,F401  (chooses libLLVM before drjit loads)


def write_files(folder: Path, segments: int, sides: int) -> list[Path]:
    import numpy as np

    sys.path.insert(0, str(ROOT / "scenes" / "meshes"))
    from generate import torus_knot, write_obj, write_ply

    v, f = torus_knot(segments, sides)
    binary, obj, text = folder / "knot.ply", folder / "knot.obj", folder / "knot_ascii.ply"
    write_ply(binary, v, f)
    write_obj(obj, v, f)
    head = (f"ply\nformat ascii 1.0\nelement vertex {len(v)}\nproperty float x\n"
            f"property float y\nproperty float z\nelement face {len(f)}\n"
            "property list uchar int vertex_indices\nend_header\n")
    text.write_text(head + "".join(f"{x:.9g} {y:.9g} {z:.9g}\n" for x, y, z in v)
                    + "".join(f"3 {a} {b} {c}\n" for a, b, c in f))
    v, f = torus_knot(880, 46)  # v and f lines: 2.9 MB
    small = folder / "knot_2.9MB.obj"
    write_obj(small, v, f)
    # v/vt/vn, every corner with its own uv and normal index: 2.8 MB at 470 x 32.
    seg, sid = 470, 32
    v, f = torus_knot(seg, sid)
    uv = np.stack(np.meshgrid(np.arange(seg) / seg, np.arange(sid) / sid, indexing="ij"),
                  -1).reshape(-1, 2)
    n = v - v.mean(axis=0)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    vtn = folder / "knot_vtn.obj"
    vtn.write_text("".join(f"v {x:.7g} {y:.7g} {z:.7g}\n" for x, y, z in v)
                   + "".join(f"vt {a:.7g} {b:.7g}\n" for a, b in uv)
                   + "".join(f"vn {x:.7g} {y:.7g} {z:.7g}\n" for x, y, z in n)
                   + "".join("f " + " ".join(f"{i + 1}/{i + 1}/{i + 1}" for i in t) + "\n"
                             for t in f))
    # The big knot's faces as alternate quads and triangle pairs (binary): lists of two
    # lengths, so read record by record for their lengths.
    v, f = torus_knot(segments, sides)
    q = len(f) // 2  # quad k is triangles k and k + q: (a, b, c) and (a, c, d)
    records = []
    for k in range(q):
        a, b, c = f[k]
        d = f[k + q][2]
        records.append(struct.pack("<B4i", 4, a, b, c, d) if k % 2 == 0 else
                       struct.pack("<B3iB3i", 3, a, b, c, 3, a, c, d))
    mixed = folder / "knot_mixed.ply"
    mixed.write_bytes((f"ply\nformat binary_little_endian 1.0\nelement vertex {len(v)}\n"
                       "property float x\nproperty float y\nproperty float z\n"
                       f"element face {q + q // 2}\n"
                       "property list uchar int vertex_indices\nend_header\n").encode()
                      + v.astype("<f4").tobytes() + b"".join(records))
    torus = folder / "torus_160k.obj"
    write_torus_obj(torus, 160_000)
    v, f = torus_knot(5000, 100)
    big = folder / "knot_1M.ply"
    write_ply(big, v, f)
    return [binary, text, obj, small, vtn, mixed, torus, big]


def torus(segments: int, sides: int):
    """A torus (radii 1 and 0.35) of 2 x segments x sides triangles: positions, normals,
    a uv grid and faces (0-based)."""
    import numpy as np

    u = np.arange(segments) * 2 * np.pi / segments
    w = np.arange(sides) * 2 * np.pi / sides
    uu, ww = np.meshgrid(u, w, indexing="ij")
    p = np.stack([(1 + 0.35 * np.cos(ww)) * np.cos(uu), 0.35 * np.sin(ww),
                  (1 + 0.35 * np.cos(ww)) * np.sin(uu)], -1).reshape(-1, 3)
    n = np.stack([np.cos(ww) * np.cos(uu), np.sin(ww), np.cos(ww) * np.sin(uu)],
                 -1).reshape(-1, 3)
    uv = np.stack([uu / (2 * np.pi), ww / (2 * np.pi)], -1).reshape(-1, 2)
    i, j = np.meshgrid(np.arange(segments), np.arange(sides), indexing="ij")
    a, b = i * sides + j, (i + 1) % segments * sides + j
    c, d = (i + 1) % segments * sides + (j + 1) % sides, i * sides + (j + 1) % sides
    f = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                        np.stack([a, c, d], -1).reshape(-1, 3)])
    return p, n, uv, f


def write_torus_obj(path: Path, triangles: int, sides: int = 200) -> None:
    """The torus of about ``triangles`` triangles as an OBJ of v, vt and vn lines and
    v/vt/vn corners (15 MB at 160,000 triangles), as exporters write one."""
    p, n, uv, f = torus(max(3, triangles // (2 * sides)), sides)
    with open(path, "w") as fh:
        fh.write("# a torus written by whitted's benchmarks\no torus\n")
        fh.write("".join(f"v {x:.7g} {y:.7g} {z:.7g}\n" for x, y, z in p.tolist()))
        fh.write("".join(f"vt {x:.6g} {y:.6g}\n" for x, y in uv.tolist()))
        fh.write("".join(f"vn {x:.6g} {y:.6g} {z:.6g}\n" for x, y, z in n.tolist()))
        fh.write("".join(f"f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}\n"
                         for a, b, c in (f + 1).tolist()))


SCENE = """
[film]
width = 64
height = 48
[camera]
origin = [0, 2.6, 6]
target = [0, 0.7, 0]
fov = 40
[materials.white]
type = "diffuse"
reflectance = 0.5
[[lights]]
type = "point"
position = [0, 5, 5]
intensity = 10
[[shapes]]
type = "mesh"
file = "{mesh}"
material = "white"
"""


def ten_scene_loads(scene: Path, repeat: int, reader=None) -> list[float]:
    from whitted.tracer import load_scene, meshio

    def ten():
        meshio.clear_cache()
        clear(reader)
        for _ in range(10):
            load_scene(scene)

    return timed(ten, repeat)


def clear(reader) -> None:
    """Empty another reader's own cache, if it has one (older readers have none)."""
    if reader is not None and hasattr(reader, "clear_cache"):
        reader.clear_cache()


def timed(fn, repeat: int) -> list[float]:
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return out


def show(ts: list[float]) -> str:
    return (f"{statistics.median(ts) * 1e3:9.2f} ms [{min(ts) * 1e3:.2f}-"
            f"{max(ts) * 1e3:.2f}]")


def same(a, b) -> bool:
    import numpy as np

    pairs = ((a.vertices, b.vertices), (a.faces, b.faces), (a.normals, b.normals),
             (a.uvs, b.uvs))
    return all((x is None and y is None) or (x is not None and y is not None and
                                             x.dtype == y.dtype and np.array_equal(x, y))
               for x, y in pairs)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--segments", type=int, default=1200)
    p.add_argument("--sides", type=int, default=60)
    p.add_argument("--repeat", type=int, default=7)
    p.add_argument("--old", type=Path, help="another meshio.py to time on the same files")
    args = p.parse_args(argv)

    from whitted.tracer import meshio

    # The parse itself is timed: the disk cache of parsed meshes (tracer/meshio.py) is
    # kept out, or a second run would time its reads.
    meshio.DISK_MIN_BYTES = 1 << 62
    old = None
    if args.old:
        spec = importlib.util.spec_from_file_location("old_meshio", args.old)
        old = importlib.util.module_from_spec(spec)
        sys.modules["old_meshio"] = old
        spec.loader.exec_module(old)
    print(f"medians of {args.repeat} [min-max]; parse = cache cleared first")
    with tempfile.TemporaryDirectory() as tmp:
        for path in write_files(Path(tmp), args.segments, args.sides):
            meshio.clear_cache()
            mesh = meshio.load_mesh(path)
            line = f"{path.name:15s} {path.stat().st_size / 1e6:5.1f} MB {len(mesh.faces):>8,} tri"
            def new_parse(p=path):
                meshio.clear_cache()
                meshio.load_mesh(p)

            if old is not None:  # alternating: old, new, old, new, ...
                t, parse = [], []
                for _ in range(args.repeat):
                    t += timed(lambda p=path: (clear(old), old.load_mesh(p)), 1)
                    parse += timed(new_parse, 1)
                line += f"  old {show(t)}"
            else:
                parse = timed(new_parse, args.repeat)
            meshio.load_mesh(path)
            cached = timed(lambda p=path: meshio.load_mesh(p), args.repeat)
            line += f"  parse {show(parse)}  cached {show(cached)}"
            if old is not None:
                line += f"  identical: {same(old.load_mesh(path), mesh)}"
            print(line)
        scene = Path(tmp) / "scene.toml"
        scene.write_text(SCENE.format(mesh=Path(tmp) / "knot_2.9MB.obj"))
        line = "a scene with knot_2.9MB.obj loaded ten times (cache cleared first):"
        if old is not None:
            # The scene model reads meshes through tracer.meshio.load_mesh, looked up at
            # each load: the other reader stands in for it.
            current = meshio.load_mesh
            meshio.load_mesh = old.load_mesh
            try:
                line += f"  old {show(ten_scene_loads(scene, max(1, args.repeat // 2), old))}"
            finally:
                meshio.load_mesh = current
        line += f"  now {show(ten_scene_loads(scene, max(1, args.repeat // 2)))}"
        print(line)
    meshio.clear_cache()
    return 0


if __name__ == "__main__":
    sys.exit(main())
