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
scene's strata, or the mean of :data:`reference.compare.TRACER_SEEDS` seeds
where it samples area lights), ``variance`` (of that mean; zero where it is
deterministic), ``spread`` (the variance of one sample within each pixel,
which :func:`reference.check.footprint_factor` scales) and ``quadrature``
(:func:`reference.check.quadrature_error`). ``--update`` replaces R, G, B and
``variance`` by the golden image's and keeps the other two.

``check`` grades a folder of images named after the scenes
(``glass_sphere.png``, ``three_lights.exr``, ...) with
:func:`reference.check.check_image`, against the stored references of a
suite folder (``--suite``) or, without one, against references rendered now.
``--update`` stores the graded images as the suite's references (a renderer
developer's golden images), and refuses to when any scene fails.
"""

from __future__ import annotations

import datetime as _dt
import fnmatch
import json
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

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
    from tracer import emitters, materials

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
    from tracer.scene import Mesh

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
    from tracer.imageio import write_exr

    layers = {}
    for name, a in (("variance", variance), ("spread", spread), ("quadrature", quadrature)):
        if a is not None:
            layers.update({f"{name}.{c}": np.asarray(a[..., i], dtype=np.float32)
                           for i, c in enumerate("RGB")})
    write_exr(path, image, layers)


def read_reference(path: Path, name: str):
    """A stored reference EXR as a :class:`reference.check.Reference`."""
    from reference.check import Reference
    from tracer.imageio import read_exr_channels

    ch, _ = read_exr_channels(path)

    def layer(prefix):
        names = [f"{prefix}{c}" for c in "RGB"]
        if not all(n in ch for n in names):
            return None
        return np.stack([ch[n].astype(np.float64) for n in names], axis=-1)

    image = layer("")
    if image is None:
        from tracer.errors import UserError

        raise UserError(f"{path}: not a reference EXR (no R, G, B channels)")
    var = layer("variance.")
    if var is not None and not var.any():
        var = None
    return Reference(image, var, name, 1, layer("spread."), layer("quadrature."))


def export(outdir: Path, scene_paths: list[Path], log=print) -> dict:
    """Write the suite (module docstring); return the manifest."""
    from reference.check import tracer_reference
    from reference.compare import write_json
    from reference.mitsuba_scene import write_xml
    from reference.suspects import light_path_images
    from tracer import load_scene
    from tracer.imageio import write_png

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


# ---------------------------------------------------------------- grading


@dataclass
class Graded:
    name: str
    image: str | None
    passed: bool
    status: str                      # "pass", "FAIL", "missing", "error"
    message: str = ""
    run: object = None               # reference.check.CheckRun
    #: the scene and reference (for --update and the page)
    scene: object = None
    user: object = None


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


def load_suite(suite_dir: Path | None, pattern: str | None):
    """(name, scene path, stored reference path or None) for each scene to grade."""
    from tracer.errors import UserError

    if suite_dir is None:
        from reference.cli import builtin_scenes

        return [(p.stem, p, None) for p in select(builtin_scenes(), pattern)]
    mf = suite_dir / "manifest.json"
    try:
        manifest = json.loads(mf.read_text())
        entries = manifest["scenes"]
    except OSError as e:
        raise UserError(f"{suite_dir}: not a suite folder ({mf.name}: "
                        f"{e.strerror or e}; `whitted suite export` writes one)") from None
    except (ValueError, KeyError, TypeError):
        raise UserError(f"{mf}: not a whitted suite manifest") from None
    out = []
    for e in entries:
        name = e["name"]
        if pattern and not fnmatch.fnmatch(name, pattern):
            continue
        out.append((name, suite_dir / e["files"]["scene"],
                    suite_dir / e["files"]["reference_exr"]))
    return out


def find_image(folder: Path, name: str) -> tuple[Path | None, str]:
    found = [folder / f"{name}{ext}" for ext in IMAGE_EXTENSIONS
             if (folder / f"{name}{ext}").is_file()]
    if len(found) > 1:
        return None, "several images: " + ", ".join(p.name for p in found)
    return (found[0], "") if found else (None, "no image")


def grade(images: Path, suite_dir: Path | None, pattern: str | None = None,
          encoding: str | None = None, spp: int | None = None, thresholds=None,
          log=print) -> SuiteResult:
    """Grade every scene's image in ``images``; missing and unreadable images fail."""
    from reference.check import check_image
    from reference.user_image import read_user_image
    from tracer import load_scene
    from tracer.errors import UserError

    entries = load_suite(suite_dir, pattern)
    if not entries:
        raise UserError(f"no scene to grade{f' matches {pattern!r}' if pattern else ''}")
    scenes = [(name, load_scene(path), ref) for name, path, ref in entries]
    known = {name for name, _, _ in scenes}
    result = SuiteResult(True, suite=None if suite_dir is None else str(suite_dir))
    result.ignored = sorted(p.name for p in images.iterdir()
                            if p.suffix.lower() in IMAGE_EXTENSIONS and p.stem not in known)
    for i, (name, scene, ref_path) in enumerate(scenes, 1):
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
                ref = None if ref_path is None else read_reference(ref_path, "stored reference")
                if ref is not None and ref.image.shape != user.image.shape:
                    raise UserError(f"the stored reference {ref_path.name} is not {w}x{h}")
                run = check_image(user, scene, spp, thresholds, reference=ref)
                g = Graded(name, path.name, run.passed, "pass" if run.passed else "FAIL",
                           "", run, scene, user)
            except UserError as e:
                g = Graded(name, path.name, False, "error", str(e))
        result.graded.append(g)
        result.passed &= g.passed
        log(f"[{i}/{len(scenes)}] {name:<22} {g.image or '-':<26} {g.status}"
            + (f" ({g.message})" if g.message else ""))
    return result


def update_references(result: SuiteResult, suite_dir: Path) -> list[Path]:
    """Store the graded images as the suite's references; only for a run that passed."""
    from reference.compare import write_json
    from tracer.errors import UserError
    from tracer.imageio import write_png

    if not result.passed:
        raise ValueError("refusing to update the references of a run that fails")
    mf = suite_dir / "manifest.json"
    manifest = json.loads(mf.read_text())
    by_name = {e["name"]: e for e in manifest["scenes"]}
    written = []
    for g in result.graded:
        e = by_name[g.name]
        old = read_reference(suite_dir / e["files"]["reference_exr"], "stored reference")
        exr = suite_dir / e["files"]["reference_exr"]
        if g.user is None:
            raise UserError(f"{g.name}: no image to store")
        write_reference(exr, g.user.image, g.user.variance, old.spread, old.quadrature)
        write_png(suite_dir / e["files"]["reference_png"], g.user.image)
        e["reference"] = {"source": f"golden image {g.image}", "updated": _now(),
                          "storage": g.user.storage}
        written.append(exr)
    write_json(mf, manifest)
    (suite_dir / "README.md").write_text(manifest_markdown(manifest))
    return written


def _top_suspect(run) -> dict | None:
    """The catalog's bug that explains most of a failing image's difference (or None)."""
    sp = getattr(run, "suspects", None)
    return sp["top"][0] if sp and sp["top"] else None


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

    from reference.check import PAGE_CSS, _verdict_html, describe_method, result_rows
    from reference.viewer import assets, viewer

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
