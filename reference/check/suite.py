"""``whitted suite``: the built-in scenes as a folder to hand out, and grading a folder of images.

``export`` writes, for every scene, its TOML (and the mesh files it reads),
its Mitsuba 3 XML (stock ``path`` integrator at the scene's max_depth, samples
jittered in their strata, so that Mitsuba renders it without bias), the
reference as linear EXR and as sRGB PNG, and a manifest: ``manifest.json``
for machines, ``README.md`` for people. What each scene tests is derived from
the scene itself: its material, light and shape kinds, the features in use
(Schlick, textures, area lights), the share of its light on each of
Heckbert's paths, and the formulas those stand for (:data:`FORMULAS`, one
entry per registered kind, each with the lecture topic it is taught under).

The reference EXR holds four layers: R, G, B (the tracer's image at the
scene's strata, or the mean of :data:`reference.verdicts.compare.TRACER_SEEDS` seeds
where it samples area lights), ``variance`` (of that mean; zero where it is
deterministic), ``spread`` (the variance of one sample within each pixel,
which :func:`reference.check.judge.footprint_factor` scales) and ``quadrature``
(:func:`reference.check.judge.quadrature_error`). ``--update`` replaces R, G, B and
``variance`` by the golden image's and keeps the other two.

``check`` grades a folder of images named after the scenes
(``glass_sphere.png``, ``three_lights.exr``, ...) with
:func:`reference.check.judge.check_image`, against the stored references of a
suite folder (``--suite``) or, without one, against references rendered now.
``--update`` stores the graded images as the suite's references (a renderer
developer's golden images), and refuses to when any scene fails.

A suite folder is input from anyone, so ``manifest.json`` is read as such
(:func:`read_manifest`): a regular file of at most :data:`MAX_MANIFEST_BYTES`,
nested at most :data:`MAX_MANIFEST_NESTING` deep, every field the commands use of
the type :func:`validate_manifest` expects, and every path in it relative and,
symbolic links resolved, inside the suite (:func:`safe_member`), before any work.
"""

from __future__ import annotations

import datetime as _dt
import fnmatch
import json
import math
import os
import re
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

import numpy as np

from whitted.tracer.files import NotRegularFile, read_regular, special_kind

#: The formulas each kind stands for, with the lecture topic it belongs to (the lectures'
#: slide titles: radiometry, BRDFs, Fresnel, Snell, intersections, cameras, shadows,
#: recursion, Phong, lights). Keys: ("material" | "light" | "shape" | "feature", name).
FORMULAS: dict[tuple[str, str], list[tuple[str, str]]] = {
    ("material", "diffuse"): [("Lambertian BRDF f = rho / pi", "BRDFs: the diffuse BRDF"),
                              ("cosine cos(theta_i) = n . l", "The illumination equation")],
    ("material", "mirror"): [("law of reflection r = d - 2 (d . n) n", "Reflection"),
                             ("specular weight: the reflectance", "Recursion")],
    ("material", "dielectric"): [("Snell's law n1 sin(theta_1) = n2 sin(theta_2)",
                                  "Snell's law"),
                                 ("exact Fresnel R = (r_s^2 + r_p^2) / 2", "The Fresnel equation"),
                                 ("total internal reflection beyond asin(n2 / n1)",
                                  "Total internal reflection"),
                                 ("radiance scaled by (n1 / n2)^2 on refraction",
                                  "Radiometry: radiance at a boundary")],
    ("material", "conductor"): [("law of reflection r = d - 2 (d . n) n", "Reflection"),
                                ("conductor Fresnel with the complex index eta + i k",
                                 "The Fresnel equation")],
    ("material", "thindielectric"): [("thin slab R' = R + T^2 R / (1 - R^2) = 2R / (1 + R)",
                                      "The Fresnel equation"),
                                     ("exact Fresnel R = (r_s^2 + r_p^2) / 2",
                                      "The Fresnel equation")],
    ("material", "plastic"): [("exact Fresnel R = (r_s^2 + r_p^2) / 2 on the coating",
                               "The Fresnel equation"),
                              ("diffuse base kd / (1 - F_dr) (1 - F_i)(1 - F_o) / (eta^2 pi)",
                               "The illumination equation")],
    ("material", "blend"): [("linear blend f = (1 - w) f_1 + w f_2 of two smooth BRDFs",
                             "BRDF types"),
                            ("Lambertian BRDF f = rho / pi", "BRDFs: the diffuse BRDF")],
    ("material", "phong"): [("Phong lobe ks (n + 2) / (2 pi) cos^n(alpha)",
                             "Phong's reflection model"),
                            ("Blinn-Phong lobe with the half vector", "Phong's reflection model")],
    ("material", "classic"): [("classic illumination model: ambient + kd (n . l) + ks (r . v)^n "
                               "+ kr R + kt T", "Whitted's illumination model"),
                              ("Heckbert's fixed refraction weights", "Recursion")],
    ("light", "point"): [("inverse-square falloff E = I cos / r^2", "Point lights")],
    ("light", "spot"): [("spot falloff linear in the angle between beam and cutoff",
                         "Spot lights"),
                        ("inverse-square falloff", "Point lights")],
    ("light", "directional"): [("irradiance E cos(theta), no falloff", "Directional lights")],
    ("light", "constant"): [("uniform sphere directions, pdf 1 / (4 pi)",
                             "Quick radiometry recap"),
                            ("radiance of rays that miss everything", "Recursion")],
    ("light", "envmap"): [("lat-long lookup u = atan2(x, -z) / 2 pi, v = acos(y) / pi",
                           "Textures"),
                          ("uniform sphere directions, pdf 1 / (4 pi)", "Quick radiometry recap")],
    ("light", "projector"): [("projector: the image at the pinhole projection of the point, "
                               "E = pi scale irradiance / (z^2 cos)",
                               "Perspective camera construction")],
    ("light", "background"): [("radiance of rays that miss everything", "Recursion")],
    ("light", "heckbert"): [("Heckbert's light spheres: no falloff, a visibility test",
                             "Whitted's illumination model")],
    ("shape", "sphere"): [("ray-sphere intersection (the nearer positive root)",
                           "Ray-sphere intersection")],
    ("shape", "rectangle"): [("ray-plane intersection", "Ray-plane intersection")],
    ("shape", "disk"): [("ray-plane intersection inside a radius", "Ray-plane intersection")],
    ("shape", "polygon"): [("ray-polygon intersection (even-odd rule)",
                            "Ray-polygon intersection")],
    ("shape", "triangle"): [("ray-triangle intersection (watertight)",
                             "Ray-triangle intersection")],
    ("shape", "mesh"): [("ray-triangle intersection (watertight)", "Ray-triangle intersection"),
                        ("interpolated vertex normals", "Shading normals")],
    ("shape", "cylinder"): [("ray-cylinder intersection", "Ray-quadric intersection")],
    ("shape", "paraboloid"): [("ray-paraboloid intersection", "Ray-quadric intersection")],
    ("shape", "instance"): [("transforms: points, vectors and normals (inverse transpose)",
                             "Transformations")],
    ("feature", "area_lights"): [("area light sampling, pdf converted to solid angle "
                                  "(r^2 / cos)", "Radiometry: area lights")],
    ("feature", "schlick"): [("Schlick's approximation R0 + (1 - R0)(1 - cos)^5",
                              "The Fresnel equation")],
    ("feature", "textures"): [("checkerboard texture lookup", "Textures")],
    ("feature", "shadows"): [("shadow rays: a point is lit only if nothing blocks the light",
                              "Shadows")],
    ("feature", "perspective"): [("perspective camera rays (horizontal field of view)",
                                  "Cameras")],
    ("feature", "orthographic"): [("orthographic camera rays", "Cameras")],
}

#: Image files looked for, by extension, when grading a folder.
IMAGE_EXTENSIONS = (".exr", ".pfm", ".hdr", ".png", ".ppm")


def scene_kinds(scene) -> dict:
    """The kinds and features a scene uses, read from the scene model."""
    from whitted.tracer import emitters, materials

    mats = sorted({materials.type_of(m) for m in scene.used_materials()})
    lights = sorted({emitters.type_of(light) for light in scene.lights}
                    | {emitters.type_of(light) for light in scene.shape_lights()})
    shapes = sorted({type(s).__name__.lower() for s in scene.all_shapes()})
    features = ["shadows", scene.camera.type]
    if scene.has_area_lights():
        features.append("area_lights")
    if scene.uses_schlick():
        features.append("schlick")
    if scene.uses_textures():
        features.append("textures")
    return {"materials": mats, "lights": lights, "shapes": shapes, "features": features}


def scene_formulas(kinds: dict) -> list[dict]:
    """The formulas a scene's kinds and features stand for (no repeats)."""
    out, seen = [], set()
    for group, key in (("materials", "material"), ("lights", "light"), ("shapes", "shape"),
                       ("features", "feature")):
        for name in kinds[group]:
            for formula, topic in FORMULAS.get((key, name), []):
                if formula not in seen:
                    seen.add(formula)
                    out.append({"formula": formula, "topic": topic, "from": f"{key} {name}"})
    return out


def select(paths: list[Path], pattern: str | None) -> list[Path]:
    if not pattern:
        return paths
    return [p for p in paths if fnmatch.fnmatch(p.stem, pattern) or fnmatch.fnmatch(p.name,
                                                                                    pattern)]


def _copy_meshes(scene, scene_path: Path, dest: Path) -> list[Path]:
    """Copy the mesh files a scene reads to the same relative place beside its copy."""
    from whitted.tracer.scene import Mesh

    out = []
    for s in scene.all_shapes():
        if not isinstance(s, Mesh):
            continue
        rel = os.path.relpath(s.file, scene_path.parent)
        if rel.startswith(".."):
            continue  # an absolute or outside path: the copied TOML still points to it
        target = dest / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(s.file, target)
        out.append(target)
    return out


def write_reference(path: Path, image: np.ndarray, variance: np.ndarray | None,
                    spread: np.ndarray | None, quadrature: np.ndarray | None = None) -> None:
    """A reference EXR: RGB, and the ``variance``, ``spread`` and ``quadrature`` layers."""
    from whitted.tracer.imageio import write_exr

    layers = {}
    for name, a in (("variance", variance), ("spread", spread), ("quadrature", quadrature)):
        if a is not None:
            layers.update({f"{name}.{c}": np.asarray(a[..., i], dtype=np.float32)
                           for i, c in enumerate("RGB")})
    write_exr(path, image, layers)


#: Largest reference EXR read from a suite (a 4K image with its four layers is 400 MB).
MAX_REFERENCE_BYTES = 1 << 30


def _regular_file(path: Path, what: str, limit: int) -> os.stat_result:
    """``path``'s status if it is a regular file of at most ``limit`` bytes (no FIFO, device)."""
    from whitted.tracer.errors import UserError

    try:
        st = os.stat(path)
    except OSError as e:
        raise UserError(f"{path}: cannot read {what}: {e.strerror or e}") from None
    if special_kind(st) is not None:
        raise UserError(f"{path}: not a regular file ({what})")
    if st.st_size > limit:
        raise UserError(f"{path}: larger than {limit:,} bytes ({what})")
    return st


def read_reference(path: Path, name: str):
    """A stored reference EXR as a :class:`reference.check.judge.Reference`; one-line errors.

    R, G, B must be finite; the ``variance``, ``spread`` and ``quadrature``
    layers, where present, finite and not negative, all of one size.
    """
    from whitted.reference.check.judge import Reference
    from whitted.tracer.errors import UserError, one_line
    from whitted.tracer.imageio import read_exr_channels

    _regular_file(path, "a reference EXR", MAX_REFERENCE_BYTES)
    try:
        ch, _ = read_exr_channels(path)
    except OSError as e:
        raise UserError(f"{path}: cannot read a reference EXR: {e.strerror or e}") from None
    except (RuntimeError, ValueError, TypeError, KeyError, EOFError) as e:
        raise UserError(f"{path}: not a reference EXR (unreadable: "
                        f"{one_line(str(e), 120) or type(e).__name__})") from None

    def layer(prefix):
        names = [f"{prefix}{c}" for c in "RGB"]
        if not all(n in ch for n in names):
            return None
        planes = [np.asarray(ch[n]) for n in names]
        if any(pl.ndim != 2 or pl.shape != planes[0].shape or pl.size == 0 for pl in planes):
            raise UserError(f"{path}: not a reference EXR ({prefix or 'R, G, B'} channels of "
                            "different sizes)")
        a = np.stack([pl.astype(np.float64) for pl in planes], axis=-1)
        # A variance, spread or quadrature bound is never negative.
        if not np.isfinite(a).all() or (prefix and (a < 0).any()):
            what = prefix.rstrip(".") or "R, G, B"
            raise UserError(f"{path}: not a reference EXR ({what}: values that are not "
                            f"finite{' or below 0' if prefix else ''})")
        return a

    image = layer("")
    if image is None:
        raise UserError(f"{path}: not a reference EXR (no R, G, B channels)")
    extra = {p: layer(f"{p}.") for p in ("variance", "spread", "quadrature")}
    for p, a in extra.items():
        if a is not None and a.shape != image.shape:
            raise UserError(f"{path}: not a reference EXR (its {p} layer is not the image's "
                            "size)")
    var = extra["variance"]
    if var is not None and not var.any():
        var = None
    return Reference(image, var, name, 1, extra["spread"], extra["quadrature"])


def export(outdir: Path, scene_paths: list[Path], log=print) -> dict:
    """Write the suite (module docstring); return the manifest."""
    from whitted.reference.check.judge import tracer_reference
    from whitted.reference.check.suspects import light_path_images
    from whitted.reference.renderers.mitsuba.scene import write_xml
    from whitted.reference.verdicts.compare import write_json
    from whitted.tracer import load_scene
    from whitted.tracer.imageio import write_png

    scenes = [(p, load_scene(p)) for p in scene_paths]   # all validated first
    for sub in ("scenes", "mitsuba", "references"):
        (outdir / sub).mkdir(parents=True, exist_ok=True)
    entries = []
    for i, (path, scene) in enumerate(scenes, 1):
        name = scene.name
        shutil.copyfile(path, outdir / "scenes" / f"{name}.toml")
        meshes = _copy_meshes(scene, path, outdir / "scenes")
        xml = write_xml(scene, outdir / "mitsuba" / f"{name}.xml", "path", jitter=True)
        ref = tracer_reference(scene)
        write_reference(outdir / "references" / f"{name}.exr", ref.image, ref.variance,
                        ref.spread, ref.quadrature)
        write_png(outdir / "references" / f"{name}.png", ref.image)
        parts = light_path_images(scene)
        total = float(np.abs(ref.image).sum()) or 1.0
        kinds = scene_kinds(scene)
        f = scene.film
        entries.append({
            "name": name, "description": scene.description,
            "size": [f.width, f.height], "spp": f.strata ** 2, "max_depth": f.max_depth,
            "depth": f.depth, "tests": kinds, "formulas": scene_formulas(kinds),
            "light_paths": {e: float(np.abs(img).sum()) / total for e, img in parts.items()},
            "tracer_only": list(scene.tracer_only),
            "reference": {"source": ref.name, "seeds": ref.seeds},
            "files": {"scene": f"scenes/{name}.toml",
                      "meshes": [str(m.relative_to(outdir)) for m in meshes],
                      "mitsuba": [str(Path(x).relative_to(outdir)) for x in xml],
                      "reference_exr": f"references/{name}.exr",
                      "reference_png": f"references/{name}.png"}})
        log(f"[{i}/{len(scenes)}] {name}")
    manifest = {"whitted_suite": 1, "date": _now(), "scenes": entries}
    write_json(outdir / "manifest.json", manifest)
    (outdir / "README.md").write_text(manifest_markdown(manifest))
    return manifest


def _now() -> str:
    return _dt.datetime.now().astimezone().isoformat(timespec="seconds")


def manifest_markdown(manifest: dict) -> str:
    lines = ["# whitted scene suite", "",
             "Render each scene of `scenes/` (or `mitsuba/`, the same scene as Mitsuba 3 XML) "
             "with your renderer at its size, save the image under the scene's name "
             "(`glass_sphere.png`, `.exr`, `.pfm`, `.hdr` or `.ppm`) in one folder, and run "
             "`whitted suite check FOLDER --suite THIS_FOLDER`. Every scene is Whitted's "
             "light transport: light seen directly (LE), direct light on diffuse surfaces "
             "(LDE), and both seen in mirrors and through glass (LS+E, LDS+E); no indirect "
             "diffuse light. PNG and PPM images are read as sRGB unless you say "
             "`--encoding linear` or `minray`.", "",
             "| scene | size | spp | max_depth | what it tests | formulas |",
             "|---|---|---|---|---|---|"]
    for s in manifest["scenes"]:
        t = s["tests"]
        what = "; ".join(f"{k}: {', '.join(v)}" for k, v in t.items() if v)
        paths = ", ".join(f"{e} {100 * v:.0f} %" for e, v in s["light_paths"].items() if v > 0)
        formulas = "; ".join(f"{f['formula']} ({f['topic']})" for f in s["formulas"])
        lines.append(f"| {s['name']} | {s['size'][0]}x{s['size'][1]} | {s['spp']} | "
                     f"{s['max_depth']} | {what}; light paths: {paths} | {formulas} |")
    lines.append("")
    return "\n".join(lines)


# ---------------------------------------------------------------- a suite folder, read safely

#: Largest manifest.json read (the 27 built-in scenes' manifest is about 60 KB).
MAX_MANIFEST_BYTES = 16 << 20
#: Deepest nesting of objects and lists in a manifest (export writes four levels).
MAX_MANIFEST_NESTING = 16
#: A scene's name: it names the image looked for, so no path separator and no "..".
SCENE_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.+-]{0,127}")


def safe_member(root: Path, relpath, what: str) -> Path:
    """``root / relpath`` resolved, for a path read from a file in ``root``; refused unless inside.

    A member path is a non-empty relative path without a ``..`` component that,
    symbolic links resolved, names something strictly inside ``root`` (which
    need not exist yet). Anything else is refused in one line naming ``what``
    (the manifest entry), so that no read or write can leave the folder.
    Returns the resolved path: use it, not the joined one.
    """
    from whitted.tracer.errors import UserError

    shown = repr(relpath) if not isinstance(relpath, str) or len(relpath) <= 80 \
        else repr(relpath[:80] + "...")

    def refuse(why: str):
        raise UserError(f"{what}: {shown}: {why}; paths in a suite are relative and stay "
                        f"inside {root}")

    if not isinstance(relpath, str) or not relpath:
        refuse("expected a relative path (a non-empty string)")
    if "\0" in relpath:
        refuse("a NUL byte in the path")
    rel = PurePosixPath(relpath)
    if rel.is_absolute() or os.path.isabs(relpath):
        refuse("an absolute path")
    if ".." in rel.parts:
        refuse("a '..' component")
    try:
        base = Path(root).resolve(strict=True)
        full = (base / rel).resolve()
    except (OSError, RuntimeError) as e:  # RuntimeError: a symbolic link loop (Python 3.11)
        refuse(f"cannot be resolved ({getattr(e, 'strerror', None) or e})")
    if full == base or base not in full.parents:
        refuse("leads outside the suite through a symbolic link")
    return full


def read_bounded(path: Path, limit: int, what: str) -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes; a FIFO or device is refused.

    Checked with stat before opening, opened without blocking (a FIFO swapped in
    meanwhile does not hang) and checked again on the open file.
    """
    from whitted.tracer.errors import UserError

    _regular_file(path, what, limit)
    try:
        data = read_regular(path, limit)
    except NotRegularFile:
        raise UserError(f"{path}: not a regular file ({what})") from None
    except OSError as e:
        raise UserError(f"{path}: cannot read {what}: {e.strerror or e}") from None
    if len(data) > limit:
        raise UserError(f"{path}: larger than {limit:,} bytes ({what})")
    return data


def _kind(v) -> str:
    return {dict: "an object", list: "a list", str: "a string", bool: "true or false",
            int: "an integer", float: "a number", type(None): "null"}.get(type(v), "a value")


def _nesting(data) -> int:
    """How deeply objects and lists nest in ``data`` (walked without recursion)."""
    deepest, stack = 0, [(data, 0)]
    while stack:
        v, depth = stack.pop()
        deepest = max(deepest, depth)
        if depth <= MAX_MANIFEST_NESTING:
            stack.extend((x, depth + 1) for x in (v.values() if isinstance(v, dict) else
                                                  v if isinstance(v, list) else ()))
    return deepest


def validate_manifest(data, mf: Path, root: Path) -> list[dict]:
    """Check a parsed manifest's structure (module docstring); return its scene entries.

    Every field a command reads is required with its type; the fields export
    writes but nothing reads (``description``, ``depth``, ``tracer_only``,
    ``reference``, ``date``) are checked when present. Every path is checked by
    :func:`safe_member`. Errors name the entry: ``scenes[3] (glass_sphere) files.scene``.
    """
    from whitted.tracer.errors import UserError

    def bad(where: str, expected: str, v) -> None:
        raise UserError(f"{mf}: {where}: expected {expected}, got {_kind(v)}; not a whitted "
                        "suite manifest (`whitted suite export` writes one)")

    def need(obj: dict, key: str, where: str, types, expected: str, required: bool = True):
        if key not in obj:
            if required:
                raise UserError(f"{mf}: {where}: no {key!r}; not a whitted suite manifest")
            return None
        v = obj[key]
        if not isinstance(v, types) or isinstance(v, bool):
            bad(f"{where} {key}", expected, v)
        return v

    def strings(v, where: str) -> None:
        for i, x in enumerate(v):
            if not isinstance(x, str):
                bad(f"{where}[{i}]", "a string", x)

    if not isinstance(data, dict):
        bad("the document", "a JSON object", data)
    version = data.get("whitted_suite")
    if type(version) is not int or version != 1:
        raise UserError(f"{mf}: not a whitted suite manifest (\"whitted_suite\": 1 missing)")
    need(data, "date", "the document", str, "a string", required=False)
    entries = need(data, "scenes", "the document", list, "a list")
    names = set()
    for i, e in enumerate(entries):
        where = f"scenes[{i}]"
        if not isinstance(e, dict):
            bad(where, "an object", e)
        name = need(e, "name", where, str, "a string")
        if not SCENE_NAME.fullmatch(name):
            raise UserError(f"{mf}: {where} name: {name[:80]!r} is not a scene name (letters, "
                            "digits, '_', '.', '+', '-'; at most 128)")
        if name in names:
            raise UserError(f"{mf}: {where} name: {name!r} appears twice")
        names.add(name)
        where = f"{where} ({name})"
        for key in ("description",):
            need(e, key, where, str, "a string", required=False)
        for key in ("depth", "spp", "max_depth"):
            need(e, key, where, int, "an integer", required=key != "depth")
        size = need(e, "size", where, list, "a list")
        if len(size) != 2 or not all(type(x) is int and x > 0 for x in size):
            raise UserError(f"{mf}: {where} size: expected [width, height], two integers > 0")
        for key, values in need(e, "tests", where, dict, "an object").items():
            if not isinstance(values, list):
                bad(f"{where} tests.{key}", "a list", values)
            strings(values, f"{where} tests.{key}")
        for j, f in enumerate(need(e, "formulas", where, list, "a list")):
            if not isinstance(f, dict):
                bad(f"{where} formulas[{j}]", "an object", f)
            for key in ("formula", "topic"):
                need(f, key, f"{where} formulas[{j}]", str, "a string")
        for key, v in need(e, "light_paths", where, dict, "an object").items():
            if type(v) not in (int, float) or not math.isfinite(v):
                bad(f"{where} light_paths.{key}", "a finite number", v)
        strings(need(e, "tracer_only", where, list, "a list", required=False) or [],
                f"{where} tracer_only")
        need(e, "reference", where, dict, "an object", required=False)
        files = need(e, "files", where, dict, "an object")
        for key, suffix in (("scene", ".toml"), ("reference_exr", ".exr"),
                            ("reference_png", ".png")):
            rel = need(files, key, f"{where} files", str, "a string")
            if not rel.lower().endswith(suffix):
                raise UserError(f"{mf}: {where} files.{key}: {rel[:80]!r} does not end in "
                                f"{suffix}")
            safe_member(root, rel, f"{mf}: {where} files.{key}")
        for key in ("meshes", "mitsuba"):
            for j, rel in enumerate(need(files, key, f"{where} files", list, "a list",
                                         required=False) or []):
                safe_member(root, rel, f"{mf}: {where} files.{key}[{j}]")
    return entries


def read_manifest(suite_dir: Path) -> dict:
    """A suite folder's ``manifest.json``, read and validated (module docstring)."""
    from whitted.tracer.errors import UserError

    mf = suite_dir / "manifest.json"
    if not os.path.lexists(mf):
        raise UserError(f"{suite_dir}: not a suite folder (no {mf.name}; `whitted suite "
                        "export` writes one)")
    raw = read_bounded(mf, MAX_MANIFEST_BYTES, "a suite manifest")

    def no_constant(name):   # NaN and Infinity are not JSON (RFC 8259)
        raise ValueError(f"{name} is not JSON")

    try:
        data = json.loads(raw, parse_constant=no_constant)
    except RecursionError:
        raise UserError(f"{mf}: nested too deeply (a manifest needs "
                        f"{MAX_MANIFEST_NESTING} levels at most)") from None
    except ValueError as e:   # UnicodeDecodeError and JSONDecodeError among them
        from whitted.tracer.errors import one_line

        raise UserError(f"{mf}: not a whitted suite manifest (not JSON: "
                        f"{one_line(str(e), 120)})") from None
    if _nesting(data) > MAX_MANIFEST_NESTING:
        raise UserError(f"{mf}: nested more than {MAX_MANIFEST_NESTING} levels deep; a manifest "
                        "needs far fewer")
    validate_manifest(data, mf, suite_dir)
    return data


@dataclass
class SuiteEntry:
    """One scene to grade: its scene file, and the suite's stored reference (or None)."""
    name: str
    scene: Path
    reference_exr: Path | None = None
    reference_png: Path | None = None
    #: its place in the manifest's ``scenes``
    index: int = -1


@dataclass
class Suite:
    """The scenes to grade: a validated suite folder's, or (``folder`` None) the built-in ones."""
    folder: Path | None
    manifest: dict | None
    entries: list[SuiteEntry]


def load_suite(suite_dir: Path | None, pattern: str | None = None) -> Suite:
    """The scenes of a suite folder (validated, paths resolved) or the built-in scenes."""
    if suite_dir is None:
        from whitted.scenes import builtin_scenes

        return Suite(None, None, [SuiteEntry(p.stem, p)
                                  for p in select(builtin_scenes(), pattern)])
    manifest = read_manifest(suite_dir)
    root = Path(suite_dir).resolve()
    mf = suite_dir / "manifest.json"
    entries = []
    for i, e in enumerate(manifest["scenes"]):
        name = e["name"]
        if pattern and not fnmatch.fnmatch(name, pattern):
            continue
        where = f"{mf}: scenes[{i}] ({name}) files"
        files = e["files"]
        entries.append(SuiteEntry(
            name, *(safe_member(root, files[k], f"{where}.{k}")
                    for k in ("scene", "reference_exr", "reference_png")), index=i))
    return Suite(Path(suite_dir), manifest, entries)


# ---------------------------------------------------------------- grading


@dataclass
class Graded:
    name: str
    image: str | None
    passed: bool
    status: str                      # "pass", "FAIL", "missing", "error"
    message: str = ""
    run: object = None               # reference.check.judge.CheckRun
    #: the scene, image and stored reference (for --update and the page)
    scene: object = None
    user: object = None
    reference: object = None


@dataclass
class SuiteResult:
    passed: bool
    graded: list = field(default_factory=list)
    ignored: list = field(default_factory=list)
    suite: str | None = None

    def to_json(self) -> dict:
        return {"pass": self.passed, "suite": self.suite, "ignored": self.ignored,
                "scenes": [{"name": g.name, "image": g.image, "pass": g.passed,
                            "status": g.status, "message": g.message,
                            "check": None if g.run is None else g.run.to_json()}
                           for g in self.graded]}


def find_image(folder: Path, name: str) -> tuple[Path | None, str]:
    found = [folder / f"{name}{ext}" for ext in IMAGE_EXTENSIONS
             if (folder / f"{name}{ext}").is_file()]
    if len(found) > 1:
        return None, "several images: " + ", ".join(p.name for p in found)
    return (found[0], "") if found else (None, "no image")


def _stored_reference(entry: SuiteEntry, scene):
    """The entry's stored reference, checked against the scene's film (one-line errors)."""
    from whitted.tracer.errors import UserError

    ref = read_reference(entry.reference_exr, "stored reference")
    w, h = scene.film.width, scene.film.height
    if ref.image.shape != (h, w, 3):
        raise UserError(f"the stored reference {entry.reference_exr.name} of {entry.name} is "
                        f"{ref.image.shape[1]}x{ref.image.shape[0]}, the scene's film {w}x{h}")
    return ref


def grade(images: Path, suite: Suite | Path | None, pattern: str | None = None,
          encoding: str | None = None, spp: int | None = None, thresholds=None,
          log=print) -> SuiteResult:
    """Grade every scene's image in ``images``; missing and unreadable images fail.

    The scenes and the stored references are all read and checked before any
    rendering: a bad suite is bad input (one line), not a failing scene.
    """
    from whitted.reference.check.images import read_user_image
    from whitted.reference.check.judge import check_image
    from whitted.tracer import load_scene
    from whitted.tracer.errors import UserError

    if not isinstance(suite, Suite):
        suite = load_suite(suite, pattern)
    if not suite.entries:
        raise UserError(f"no scene to grade{f' matches {pattern!r}' if pattern else ''}")
    scenes = [(e, load_scene(e.scene)) for e in suite.entries]
    for e, scene in scenes:
        if e.reference_exr is not None:
            _stored_reference(e, scene)   # read again below, one at a time
    known = {e.name for e in suite.entries}
    result = SuiteResult(True, suite=None if suite.folder is None else str(suite.folder))
    result.ignored = sorted(p.name for p in images.iterdir()
                            if p.suffix.lower() in IMAGE_EXTENSIONS and p.stem not in known)
    for i, (e, scene) in enumerate(scenes, 1):
        name = e.name
        path, why = find_image(images, name)
        if path is None:
            g = Graded(name, None, False, "missing" if why == "no image" else "error", why)
        else:
            try:
                user = read_user_image(path, encoding)
                w, h = scene.film.width, scene.film.height
                if user.size != (w, h):
                    raise UserError(f"{path.name} is {user.size[0]}x{user.size[1]}, the scene's "
                                    f"film is {w}x{h}")
                ref = None if e.reference_exr is None else _stored_reference(e, scene)
                run = check_image(user, scene, spp, thresholds, reference=ref)
                g = Graded(name, path.name, run.passed, "pass" if run.passed else "FAIL",
                           "", run, scene, user, ref)
            except UserError as err:
                g = Graded(name, path.name, False, "error", str(err))
        result.graded.append(g)
        result.passed &= g.passed
        log(f"[{i}/{len(scenes)}] {name:<22} {g.image or '-':<26} {g.status}"
            + (f" ({g.message})" if g.message else ""))
    return result


#: What ``whitted suite check`` writes into its output folder: the page, the JSON, and
#: the graders' files (Gradescope's ``results.json``, a JUnit ``junit.xml``).
OUTPUT_NAMES = ("index.html", "suite.json", "results.json", "junit.xml")


def write_outputs(result: SuiteResult, outdir: Path) -> list[Path]:
    """Every file of :data:`OUTPUT_NAMES` in ``outdir`` (which exists)."""
    from whitted.reference.verdicts.compare import write_json

    write_json(outdir / "suite.json", result.to_json())
    write_json(outdir / "results.json", gradescope_results(result))
    (outdir / "junit.xml").write_bytes(junit_xml(result))
    (outdir / "index.html").write_text(suite_page(result))
    return [outdir / n for n in OUTPUT_NAMES]


# ---------------------------------------------------------------- graders: Gradescope, JUnit


def scene_report(g: Graded) -> str:
    """A graded scene in a few lines of plain text (a grader's per-test output)."""
    if g.run is None:
        return f"{g.status}: {g.message or 'no image'}" + (f" ({g.image})" if g.image else "")
    r = g.run.result
    lines = [f"{g.status}: {g.image}: {100 * r.pixels['fraction']:.3f} % of the pixels beyond "
             f"their threshold; largest region |Z| {r.regions['max_abs_z']:.2f} (limit "
             f"{r.regions['limit']:.2f})"]
    top = _top_suspect(g.run)
    if top is not None:
        lines.append(f"suspect: {top['id']} ({top['topic']}), explains "
                     f"{100 * top['explains']:.0f} % of the difference")
    return "\n".join(lines)


def gradescope_results(result: SuiteResult) -> dict:
    """The suite as a Gradescope autograder's ``results.json``: one test a scene, worth one
    point when it passes (Gradescope's documented schema: ``score``, ``max_score``,
    ``output``, ``tests`` of ``name``, ``score``, ``max_score``, ``status``, ``output``)."""
    tests = [{"name": g.name, "score": 1.0 if g.passed else 0.0, "max_score": 1.0,
              "status": "passed" if g.passed else "failed", "output": scene_report(g),
              "visibility": "visible"} for g in result.graded]
    n = sum(g.passed for g in result.graded)
    output = (f"whitted suite check: {n} of {len(result.graded)} scenes pass"
              + (f"; not graded (no such scene): {', '.join(result.ignored)}"
                 if result.ignored else ""))
    return {"score": float(n), "max_score": float(len(result.graded)), "output": output,
            "visibility": "visible", "stdout_visibility": "visible", "tests": tests}


def _xml_text(text: str) -> str:
    """``text`` with what XML 1.0 cannot carry (control characters, lone surrogates from a
    file name that is not UTF-8) written as escapes."""
    def ok(ch):
        c = ord(ch)
        return (c in (9, 10, 13) or 0x20 <= c <= 0xD7FF or 0xE000 <= c <= 0xFFFD
                or 0x10000 <= c <= 0x10FFFF)
    return "".join(ch if ok(ch) else f"\\x{ord(ch):02x}" for ch in text)


def junit_xml(result: SuiteResult) -> bytes:
    """The suite as a JUnit XML report (``testsuites/testsuite/testcase``, a ``failure`` for a
    failing or missing image, an ``error`` for one that cannot be read), as CI systems read
    it."""
    import xml.etree.ElementTree as ET

    graded = result.graded
    failures = sum(g.status in ("FAIL", "missing") for g in graded)
    errors = sum(g.status == "error" for g in graded)
    root = ET.Element("testsuites", name="whitted suite check", tests=str(len(graded)),
                      failures=str(failures), errors=str(errors))
    suite_el = ET.SubElement(root, "testsuite", name="whitted suite check",
                             tests=str(len(graded)), failures=str(failures),
                             errors=str(errors), skipped="0",
                             timestamp=_dt.datetime.now().isoformat(timespec="seconds"))
    for g in graded:
        case = ET.SubElement(suite_el, "testcase", classname="whitted.suite",
                             name=_xml_text(g.name))
        if g.passed:
            continue
        text = _xml_text(scene_report(g))
        tag, kind = ("error", "error") if g.status == "error" else ("failure", g.status)
        el = ET.SubElement(case, tag, message=text.split("\n")[0][:500], type=kind)
        el.text = text
    if result.ignored:
        out = ET.SubElement(suite_el, "system-out")
        out.text = _xml_text(f"not graded (no such scene): {', '.join(result.ignored)}")
    return ET.tostring(root, encoding="utf-8", xml_declaration=True) + b"\n"


# ---------------------------------------------------------------- --update


class PendingFiles:
    """Files written beside their targets under temporary names, renamed over them together.

    :meth:`path_for` hands out the temporary name to write (in the target's own
    folder, so the rename cannot cross file systems); :meth:`commit` renames
    them all; leaving the ``with`` block removes whatever was not renamed.
    """

    def __init__(self):
        self.moves: list[tuple[Path, Path]] = []

    def __enter__(self) -> PendingFiles:
        return self

    def path_for(self, target: Path) -> Path:
        from whitted.tracer.errors import UserError
        from whitted.tracer.imageio import TEMP_PREFIX, file_mode

        try:
            fd, tmp = tempfile.mkstemp(prefix=TEMP_PREFIX, suffix=target.suffix,
                                       dir=target.parent)
            os.close(fd)
            self.moves.append((Path(tmp), target))
            os.chmod(tmp, file_mode())
        except OSError as e:
            raise UserError(f"{target}: cannot write: {e.strerror or e}") from None
        return Path(tmp)

    def commit(self) -> None:
        from whitted.tracer.errors import UserError

        while self.moves:
            tmp, target = self.moves[0]
            try:
                os.replace(tmp, target)
            except OSError as e:
                raise UserError(f"{target}: cannot write: {e.strerror or e}") from None
            self.moves.pop(0)

    def __exit__(self, *exc) -> None:
        for tmp, _ in self.moves:
            try:
                os.unlink(tmp)
            except OSError:
                pass
        self.moves = []


def check_update_targets(suite: Suite) -> None:
    """Refuse, before any rendering, an ``--update`` that could not write all its files."""
    from whitted.tracer.errors import UserError
    from whitted.tracer.imageio import check_output_path

    if suite.folder is None:
        raise UserError("--update rewrites a suite's stored references: give --suite DIR")
    for e in suite.entries:
        check_output_path(e.reference_exr, (".exr",), "file type")
        check_output_path(e.reference_png, (".png",), "file type")
    check_output_path(suite.folder / "manifest.json", (".json",), "file type")
    check_output_path(suite.folder / "README.md", (".md",), "file type")


def stage_references(result: SuiteResult, suite: Suite, pending: PendingFiles) -> list[Path]:
    """Write the graded images as the suite's references into ``pending``; only for a pass.

    The references' ``spread`` and ``quadrature`` layers are kept (module
    docstring). Returns the reference EXRs that :meth:`PendingFiles.commit`
    will replace.
    """
    from whitted.reference.verdicts.compare import write_json
    from whitted.tracer.errors import UserError
    from whitted.tracer.imageio import write_png

    if not result.passed:
        raise ValueError("refusing to update the references of a run that fails")
    by_name = {e.name: e for e in suite.entries}
    written = []
    for g in result.graded:
        e = by_name[g.name]
        if g.user is None or g.reference is None:
            raise UserError(f"{g.name}: no image to store")
        write_reference(pending.path_for(e.reference_exr), g.user.image, g.user.variance,
                        g.reference.spread, g.reference.quadrature)
        write_png(pending.path_for(e.reference_png), g.user.image)
        suite.manifest["scenes"][e.index]["reference"] = {
            "source": f"golden image {g.image}", "updated": _now(), "storage": g.user.storage}
        written.append(e.reference_exr)
    write_json(pending.path_for(suite.folder / "manifest.json"), suite.manifest)
    pending.path_for(suite.folder / "README.md").write_text(manifest_markdown(suite.manifest))
    return written


def update_references(result: SuiteResult, suite: Suite) -> list[Path]:
    """Store the graded images as the suite's references, all or none; only for a pass."""
    check_update_targets(suite)
    with PendingFiles() as pending:
        written = stage_references(result, suite, pending)
        pending.commit()
    return written


def _top_suspect(run) -> dict | None:
    """The cause check names for a failing image's difference: a catalog bug or an output
    convention, only where check names one (``named``); None where it cannot."""
    sp = getattr(run, "suspects", None)
    if not sp or not sp.get("top") or not sp.get("named", True):
        return None
    return sp["top"][0]


def format_suite(result: SuiteResult) -> str:
    lines = [f"{'scene':<22} {'image':<26} {'pixels':>9} {'max |Z|':>8}  result"]
    for g in result.graded:
        if g.run is None:
            lines.append(f"{g.name:<22} {g.image or '-':<26} {'':>9} {'':>8}  {g.status}"
                         + (f": {g.message}" if g.message else ""))
            continue
        r = g.run.result
        lines.append(f"{g.name:<22} {g.image:<26} {100 * r.pixels['fraction']:>7.3f} % "
                     f"{r.regions['max_abs_z']:>8.2f}  {g.status}")
        top = _top_suspect(g.run)
        if top is not None:
            lines.append(f"  suspect: {top['id']} ({top['topic']}), explains "
                         f"{100 * top['explains']:.0f} % of the difference")
    n = sum(g.passed for g in result.graded)
    lines.append(f"{'PASS' if result.passed else 'FAIL'}: {n}/{len(result.graded)} scenes pass"
                 + (f"; not graded (no such scene): {', '.join(result.ignored)}"
                    if result.ignored else ""))
    return "\n".join(lines)


def suite_page(result: SuiteResult) -> str:
    """One self-contained HTML page: the table, then each scene with its viewer."""
    import html

    from whitted.reference.check.judge import PAGE_CSS, _verdict_html, describe_method, result_rows
    from whitted.reference.report.viewer import assets, viewer

    esc = html.escape
    parts = ["<!doctype html><html lang='en'><head><meta charset='utf-8'>",
             f"<title>whitted suite check</title><style>{PAGE_CSS}</style>", assets(),
             "</head><body>", f"<h1>whitted suite check: {_verdict_html(result.passed)}</h1>",
             f"<p class='meta'>{_now()}; references: "
             f"{esc(result.suite or 'rendered now by the tracer')}</p>",
             "<table><tr><th>scene</th><th>image</th><th>pixels beyond threshold</th>"
             "<th>largest region |Z|</th><th>result</th></tr>"]
    for g in result.graded:
        if g.run is None:
            parts.append(f"<tr><td>{esc(g.name)}</td><td>{esc(g.image or '-')}</td><td></td>"
                         f"<td></td><td><span class='fail'>{esc(g.status)}</span> "
                         f"{esc(g.message)}</td></tr>")
            continue
        r = g.run.result
        parts.append(f"<tr><td><a href='#{esc(g.name)}'>{esc(g.name)}</a></td>"
                     f"<td>{esc(g.image)}</td><td>{100 * r.pixels['fraction']:.3f} %</td>"
                     f"<td>{r.regions['max_abs_z']:.2f} / {r.regions['limit']:.2f}</td>"
                     f"<td>{_verdict_html(g.passed)}</td></tr>")
    parts.append("</table>")
    if result.ignored:
        parts.append(f"<p class='meta'>not graded (no such scene): "
                     f"{esc(', '.join(result.ignored))}</p>")
    for g in result.graded:
        if g.run is None:
            continue
        r = g.run.result
        a = r.arrays
        parts.append(f"<h2 id='{esc(g.name)}'>{esc(g.name)}: {_verdict_html(g.passed)}</h2>"
                     f"<p class='meta'>{esc(g.image)} ({esc(g.run.storage)}); reference: "
                     f"{esc(r.reference)}; noise: {esc(describe_method(r, g.run.spp))}</p>"
                     "<table><tr><th>check</th><th>value vs. limit</th><th>result</th></tr>"
                     f"{result_rows(r)}</table>")
        top = _top_suspect(g.run)
        if top is not None:
            parts.append(f"<p>first suspect: <code>{esc(top['id'])}</code> "
                         f"({esc(top['topic'])}): {esc(top['formula'])}, explains "
                         f"{100 * top['explains']:.0f} % of the difference</p>")
        parts.append(viewer([("your image", a["image"]), ("reference", a["reference"])],
                            marks=a["failing"]))
    parts.append("</body></html>\n")
    return "\n".join(parts)
