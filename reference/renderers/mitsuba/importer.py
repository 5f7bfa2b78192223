"""``whitted import``: a Mitsuba 3 scene (XML, or a ``load_dict`` dictionary) as a TOML scene.

The XML is read by :mod:`tracer.mitsuba_xml` (no Mitsuba needed, so that
``whitted render scene.xml`` renders it too); this module writes the result as
TOML, with a comment at every place where something was approximated, mesh
files referenced (relative to the TOML file where they can be), not copied.

Mitsuba is asked where it knows better than a re-parse: :func:`mitsuba_view`
loads the original with ``mi.load_file`` and reads the sensor's ``to_world``
and horizontal field of view and the film's size through ``mi.traverse``, and
:func:`disagreements` compares them with the imported scene (used by the
tests and by ``whitted import --verify``). A ``load_dict`` dictionary, such as
``mi.cornell_box()``, is written as XML first (:func:`dict_to_xml`).

:func:`write_import` is ``whitted import``: nothing is written unless the
TOML text loads as a scene (parsed back from memory, as ``whitted render``
would read it) and, with ``verify``, agrees with Mitsuba; the TOML is
written to a temporary file renamed into place, into a folder made for it if
it does not exist yet (:func:`check_output` accepts such a path), and the
meshes converted and folders made for a failed import are removed again.
Mitsuba's own errors (a corrupt ``serialized`` file, a scene it refuses) become
one-line errors (:class:`UserError`).
"""

from __future__ import annotations

import json
import math
import os
import struct
import tomllib
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from whitted.reference import mitsuba_error
from whitted.reference.renderers.mitsuba.scene import loading_threads
from whitted.scenes import MITSUBA_DATA_DIR
from whitted.tracer.errors import UserError, one_line
from whitted.tracer.mitsuba_xml import Imported, read_xml

# ---------------------------------------------------------------- TOML


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):  # the reader refuses them: a scene value cannot be one
            raise UserError(f"no TOML for the number {v}")
        r = repr(v)
        return r if ("." in r or "e" in r or "inf" in r) else r + ".0"
    if isinstance(v, (np.floating, np.integer)):
        return _value(v.item())
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"no TOML for {type(v).__name__}")


def _key(k: str) -> str:
    return k if k.replace("_", "").replace("-", "").isalnum() and k.isascii() else json.dumps(k)


def _comments(notes: list[str]) -> list[str]:
    return [f"# {line}" for n in notes for line in n.splitlines()]


def _table(header: str, body: dict, notes: list[str]) -> list[str]:
    lines = ["", header] + _comments(notes)
    lines += [f"{_key(k)} = {_value(v)}" for k, v in body.items()]
    return lines


def to_toml(imp: Imported, source: str = "") -> str:
    """The imported scene as TOML text, its notes as comments above the tables they concern."""
    d, notes = imp.data, imp.notes
    lines = [f"# Imported by `whitted import` from {source or 'Mitsuba XML'}."]
    if imp.approximate:
        lines.append("# APPROXIMATE: parts outside the Whitted subset were replaced (see the "
                     "comments marked 'approximated').")
    lines.append(f"description = {_value(d.get('description', ''))}")
    lines += _table("[film]", d["film"], notes.get("film", []))
    lines += _table("[camera]", d["camera"], notes.get("camera", []))
    for name, m in d.get("materials", {}).items():
        lines += _table(f"[materials.{_key(name)}]", m, notes.get(f"materials.{name}", []))
    for i, light in enumerate(d.get("lights", [])):
        lines += _table("[[lights]]", light, notes.get(f"lights[{i}]", []))
    for gname, g in d.get("groups", {}).items():
        for i, s in enumerate(g["shapes"]):
            lines += _table(f"[[groups.{_key(gname)}.shapes]]", s,
                            notes.get(f"groups.{gname}.shapes[{i}]", []))
    for i, s in enumerate(d.get("shapes", [])):
        lines += _table("[[shapes]]", s, notes.get(f"shapes[{i}]", []))
    return "\n".join(lines) + "\n"


def _relative_files(data: dict, folder: Path) -> None:
    """Mesh, bitmap and envmap file names relative to the TOML's folder where possible."""
    def fix(x):
        if isinstance(x, dict):
            for k, v in x.items():
                if k in ("file", "filename") and isinstance(v, str) and os.path.isabs(v):
                    try:
                        x[k] = os.path.relpath(v, folder)
                    except ValueError:  # another drive
                        pass
                else:
                    fix(v)
        elif isinstance(x, list):
            for v in x:
                fix(v)
    fix(data)


def import_scene(source: str | Path, output: str | Path | None = None,
                 approximate: bool = False, **params) -> tuple[str, Imported]:
    """(TOML text, the import) of a Mitsuba XML file; file names relative to ``output``.

    The text is checked: it loads as a scene (:func:`check_toml`), else
    :class:`UserError`, and the meshes converted for it are removed again."""
    created: list[Path] = []
    try:
        text, imp, _ = _import(source, output, approximate, params, created)
    except BaseException:
        _remove(created)
        raise
    return text, imp


def check_output(path: str | Path) -> Path:
    """``whitted import``'s output, refused before any work: a ``.toml`` name whose
    folder exists or can be made (the nearest existing folder above it written into
    as a proof: :func:`tracer.imageio.check_output_folder`); not a folder itself."""
    from whitted.tracer.imageio import check_output_folder, check_output_path

    p = Path(path)
    if p.suffix.lower() != ".toml":
        return check_output_path(p, (".toml",), "file type")  # its one-line refusal
    if p.is_dir():
        raise UserError(f"{path}: is a folder, expected a file name")
    if os.path.lexists(p) and not p.is_file():
        raise UserError(f"{path}: exists and is not a regular file")
    check_output_folder(p.parent if str(p.parent) else Path("."))
    if not os.path.lexists(p):
        check_output_folder(p)  # the file's own name within the limits
    return p


def _make_folders(folder: Path, created: list) -> None:
    """Make ``folder`` and the folders above it that are missing, each appended to
    ``created`` (top first) so that a failed import removes them again."""
    missing = []
    q = folder
    while not q.is_dir():
        missing.append(q)
        if q.parent == q:
            break
        q = q.parent
    for d in reversed(missing):
        try:
            d.mkdir()
        except FileExistsError:
            if not d.is_dir():
                raise UserError(f"{d}: exists and is not a folder") from None
            continue
        except OSError as e:
            raise UserError(f"{d}: cannot make the folder: {e.strerror or e}") from None
        created.append(d)


def write_import(source: str | Path, output: str | Path, approximate: bool = False,
                 verify: bool = False, **params):
    """``whitted import``: (the scene, the import) of ``source``, written to ``output``.

    Written only when complete and checked: the TOML loads as a scene
    (:func:`check_toml`) and, with ``verify``, Mitsuba's loading of ``source``
    agrees on the camera and film (:func:`disagreements`) and with Mitsuba's reading of
    the import object by object (:func:`reference.renderers.mitsuba.original.compare_structure`:
    a difference raises its :class:`StructureMismatch`; the :class:`Structure` is left in
    ``imp.structure``); the file is renamed into
    place from a temporary one, and on any failure the meshes converted for it are
    removed, so that nothing is left behind. A missing folder of ``output`` is made
    once everything is checked, and removed again if the writing fails."""
    from whitted.tracer.imageio import _atomic_write

    output = Path(output)
    created: list[Path] = []
    try:
        text, imp, scene = _import(source, output, approximate, params, created)
        if verify:
            problems = disagreements(scene, mitsuba_view(source, **params))
            if problems:
                raise UserError(f"{one_line(str(source), 300)}: the import disagrees with "
                                "Mitsuba's own loading: " + "; ".join(problems))
            from whitted.reference.renderers.mitsuba.original import (
                StructureMismatch,
                compare_structure,
            )

            structure = compare_structure(source, scene, imp, approximate, **params)
            if not structure.agrees:
                raise StructureMismatch(structure)
            imp.structure = structure
        folder = output.resolve().parent
        if not folder.is_dir():  # every check passed: only now is the folder made
            _make_folders(folder, created)
            scene = check_toml(text, output)  # the text, read back from where it will lie
        _atomic_write(output, lambda tmp: Path(tmp).write_text(text))
    except BaseException:
        _remove(created)
        raise
    return scene, imp


def check_toml(text: str | dict, output: str | Path):
    """The scene the TOML text describes, read back as ``whitted render`` reads the file
    (``tomllib`` and the scene's validation, files relative to ``output``), else a
    :class:`UserError` saying that the tracer cannot load the import. A dictionary is
    validated as the document it is."""
    from whitted.tracer.scene import parse_scene

    try:
        return parse_scene(tomllib.loads(text) if isinstance(text, str) else text, str(output))
    except tomllib.TOMLDecodeError as e:  # pragma: no cover (to_toml writes valid TOML)
        raise UserError(f"the import is not valid TOML ({e}); nothing was written") from None
    except UserError as e:
        raise UserError(f"the tracer cannot load the import, nothing was written: {e}") \
            from None


def _import(source, output, approximate: bool, params: dict, created: list):
    folder = Path(output).resolve().parent if output is not None else Path.cwd()
    stem = Path(output).stem if output is not None else Path(source).stem
    imp = read_xml(source, approximate, convert=_serialized_converter(folder, stem, created),
                   **params)
    where = output if output is not None else folder / f"{stem}.toml"
    scene = check_toml(imp.data, where)  # file names still absolute: valid in any folder
    _relative_files(imp.data, folder)
    text = to_toml(imp, Path(source).name)
    if folder.is_dir():  # the very text, read back as `whitted render` will read the file
        scene = check_toml(text, where)
    return text, imp, scene


def _remove(paths: list[Path]) -> None:
    """Remove files (and then folders, once empty) that a failed import created."""
    for p in reversed(paths):
        try:
            if p.is_dir():
                p.rmdir()
            else:
                p.unlink()
        except OSError:
            pass


#: Mitsuba's ``serialized`` format (src/shapes/serialized.cpp): a uint16 0x041C, a uint16
#: version (3 or 4), then a zlib stream of flags, (version 4) a name, vertex and face counts.
SERIALIZED_MAGIC = 0x041C
#: Memory of converting one vertex and one face (upper bounds): Mitsuba's buffers and the
#: doubles it reads, numpy's copies, the OBJ's text lines and the text joined.
SERIALIZED_BYTES_PER_VERTEX = 512
SERIALIZED_BYTES_PER_FACE = 256
#: DEFLATE expands at most about 1032 to 1: counts needing more data than that are corrupt.
DEFLATE_MAX_RATIO = 1032


def check_serialized(path: Path, index: int) -> tuple[int, int]:
    """(vertices, faces) of mesh ``index`` of a Mitsuba ``serialized`` file, from its headers.

    Refused (:class:`UserError`): a file that is not one, a ``shape_index`` beyond
    its meshes (Mitsuba's own check lets the one past the last through), counts the
    file cannot hold, and a mesh whose conversion would take more than
    ``WHITTED_MAX_MEMORY`` (Mitsuba allocates its buffers from these counts)."""
    from whitted.tracer.limits import check_memory

    def bad(why: str) -> UserError:
        return UserError(f"{one_line(path.name, 60)}: not a Mitsuba serialized mesh ({why})")

    size = path.stat().st_size
    with open(path, "rb") as f:  # a regular file: the reader checked it
        head = f.read(4)
        if len(head) < 4 or struct.unpack("<H", head[:2])[0] != SERIALIZED_MAGIC:
            raise bad("no 0x041C header")
        version = struct.unpack("<H", head[2:])[0]
        if version not in (3, 4):
            raise bad(f"version {version}; Mitsuba reads 3 and 4")
        offset = 0
        if index:
            width = 8 if version == 4 else 4
            f.seek(max(size - 4, 0))
            count = struct.unpack("<I", f.read(4).rjust(4, b"\0"))[0]
            if index >= count:
                raise UserError(f"{one_line(path.name, 60)}: shape_index {index}, but the file "
                                f"holds {count} meshes")
            at = size - 4 - width * (count - index)
            if at < 4:
                raise bad("its table of meshes is truncated")
            f.seek(at)
            offset = struct.unpack("<Q" if width == 8 else "<I", f.read(width))[0]
            if not 4 <= offset < size - 8:
                raise bad(f"mesh {index} at offset {offset}, outside the file")
            f.seek(offset)
            if f.read(4) != head:
                raise bad(f"no header at mesh {index}")
        compressed = f.read(1 << 16)
    try:
        data = zlib.decompressobj().decompress(compressed, 1 << 16)
    except zlib.error:
        raise bad("its data is not zlib-compressed") from None
    pos = 4
    if version == 4:
        pos = data.find(b"\0", 4) + 1
        if pos == 0:
            raise bad("its header is truncated")
    if len(data) < pos + 16:
        raise bad("its header is truncated")
    vertices, faces = struct.unpack("<QQ", data[pos:pos + 16])
    if 12 * (vertices + faces) > DEFLATE_MAX_RATIO * (size - offset):
        raise bad(f"{vertices:,} vertices and {faces:,} faces in a {size:,}-byte file")
    check_memory(vertices * SERIALIZED_BYTES_PER_VERTEX + faces * SERIALIZED_BYTES_PER_FACE,
                 f"converting a serialized mesh of {vertices:,} vertices and {faces:,} faces")
    return vertices, faces


def _serialized_converter(folder: Path, stem: str, created: list | None = None):
    """``convert(file, index)``: a Mitsuba ``serialized`` mesh written as OBJ by Mitsuba.

    Mitsuba reads the file (its compressed format; its headers checked first:
    :func:`check_serialized`); its vertex positions, normals, texture coordinates
    and faces, read through ``mi.traverse``, are written to
    ``meshes/STEM_NAME_INDEX.obj`` beside the TOML (through a temporary file; each
    file and folder created is appended to ``created``)."""
    created = [] if created is None else created

    def convert(source: Path, index: int) -> Path:
        from whitted.reference import mitsuba
        from whitted.reference.renderers.mitsuba.scene import _write_obj
        from whitted.tracer.imageio import _atomic_write

        check_serialized(source, index)
        mi = mitsuba()
        try:
            mesh = mi.load_dict({"type": "serialized", "filename": str(source),
                                 "shape_index": index})
        except (RuntimeError, ValueError) as e:  # Mitsuba's C++ exceptions
            raise UserError(f"Mitsuba cannot read {one_line(source.name, 60)}: "
                            f"{mitsuba_error(e)}") from None
        p = mi.traverse(mesh)

        def arr(key, n):
            if key not in p.keys():
                return None
            a = np.asarray(p[key], dtype=np.float64)
            return a.reshape(-1, n) if a.size else None

        node = {"vertices": arr("vertex_positions", 3),
                "faces": np.asarray(p["faces"], dtype=np.int64).reshape(-1, 3),
                "normals": arr("vertex_normals", 3), "uvs": arr("vertex_texcoords", 2)}
        out = folder / "meshes" / f"{stem}_{source.stem}_{index}.obj"
        _make_folders(out.parent, created)
        if not out.exists():
            created.append(out)
        _atomic_write(out, lambda tmp: _write_obj(Path(tmp), node))
        return out
    return convert


# ---------------------------------------------------------------- load_dict -> XML

_TAGS = {"sensor": "sensor", "film": "film", "sampler": "sampler", "rfilter": "rfilter",
         "integrator": "integrator", "bsdf": "bsdf", "emitter": "emitter"}
_SHAPES = {"sphere", "rectangle", "disk", "cylinder", "cube", "obj", "ply", "serialized",
           "shapegroup", "instance"}
_EMITTERS = {"point", "spot", "directional", "constant", "envmap", "area"}
_SENSORS = {"perspective", "orthographic", "thinlens"}
_INTEGRATORS = {"path", "direct", "volpath", "moment", "aov", "ptracer"}


def _tag_of(key: str, node: dict) -> str:
    t = node.get("type")
    if key in _TAGS:
        return _TAGS[key]
    if t in _SHAPES:
        return "shape"
    if t in _EMITTERS:
        return "emitter"
    if t in _SENSORS:
        return "sensor"
    if t in _INTEGRATORS:
        return "integrator"
    if t in ("checkerboard", "bitmap"):
        return "texture"
    return "bsdf"


def _fmt(x) -> str:
    return f"{float(x):.9g}"


def dict_to_xml(tree: dict) -> str:
    """A ``mi.load_dict`` dictionary (Mitsuba objects as values) as Mitsuba XML text."""
    from xml.sax.saxutils import quoteattr

    def obj(key, node, indent, name=None) -> list[str]:
        pad = "    " * indent
        if node.get("type") == "ref":
            return [f"{pad}<ref id={quoteattr(node['id'])}/>"]
        if node.get("type") == "rgb":
            return [f'{pad}<rgb name={quoteattr(name)} value="'
                    + ", ".join(_fmt(x) for x in node["value"]) + '"/>']
        tag = _tag_of(key, node)
        attrs = f' type={quoteattr(node["type"])}'
        if name is None and key not in _TAGS and indent == 1:
            attrs += f" id={quoteattr(key)}"
        if name is not None and tag == "texture":
            attrs += f" name={quoteattr(name)}"
        lines = [f"{pad}<{tag}{attrs}>"]
        for k, v in node.items():
            if k in ("type", "id"):
                continue
            lines += prop(k, v, indent + 1)
        return lines + [f"{pad}</{tag}>"]

    def prop(k, v, indent) -> list[str]:
        pad = "    " * indent
        if isinstance(v, dict):
            child_name = None if k in _TAGS or v.get("type") == "ref" else k
            if v.get("type") in _SHAPES | _EMITTERS or k in _TAGS:
                child_name = None
            return obj(k, v, indent, child_name)
        if isinstance(v, bool):
            return [f'{pad}<boolean name="{k}" value="{"true" if v else "false"}"/>']
        if isinstance(v, int):
            return [f'{pad}<integer name="{k}" value="{v}"/>']
        if isinstance(v, float):
            return [f'{pad}<float name="{k}" value="{_fmt(v)}"/>']
        if isinstance(v, str):
            return [f"{pad}<string name={quoteattr(k)} value={quoteattr(v)}/>"]
        if hasattr(v, "matrix"):  # a ScalarTransform4f
            m = np.asarray(v.matrix, dtype=np.float64).reshape(4, 4)
            return [f'{pad}<transform name="{k}">',
                    f'{pad}    <matrix value="' + " ".join(_fmt(x) for x in m.ravel()) + '"/>',
                    f"{pad}</transform>"]
        seq = list(v)
        if len(seq) == 3:
            return [f'{pad}<point name="{k}" value="' + ", ".join(_fmt(x) for x in seq) + '"/>']
        raise TypeError(f"no XML for {k} = {v!r}")

    lines = ['<?xml version="1.0" encoding="utf-8"?>', '<scene version="3.0.0">']
    for k, v in tree.items():
        if k == "type":
            continue
        lines += obj(k, v, 1)
    return "\n".join(lines + ["</scene>", ""])


# ---------------------------------------------------------------- asking Mitsuba


def mitsuba_view(path: str | Path, **params) -> dict:
    """What Mitsuba itself makes of the file's sensor: to_world, horizontal fov, film size."""
    from whitted.reference import mitsuba

    mi = mitsuba()
    try:
        with loading_threads():
            scene = mi.load_file(str(path), **params)
    except (RuntimeError, ValueError) as e:  # Mitsuba's C++ exceptions
        raise UserError(f"{one_line(str(path), 300)}: Mitsuba cannot load it: "
                        f"{mitsuba_error(e)}") from None
    sensor = scene.sensors()[0]
    p = mi.traverse(sensor)
    out = {"to_world": np.asarray(p["to_world"].matrix, dtype=np.float64).reshape(4, 4),
           "size": tuple(int(x) for x in p["film.size"])}
    if "x_fov" in p.keys():
        out["x_fov"] = float(np.asarray(p["x_fov"]).ravel()[0])
    return out


def disagreements(scene, view: dict, tol: float = 1e-4) -> list[str]:
    """Where the imported scene's camera and film differ from what Mitsuba loaded."""
    out = []
    f = scene.film
    if (f.width, f.height) != view["size"]:
        out.append(f"film {f.width}x{f.height}, Mitsuba's {view['size']}")
    cam = scene.camera
    mine = cam.to_world()
    theirs = view["to_world"]
    if cam.type == "orthographic" and cam.matrix is None:  # look_at x scale(width / 2)
        from whitted.tracer import transform as tf

        mine = mine @ tf.scale([cam.width / 2, cam.width / 2, 1])
    scale = max(1.0, float(np.abs(theirs).max()))
    if not np.allclose(mine, theirs, atol=tol * scale):
        out.append(f"camera to_world {mine.tolist()}, Mitsuba's {theirs.tolist()}")
    if "x_fov" in view and cam.type == "perspective":
        fx = cam.fov_x(f.width / f.height)
        if abs(fx - view["x_fov"]) > 1e-3:
            out.append(f"horizontal fov {fx:.5f}, Mitsuba's {view['x_fov']:.5f}")
    return out


# ---------------------------------------------------------------- validation


#: Luminance of linear sRGB (Rec. 709 primaries, D65): the Y row of the RGB -> XYZ matrix,
#: as Mitsuba's ``luminance``; Mitsuba's ``moment`` integrator reports second moments in XYZ.
LUMINANCE = np.array([0.212671, 0.715160, 0.072169])


def render_original(source, integrator: str = "path", spp: int = 64, passes: int = 8):
    """Mitsuba's render of the *original* scene (XML path or load_dict dictionary).

    ``integrator``: "direct", or "path" at max_depth 2 (direct light, as Whitted's
    tracer at max_depth 2 computes it), wrapped in Mitsuba's ``moment`` integrator.
    ``passes`` independent renders of ``spp`` samples (seeds 0 .. passes-1). Returns
    (mean image H x W x 3, luminance of that mean H x W, variance of the luminance
    mean H x W): from the per-sample second moment, (E[Y^2] - E[Y]^2) / (spp passes).
    With a filter wider than a pixel, a pixel gathers more than spp samples, so this
    overestimates the variance (rule 1 of :class:`reference.verdicts.compare.Noise`).
    """
    from whitted.reference import mitsuba

    mi = mitsuba()
    with loading_threads():   # the report may run Dr.Jit on one thread here (SharedCores)
        scene = (mi.load_dict(source) if isinstance(source, dict)
                 else mi.load_file(str(source)))
    inner = {"type": "direct"} if integrator == "direct" else {"type": "path", "max_depth": 2}
    integ = mi.load_dict({"type": "moment", "nested": inner})
    names = integ.aov_names()
    iy, im2 = 3 + names.index("nested.Y"), 3 + names.index("m2_nested.Y")
    rgb = y = m2 = 0.0
    for k in range(passes):
        out = np.asarray(mi.render(scene, integrator=integ, spp=spp, seed=k), dtype=np.float64)
        rgb, y, m2 = rgb + out[..., :3] / passes, y + out[..., iy] / passes, \
            m2 + out[..., im2] / passes
    return rgb, y, np.maximum(m2 - y * y, 0) / (spp * passes)


def render_imported(scene, seeds: int = 8):
    """The tracer's render of an imported scene: (mean image, its luminance, variance of that).

    Each seed's variance of the pixel mean comes from the per-sample second moments
    (per channel); the luminance's is bounded by (sum_c w_c sd_c)^2 (Cauchy-Schwarz,
    channels being correlated). A scene without randomness (strata centres, no
    sampled light) is rendered once; its moments then bound the strata's error.
    """
    from whitted.tracer.integrator import Integrator

    n = seeds if (scene.film.jitter or scene.samples_lights()) else 1
    rgb = var_y = 0.0
    for r in Integrator(scene).render_seeds(range(n), moments=True):
        rgb = rgb + r.image.astype(np.float64) / n
        sd = np.sqrt(r.variance.astype(np.float64))
        var_y = var_y + (sd @ LUMINANCE) ** 2 / (n * n)
    return rgb, rgb @ LUMINANCE, var_y


def agreement(test_y, test_var, ref_y, ref_var) -> dict:
    """Does the tracer agree with Mitsuba within the noise of both? (luminance images)

    Per pixel, the two-sided z-test of :func:`reference.verdicts.compare.z_test` (Sidak-
    corrected over the pixels, at least 99.75 % passing: the project's statistical
    verdict); over the whole image, the difference of the two mean luminances against
    its standard error (the per-pixel variances summed, pixels being independent),
    which sees a bias too small for any one pixel.
    """
    from whitted.reference.verdicts.compare import z_test

    zt = z_test(test_y[..., None].astype(np.float32), ref_y[..., None].astype(np.float32),
                ref_var[..., None], test_var[..., None])
    n = test_y.size
    diff = float(test_y.mean() - ref_y.mean())
    se = math.sqrt(float((ref_var + test_var).sum())) / n
    z_mean = diff / se if se > 0 else (0.0 if diff == 0 else math.inf)
    rel = diff / float(ref_y.mean()) if ref_y.mean() else 0.0
    return {"z_fraction_passed": zt.fraction_passed, "z_passed": zt.passed,
            "mean_z": z_mean, "mean_rel_diff": rel,
            "passed": bool(zt.passed and abs(z_mean) < MEAN_Z_LIMIT)}


#: |z| of the image means' difference beyond which the means disagree: 4 sigma, a false
#: alarm with probability 6e-5 per comparison for a normal statistic.
MEAN_Z_LIMIT = 4.0


# ---------------------------------------------------------------- the report's "imported" group

#: Mitsuba data scenes stored under scenes/mitsuba-data/ (see its README)
MITSUBA_DATA = MITSUBA_DATA_DIR / "tests" / "scenes"


@dataclass
class ImportedCase:
    """A Mitsuba scene the report imports: the original, its reference integrator, samples."""
    name: str
    integrator: str                 # "direct", or "path" at max_depth 2
    spp: int
    passes: int
    size: int | None = None         # square film size for mi.cornell_box()
    xml: Path | None = None         # None: mi.cornell_box()


def imported_cases(quick: bool) -> list[ImportedCase]:
    """The scenes of the report's "imported" group (smaller and fewer samples when quick)."""
    return [
        ImportedCase("floating_sphere", "direct", 32, 4,
                     xml=MITSUBA_DATA / "floating_sphere" / "test_directional_direct.xml"),
        ImportedCase("instancing", "path", 16 if quick else 64, 4,
                     xml=MITSUBA_DATA / "instancing" / "test_instancing_path.xml"),
        ImportedCase("cornell_box", "path", 16 if quick else 64, 8, 64 if quick else 128),
        # an orthographic camera whose to_world is two steps (scale, then lookat)
        ImportedCase("orthographic_sensor", "path", 16 if quick else 64, 4,
                     xml=MITSUBA_DATA / "orthographic_sensor" / "test_orthographic_path.xml"),
    ]


def validate_case(case: ImportedCase, workdir: Path) -> dict:
    """Import, check the import's structure against Mitsuba's reading of the original
    (:func:`reference.renderers.mitsuba.original.compare_structure`: a difference fails
    the case), render with the tracer, render the original on Mitsuba, and judge
    (agreement)."""
    import time

    from whitted.reference import mitsuba
    from whitted.tracer.scene import parse_scene

    t0 = time.perf_counter()
    source = case.xml
    if case.xml is None:
        mi = mitsuba()
        source = mi.cornell_box()
        source["sensor"]["film"]["width"] = source["sensor"]["film"]["height"] = case.size
        xml = workdir / f"{case.name}.xml"
        xml.parent.mkdir(parents=True, exist_ok=True)
        xml.write_text(dict_to_xml(source))
    else:
        xml = case.xml
    imp = read_xml(xml)
    imported = parse_scene(imp.data, str(xml))
    from whitted.reference.renderers.mitsuba.original import compare_structure

    structure = compare_structure(xml, imported, imp)   # the original judges the import
    scene = imported.with_overrides(max_depth=2, spp=case.spp)
    _, ref_y, ref_var = render_original(source, case.integrator, spp=case.spp,
                                        passes=case.passes)
    t1 = time.perf_counter()
    _, test_y, test_var = render_imported(scene, seeds=case.passes)
    t2 = time.perf_counter()
    out = agreement(test_y, test_var, ref_y, ref_var)
    out["images_passed"] = out["passed"]
    out["structure"] = structure.to_json()
    out["passed"] = bool(out["passed"] and structure.agrees)
    f = scene.film
    out.update(name=case.name, source=str(xml.name), integrator=(
        "direct" if case.integrator == "direct" else "path, max_depth 2"),
        size=[f.width, f.height], spp=case.spp, passes=case.passes,
        filter=f.filter, approximate=imp.approximate,
        notes=sum(len(v) for v in imp.notes.values()),
        seconds={"mitsuba": t1 - t0, "tracer": t2 - t1})
    return out
