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
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tracer.mitsuba_xml import Imported, read_xml

# ---------------------------------------------------------------- TOML


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"no TOML for {v}")
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
    """(TOML text, the import) of a Mitsuba XML file; file names relative to ``output``."""
    folder = Path(output).resolve().parent if output is not None else Path.cwd()
    stem = Path(output).stem if output is not None else Path(source).stem
    imp = read_xml(source, approximate, convert=_serialized_converter(folder, stem), **params)
    _relative_files(imp.data, folder)
    return to_toml(imp, Path(source).name), imp


def _serialized_converter(folder: Path, stem: str):
    """``convert(file, index)``: a Mitsuba ``serialized`` mesh written as OBJ by Mitsuba.

    Mitsuba reads the file (its compressed format); its vertex positions, normals,
    texture coordinates and faces, read through ``mi.traverse``, are written to
    ``meshes/STEM_NAME_INDEX.obj`` beside the TOML."""
    def convert(source: Path, index: int) -> Path:
        from reference import mitsuba
        from reference.mitsuba_scene import _write_obj

        mi = mitsuba()
        mesh = mi.load_dict({"type": "serialized", "filename": str(source),
                             "shape_index": index})
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
        out.parent.mkdir(parents=True, exist_ok=True)
        _write_obj(out, node)
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
    from reference import mitsuba

    mi = mitsuba()
    scene = mi.load_file(str(path), **params)
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
        from tracer import transform as tf

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
    overestimates the variance (rule 1 of :class:`reference.compare.Noise`).
    """
    from reference import mitsuba

    mi = mitsuba()
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
    from tracer.integrator import Integrator

    n = seeds if (scene.film.jitter or scene.samples_lights()) else 1
    rgb = var_y = 0.0
    for r in Integrator(scene).render_seeds(range(n), moments=True):
        rgb = rgb + r.image.astype(np.float64) / n
        sd = np.sqrt(r.variance.astype(np.float64))
        var_y = var_y + (sd @ LUMINANCE) ** 2 / (n * n)
    return rgb, rgb @ LUMINANCE, var_y


def agreement(test_y, test_var, ref_y, ref_var) -> dict:
    """Does the tracer agree with Mitsuba within the noise of both? (luminance images)

    Per pixel, the two-sided z-test of :func:`reference.compare.z_test` (Sidak-
    corrected over the pixels, at least 99.75 % passing: the project's statistical
    verdict); over the whole image, the difference of the two mean luminances against
    its standard error (the per-pixel variances summed, pixels being independent),
    which sees a bias too small for any one pixel.
    """
    from reference.compare import z_test

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

#: Mitsuba data scenes stored under tests/data/mitsuba_scenes/ (see its README)
MITSUBA_DATA = (Path(__file__).resolve().parent.parent / "tests" / "data" / "mitsuba_scenes"
                / "tests" / "scenes")


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
    ]


def validate_case(case: ImportedCase, workdir: Path) -> dict:
    """Import, render with the tracer, render the original on Mitsuba, and judge (agreement)."""
    import time

    from reference import mitsuba
    from tracer.scene import parse_scene

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
    scene = parse_scene(imp.data, str(xml)).with_overrides(max_depth=2, spp=case.spp)
    _, ref_y, ref_var = render_original(source, case.integrator, spp=case.spp,
                                        passes=case.passes)
    t1 = time.perf_counter()
    _, test_y, test_var = render_imported(scene, seeds=case.passes)
    t2 = time.perf_counter()
    out = agreement(test_y, test_var, ref_y, ref_var)
    f = scene.film
    out.update(name=case.name, source=str(xml.name), integrator=(
        "direct" if case.integrator == "direct" else "path, max_depth 2"),
        size=[f.width, f.height], spp=case.spp, passes=case.passes,
        filter=f.filter, approximate=imp.approximate,
        notes=sum(len(v) for v in imp.notes.values()),
        seconds={"mitsuba": t1 - t0, "tracer": t2 - t1})
    return out
