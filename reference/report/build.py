"""Accuracy reports: every built-in scene compared with Mitsuba, and the Fresnel curves.

:func:`build_report` renders each scene with both renderers (see
:mod:`reference.verdicts.compare` for the tests and their tolerances), tabulates the
Fresnel curves (:mod:`reference.teaching.fresnel_curves`), and writes three files:

* ``index.html``: one self-contained page (images embedded) for people;
* ``report.md``: the summary as Markdown, for a CI log or job summary;
* ``report.json``: the same for machines; its schema is in the README.

Every scene is judged against the deterministic reference (both lobes of
every mirror and glass, area lights at the tracer's light samples) at float
precision; scenes with area lights also get the one-lobe reference's
statistical verdict as a second opinion (``reference.verdicts.compare``).

``--quick`` renders every scene smaller and with fewer samples per pixel: the
tests keep their meaning at any size and sample count (the exact-strata test
is deterministic; the z-test's reference pools the same 1024 samples per
pixel either way), so a quick report checks the same things on fewer pixels.
"""

from __future__ import annotations

import base64
import datetime as _dt
import fnmatch
import html
import io
import os
import platform
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from whitted.reference.verdicts.compare import write_json

QUICK_WIDTH = 96
QUICK_SPP = 16
QUICK_FRESNEL = {"step": 1.0, "samples": 20_000}
FULL_FRESNEL = {"step": 0.5, "samples": 100_000}


@dataclass
class Report:
    passed: bool
    versions: dict
    machine: dict
    date: str
    quick: bool
    scenes: list = field(default_factory=list)        # Comparison.to_json() dicts
    fresnel: list = field(default_factory=list)       # fresnel summary rows
    fresnel_passed: bool = True
    seconds: float = 0.0
    #: the formula-bug sweep (reference.mutants.SweepResult.to_json()), or None
    mutants: dict | None = None
    #: Mitsuba scenes imported and compared with Mitsuba's render of the original
    #: (reference.renderers.mitsuba.importer.validate_case dicts)
    imported: list = field(default_factory=list)
    #: optional parts that did not run, and why ({"luxcore": "LuxCore is not installed: ..."})
    not_available: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        return {"pass": self.passed, "quick": self.quick, "date": self.date,
                "versions": self.versions, "machine": self.machine,
                "seconds": self.seconds, "scenes": self.scenes,
                "fresnel_pass": self.fresnel_passed, "fresnel": self.fresnel,
                "mutants": self.mutants, "imported": self.imported,
                "not_available": self.not_available}


def versions() -> dict:
    from importlib import metadata

    from whitted.tracer import backend, llvm

    def v(name):
        try:
            return metadata.version(name)
        except metadata.PackageNotFoundError:
            return None

    chosen = llvm.configure()
    out = {"whitted": v("whitted"), "mitsuba": v("mitsuba"), "drjit": v("drjit"),
           "numpy": v("numpy"), "python": platform.python_version(),
           "backend": backend.name(), "mitsuba_variant": backend.mitsuba_variant()}
    if backend.name() == "llvm":
        out["libllvm"] = {"path": chosen.path if chosen else None,
                          "major": chosen.major if chosen else None,
                          "source": chosen.source if chosen else None}
    return out


def machine() -> dict:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    gpu = None
    from whitted.tracer import backend

    if backend.name() == "cuda":
        try:
            import subprocess

            gpu = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"],
                                 capture_output=True, text=True, timeout=10).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            gpu = "unknown CUDA device"
    return {"host": platform.node(), "os": f"{platform.system()} {platform.release()}",
            "cpu": cpu, "cores": os.cpu_count(), "gpu": gpu}


def select_scenes(scenes_dir: Path, pattern: str | None) -> list[Path]:
    paths = sorted(scenes_dir.glob("*.toml"))
    if pattern:
        paths = [p for p in paths if fnmatch.fnmatch(p.name, pattern)
                 or fnmatch.fnmatch(p.stem, pattern) or fnmatch.fnmatch(str(p), pattern)]
    return paths


def quick_overrides(scene):
    w, h = scene.film.width, scene.film.height
    if w > QUICK_WIDTH:
        h = max(8, round(h * QUICK_WIDTH / w))
        w = QUICK_WIDTH
    return scene.with_overrides(size=(w, h), spp=min(scene.film.spp, QUICK_SPP))


#: The LuxCore child's priority, lowered to the least (``nice`` 19): it starts before the
#: comparisons and renders in what they leave of the two cores (while one thread judges an
#: image, writes files or traces a kernel), and gets little of a core that the comparisons'
#: timed renders use.
LUXCORE_NICE = 19


def build_report(outdir: str | Path, scene_paths: list[Path], quick: bool = False,
                 log=print, fresnel: bool = True, reference: str = "deterministic",
                 second_opinion: bool | None = None, mutants: bool = False,
                 luxcore: bool = False, imported: bool = False) -> Report:
    """Compare every scene, tabulate the Fresnel curves, write the three report files.

    ``mutants``: also run the formula-bug sweep of :mod:`reference.mutants` over the
    same scenes (its quick sizes for a quick report, the scenes' own otherwise) and
    Mitsuba's own XML files of :func:`reference.mutants.structure_sources` (the
    importer's bugs); the report then passes only if every bug is caught. A quick
    report's sweep runs in a worker process beside the comparisons
    (:mod:`reference.report.sweep_worker`); a full report's after them, in this process,
    reusing their references and renders.

    ``imported``: also Mitsuba's own scenes of
    :func:`reference.renderers.mitsuba.importer.imported_cases`, imported and judged
    (after the Fresnel curves; their seconds are measured beside whatever else still
    runs: LuxCore's child, the quick report's sweep).

    ``luxcore``: also the three-way verdict of each scene with LuxCore
    (:mod:`reference.renderers.luxcore.vote`, one LuxCore child process for all scenes). The
    child starts first, at the lowest priority (:data:`LUXCORE_NICE`), and renders while
    the comparisons, the Fresnel curves, the imported scenes and the sweep run.
    It does not change whether the report passes: that stays the tracer's verdict
    against Mitsuba. LuxCore's vote names the likely culprit of a disagreement (the
    tracer, Mitsuba or LuxCore), and LuxCore being the odd one out is a finding about
    LuxCore, shown in the report, not a failure of the tracer. Nor does LuxCore being
    missing, failing or past its time limits (reference.renderers.luxcore.render): the report then
    goes on without the vote, and says why in one line on stderr and as "not
    available" in its three files (:func:`not_available`).
    """
    from whitted.reference.shared import shared

    with shared():   # a full sweep reuses the comparisons' references and clean renders
        return _build_report(outdir, scene_paths, quick, log, fresnel, reference,
                             second_opinion, mutants, luxcore, imported)


def _build_report(outdir, scene_paths, quick, log, fresnel, reference, second_opinion,
                  mutants, luxcore, imported) -> Report:
    from whitted.tracer import load_scene

    start = time.perf_counter()
    out = Path(outdir)
    work = out / "scenes"
    work.mkdir(parents=True, exist_ok=True)
    scenes = [load_scene(p) for p in scene_paths]  # all validated before any rendering
    report = Report(passed=True, versions=versions(), machine=machine(),
                    date=_dt.datetime.now().astimezone().isoformat(timespec="seconds"),
                    quick=quick)
    total = len(scenes) + (1 if fresnel else 0)
    started = None
    if luxcore:
        from whitted.reference.renderers.luxcore import render as lux
        from whitted.reference.renderers.luxcore.vote import compare_three, start_three

        t_lux = time.perf_counter()
        sized = [quick_overrides(s) if quick else s for s in scenes]
        try:
            lux.require()
            started = start_three(sized, quick=quick, nice=LUXCORE_NICE)
        except Exception as e:   # an optional part: the report goes on without it
            not_available(report, "luxcore", e)
            luxcore = False
        else:
            log(f"LuxCore: three-way verdicts of {len(sized)} scenes; LuxCore renders while "
                "the report goes on")
    worker = None
    try:
        from whitted.reference.renderers.luxcore.render import SharedCores

        if mutants and quick:   # the sweep shares nothing with the comparisons at these sizes
            from whitted.reference.report import sweep_worker

            worker = sweep_worker.start(scene_paths, quick=True)
        _compare_scenes(report, scenes, work, quick, log, reference, second_opinion, total)
        # Dr.Jit on one thread while LuxCore's child renders beside the untimed parts
        with SharedCores(None if started is None else started.job) as cores:
            _fresnel(report, out, quick, log, fresnel, total)
            if imported:
                _imported(report, work, quick, log)
            if mutants:
                _sweep(report, scene_paths, quick, log, worker, cores.poll)
    except BaseException:
        if started is not None:
            started.close()
        if worker is not None:
            worker.close()
        raise
    threes = None
    if luxcore:
        try:
            threes = compare_three(sized, quick=quick, started=started,
                                   main=[{"passed": s["pass"], "checks": s["checks"]}
                                         for s in report.scenes])
        except Exception as e:   # slow or failing: the report goes on without the vote
            not_available(report, "luxcore", e)
    if threes is not None:
        for entry, t in zip(report.scenes, threes, strict=True):
            entry["luxcore"] = t.to_json()
            log(f"  {t.scene:<20} {t.verdict}" + (f" ({t.detail})" if t.detail else ""))
        log(f"LuxCore: {sum(t.compared for t in threes)} scenes compared "
            f"({time.perf_counter() - t_lux:.1f} s since it started)")
    report.seconds = time.perf_counter() - start
    data = report.to_json()
    data["scenes"] = [{k: v for k, v in s.items() if k not in ("images", "viewer")}
                      for s in report.scenes]
    write_json(out / "report.json", data)
    (out / "report.md").write_text(markdown(report))
    (out / "index.html").write_text(html_page(report, out))
    return report


#: The optional parts' names as the report shows them.
OPTIONAL_PARTS = {"luxcore": "LuxCore (the third renderer's vote)"}


def not_available(report: Report, part: str, error: BaseException) -> None:
    """Record that an optional part of the report (``part``, a key of OPTIONAL_PARTS)
    did not run, and say why in one line on stderr. The report's verdict is not touched:
    it stays the tracer's against Mitsuba."""
    import sys

    from whitted.tracer.errors import UserError, one_line

    why = str(error) if isinstance(error, UserError) else (
        f"{type(error).__name__}: {error}" if str(error) else type(error).__name__)
    why = one_line(why, 300)
    report.not_available[part] = why
    print(f"note: {OPTIONAL_PARTS.get(part, part)}: not available: {why}; the report goes on "
          "without it", file=sys.stderr, flush=True)


def _not_available_lines(report: Report) -> list[str]:
    """One sentence per optional part that did not run (the HTML and Markdown)."""
    return [f"{OPTIONAL_PARTS.get(k, k)}: not available: {why}. The report's result is the "
            "tracer's against Mitsuba, as without it."
            for k, why in report.not_available.items()]


def _compare_scenes(report, scenes, work, quick, log, reference, second_opinion,
                    total) -> None:
    """Each scene's comparison with Mitsuba, its images and light paths, into ``report``."""
    from whitted.reference.verdicts.compare import compare_scene

    for i, scene in enumerate(scenes, 1):
        if quick:
            scene = quick_overrides(scene)
        t0 = time.perf_counter()
        result, tracer_img, ref_img = compare_scene(scene, work / scene.name, reference,
                                                    second_opinion=second_opinion)
        entry = scene_entry(result)
        entry["images"] = _scene_images(work / scene.name, tracer_img, ref_img)
        entry["viewer"] = _scene_viewer(tracer_img, ref_img)
        if scene.has_specular() or scene.samples_lights():
            entry["light_paths"], entry["images"]["light_paths"] = light_paths(scene)
        report.scenes.append(entry)
        report.passed &= result.passed
        test = result.test + (" + z-test" if result.second_opinion else "")
        log(f"[{i}/{total}] {scene.name:<20} {test:<22} "
            f"{'pass' if result.passed else 'FAIL'}  ({time.perf_counter() - t0:.1f} s)")


def _fresnel(report, out, quick, log, fresnel, total) -> None:
    """The report's Fresnel curves."""
    from whitted.reference.teaching.fresnel_curves import DEFAULT_IORS, fresnel_table, plot

    if fresnel:
        t0 = time.perf_counter()
        params = QUICK_FRESNEL if quick else FULL_FRESNEL
        table = fresnel_table(DEFAULT_IORS, params["step"], params["samples"])
        plot(table, out / "fresnel.png")
        report.fresnel = table.summary
        report.fresnel_passed = table.passed
        report.passed &= table.passed
        log(f"[{total}/{total}] {'fresnel curves':<20} {'float32/CI':<22} "
            f"{'pass' if table.passed else 'FAIL'}  ({time.perf_counter() - t0:.1f} s)")


def _imported(report, work, quick, log) -> None:
    """The imported scenes of reference.renderers.mitsuba.importer, each judged."""
    from whitted.reference.renderers.mitsuba.importer import imported_cases, validate_case

    for case in imported_cases(quick):
        t0 = time.perf_counter()
        entry = validate_case(case, work / "imported")
        report.imported.append(entry)
        report.passed &= entry["passed"]
        for line in entry["structure"]["findings"]:
            log(f"[imported] {case.name:<20} structure: {line}")
        log(f"[imported] {case.name:<20} {'structure, z-test, mean':<22} "
            f"{'pass' if entry['passed'] else 'FAIL'}"
            f"{' (approximate)' if entry['approximate'] else ''}  "
            f"({time.perf_counter() - t0:.1f} s)")


def _sweep(report, scene_paths, quick, log, worker, between) -> None:
    """The formula-bug sweep: the worker's (``worker``, started beside the comparisons,
    reference.report.sweep_worker), waited for here, or run here (``worker`` None), with
    ``between()`` called between pieces of its work."""
    from whitted.reference import mutants as mutant_sweep

    t0 = time.perf_counter()
    log(f"formula bugs: {len(mutant_sweep.CATALOG)} mutants x {len(scene_paths)} scenes "
        f"({'quick' if quick else 'full'} sizes"
        f"{', swept beside the comparisons' if worker is not None else ''})")
    if worker is not None:
        data = worker.result(progress=lambda m: log("  " + m))
        seconds = time.perf_counter() - worker.start
    else:
        data = mutant_sweep.sweep(scene_paths, quick=quick, log=lambda m: log("  " + m),
                                  between=between,
                                  xml_sources=mutant_sweep.structure_sources()).to_json()
        seconds = time.perf_counter() - t0
    report.mutants = data
    report.passed &= data["pass"]
    log(f"formula bugs: {sum(m['caught'] for m in data['mutants'])}/{len(data['mutants'])} "
        f"caught, tracer as written {'passes' if data['clean_passed'] else 'FAILS'}: "
        f"{'pass' if data['pass'] else 'FAIL'}  ({seconds:.1f} s)")


#: Heckbert's expressions that partition a Whitted tracer's paths.
PARTITION = ("LE", "LDE", "LS+E", "LDS+E")


def light_paths(scene) -> tuple[dict, dict]:
    """The image split by light path: each part's share of the light, and its picture.

    The four expressions partition every path a Whitted tracer makes, so the
    parts sum to the full render; the largest deviation of that sum is kept.
    """
    from whitted.reference.verdicts.compare import shared_tracer_image
    from whitted.tracer.integrator import Integrator

    full = shared_tracer_image(scene)   # the comparison's render, where it is the same scene
    parts = {e: Integrator(scene, lpe=e).render().image for e in PARTITION}
    total = float(full.sum()) or 1.0
    shares = {e: float(img.sum()) / total for e, img in parts.items()}
    shares["sum_minus_full_max_abs"] = float(np.abs(sum(parts.values()) - full).max())
    return shares, {e: _png_bytes(img) for e, img in parts.items()}


def scene_entry(c) -> dict:
    """A scene's record in report.json (schema in the README)."""
    d = c.to_json()
    return {"name": d["scene"], "pass": d["passed"], "test": d["test"],
            "metrics": d["metrics"], "checks": d["checks"], "reason": d["reason"],
            "seconds": d["seconds"], "size": d["size"], "spp": d["spp"],
            "max_depth": d["max_depth"], "integrator": d["integrator"],
            "reference": d["reference"], "second_opinion": d["second_opinion"],
            "tracer_only_model": d.get("tracer_only_model"),
            "backend": d["backend"], "description": d["description"],
            "light_paths": None,
            "tracer_only": d["tracer_only"], "expected_deviation": d["expected_deviation"],
            "files": d["files"]}


def _png_bytes(image: np.ndarray, scale: int = 1) -> bytes:
    from PIL import Image

    from whitted.tracer.imageio import to_srgb8

    img = Image.fromarray(to_srgb8(image), "RGB")
    if scale > 1:
        img = img.resize((img.width * scale, img.height * scale), Image.NEAREST)
    buf = io.BytesIO()
    img.save(buf, format="PNG")
    return buf.getvalue()


def _scene_viewer(tracer_img, ref_img) -> str:
    """The tev-like viewer of the two renders (reference.report.viewer)."""
    from whitted.reference.report.viewer import viewer

    return viewer([("tracer", tracer_img), ("Mitsuba", ref_img)],
                  "hover for both renders' values; click to flip; wheel to zoom")


def _viewer_assets() -> str:
    from whitted.reference.report.viewer import assets

    return assets()


def _scene_images(folder: Path, tracer_img, ref_img) -> dict:
    imgs = {"tracer": _png_bytes(tracer_img), "mitsuba": _png_bytes(ref_img),
            "diff": (folder / "diff.png").read_bytes()}
    if (folder / "deviation.png").exists():
        imgs["deviation"] = (folder / "deviation.png").read_bytes()
    return imgs


# ------------------------------------------------------------------ Markdown

_LABEL = {"median_rel": "median rel.", "frac_over_5pct": "px > 5 %",
          "frac_over_01pct": "px > 0.1 %",
          "mean_rel_diff": "mean diff.", "z_fraction_passed": "z-test pass",
          "block_median_rel": "block median", "block_frac_over_5pct": "blocks > 5 %",
          "region_max_z": "regions max |Z|"}
_PCT = {"frac_over_5pct", "frac_over_01pct", "z_fraction_passed", "block_frac_over_5pct"}


def _fmt_check(key: str, c: dict) -> str:
    rel = ">=" if key == "z_fraction_passed" else "<"
    if key in _PCT:
        return f"{100 * c['value']:.2f} % {rel} {100 * c['limit']:.2f} %"
    if key == "region_max_z":
        return f"{c['value']:.2f} {rel} {c['limit']:.2f}"
    return f"{c['value']:.1e} {rel} {c['limit']:.0e}"


def _checks_text(checks: dict) -> str:
    return "; ".join(f"{_LABEL.get(k, k)} {_fmt_check(k, c)}" for k, c in checks.items())


def markdown(report: Report) -> str:
    v = report.versions
    lines = [f"# whitted accuracy report: {'PASS' if report.passed else 'FAIL'}", "",
             f"{report.date}, {'quick' if report.quick else 'full'} run, backend "
             f"{v.get('backend')}, whitted {v.get('whitted')}, mitsuba {v.get('mitsuba')}, "
             f"drjit {v.get('drjit')}, {report.machine.get('cpu')} ({report.machine.get('cores')}"
             f" cores), {report.seconds:.0f} s", "",
             *(line for s in _not_available_lines(report) for line in (s, "")),
             "| scene | size, spp, depth | reference | test | checks | median rel. | "
             "99.9th pct. rel. | FLIP | tracer s | Mitsuba s | Mitsuba/tracer | result |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for s in report.scenes:
        checks = _checks_text(s["checks"])
        so = s.get("second_opinion")
        if so:
            checks += (f"; second opinion ({so['reference']}, {so['test']}): "
                       f"{_checks_text(so['checks'])}")
        tm = s.get("tracer_only_model")
        if tm:
            checks += (f"; full render against the harness's {', '.join(tm['models'])} "
                       f"({tm['test']}): {_checks_text(tm['checks'])}")
        m = s["metrics"]
        sec = s["seconds"]
        ratio = sec.get("ratio_mitsuba_over_tracer")
        flip = s["metrics"].get("flip")
        result = "pass" if s["pass"] else "**FAIL**"
        if s.get("tracer_only"):
            result += f" (tracer-only: {', '.join(s['tracer_only'])})"
        lines.append(f"| {s['name']} | {s['size'][0]}x{s['size'][1]}, {s['spp']}, "
                     f"{s['max_depth']} | {s.get('reference', '')}"
                     f"{' + ' + so['reference'] if so else ''} | {s['test']}"
                     f"{' + ' + so['test'] if so else ''} | {checks} | "
                     f"{m['median_rel']:.1e} | {m.get('p999_rel', 0):.1e} | "
                     f"{'n/a' if flip is None else f'{flip:.4f}'} | {sec['tracer']:.3f} | "
                     f"{sec['mitsuba']:.3f} | {'' if ratio is None else f'{ratio:.2f}'} | "
                     f"{result} |")
    if any("luxcore" in s for s in report.scenes):
        lines += ["", "## Three renderers: tracer, Mitsuba, LuxCore", "",
                  "Each scene small, judged pairwise by the statistical verdict "
                  "(reference/renderers/luxcore/vote.py); the tracer-Mitsuba pair is the main "
                  "comparison above. The vote does not change the report's result.", "",
                  "| scene | size | tracer-Mitsuba | tracer-LuxCore | Mitsuba-LuxCore | "
                  "verdict |", "|---|---|---|---|---|---|"]
        for s in report.scenes:
            t = s.get("luxcore")
            if t is None:
                continue
            if not t["pairs"]:
                lines.append(f"| {s['name']} | | | | | not compared: {t['detail']} |")
                continue
            cells = ["pass" if t["pairs"][k]["passed"] else "**FAIL**"
                     for k in ("tracer-mitsuba", "tracer-luxcore", "mitsuba-luxcore")]
            verdict = t["verdict"] + (f": {t['detail']}" if t["detail"] else "")
            lines.append(f"| {s['name']} | {t['size'][0]}x{t['size'][1]} | "
                         + " | ".join(cells) + f" | {verdict} |")
    if report.fresnel:
        lines += ["", "## Fresnel curves", "",
                  "| ior | side | max abs(exact - mi.fresnel) | / float32 tol. | "
                  "max abs(plugin - exact) | / half interval | max abs(Schlick - exact) | "
                  "at | result |", "|---|---|---|---|---|---|---|---|---|"]
        for f in report.fresnel:
            ok = f["pass"]
            lines.append(
                f"| {f['ior']:g} | {f['side']} | {f['max_abs_exact_minus_mitsuba']:.1e} | "
                f"{f['worst_exact_vs_mitsuba_over_tolerance']:.2f} | "
                f"{f['max_abs_plugin_minus_exact']:.1e} | "
                f"{f['worst_plugin_deviation_in_half_intervals']:.2f} | "
                f"{f['max_abs_schlick_minus_exact']:.4f} | {f['schlick_worst_theta_deg']:.1f} | "
                f"{'pass' if ok else '**FAIL**'} |")
    if report.mutants:
        lines += ["", _mutants_markdown(report.mutants)]
    if report.imported:
        lines += ["", _imported_markdown(report.imported)]
    lines.append("")
    return "\n".join(lines)


_IMPORTED_TEXT = ("Mitsuba scenes (from Mitsuba's data repository, and mi.cornell_box()) "
                  "imported by `whitted import`, rendered by the tracer at max_depth 2, and "
                  "compared with Mitsuba's render of the *original* scene (its own filter "
                  "and sampler) under the named integrator: per-pixel z-test against the "
                  "variance of both means (Sidak-corrected, >= 99.75 % of pixels pass) and "
                  "the image means within 4 standard errors. First, the original judges the "
                  "import: Mitsuba's reading of the original file and of the import are "
                  "compared object by object (sensor, film, every shape's geometry, BSDF "
                  "and emitter parameters; reference/renderers/mitsuba/original.py), and a "
                  "difference fails the case. Scenes marked approximate had "
                  "parts outside the Whitted subset replaced.")


def _structure_cell(r: dict) -> str:
    st = r.get("structure")
    if st is None:
        return "not checked"
    if st["agrees"]:
        return f"agrees ({st['shapes']} shapes, {st['bsdfs']} BSDFs, {st['emitters']} emitters)"
    return f"{len(st['findings'])} difference(s): " + "; ".join(st["findings"][:3])


def _imported_markdown(rows: list) -> str:
    lines = ["## Imported Mitsuba scenes", "", _IMPORTED_TEXT, "",
             "| scene | source | structure | integrator | size, spp x passes | filter | "
             "z-test pixels passing | means differ by | mean z | tracer s | Mitsuba s | "
             "result |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        res = "pass" if r["passed"] else "**FAIL**"
        if r["approximate"]:
            res += " (approximate)"
        lines.append(f"| {r['name']} | {r['source']} | {_structure_cell(r)} | "
                     f"{r['integrator']} | "
                     f"{r['size'][0]}x{r['size'][1]}, {r['spp']} x {r['passes']} | "
                     f"{r['filter']} | {100 * r['z_fraction_passed']:.2f} % | "
                     f"{100 * r['mean_rel_diff']:.3f} % | {r['mean_z']:.2f} | "
                     f"{r['seconds']['tracer']:.1f} | {r['seconds']['mitsuba']:.1f} | {res} |")
    return "\n".join(lines)


def _imported_html(rows: list) -> str:
    esc = html.escape
    parts = ["<h2 id='imported'>Imported Mitsuba scenes</h2>", f"<p>{esc(_IMPORTED_TEXT)}</p>",
             "<table><tr><th>scene</th><th>source</th><th>structure</th><th>integrator</th>"
             "<th>size, spp x "
             "passes</th><th>filter</th><th>z-test pixels passing</th><th>means differ by</th>"
             "<th>mean z</th><th>result</th></tr>"]
    for r in rows:
        extra = " <span class='expected'>(approximate)</span>" if r["approximate"] else ""
        parts.append(f"<tr><td>{esc(r['name'])}</td><td>{esc(r['source'])}</td>"
                     f"<td>{esc(_structure_cell(r))}</td>"
                     f"<td>{esc(r['integrator'])}</td><td>{r['size'][0]}x{r['size'][1]}, "
                     f"{r['spp']} x {r['passes']}</td><td>{esc(r['filter'])}</td>"
                     f"<td>{100 * r['z_fraction_passed']:.2f} %</td>"
                     f"<td>{100 * r['mean_rel_diff']:.3f} %</td><td>{r['mean_z']:.2f}</td>"
                     f"<td>{_verdict(r['passed'])}{extra}</td></tr>")
    parts.append("</table>")
    return "\n".join(parts)


def _margin(x) -> str:
    return "inf (NaN)" if x is None or x == float("inf") else f"{x:.3g}"


def _mutants_markdown(mu: dict) -> str:
    """The formula-bug section of report.md."""
    lines = [f"## Formula bugs: {'PASS' if mu['pass'] else '**FAIL**'}", "",
             f"{len(mu['mutants'])} plausible bugs of the lectures' formulas "
             "(`reference/mutants.py`, `whitted mutants --list`), each switched into the "
             f"tracer in turn and judged on every scene as `whitted compare` judges it (the "
             "importer's by Mitsuba's reading of XML files, the image writer's against "
             "Mitsuba's sRGB encoding), at "
             f"{'quick' if mu['quick'] else 'full'} sizes ({mu['seconds']:.0f} s). The "
             f"tracer as written passes {sum(s['passed'] for s in mu['scenes'])} of "
             f"{len(mu['scenes'])} scenes. Margin: how many times the most violated check of "
             "a failing verdict exceeds its limit.", "",
             "| mutant | lecture topic | seen by | scenes failing | strongest (margin) | "
             "weakest (margin) |", "|---|---|---|---|---|---|"]
    for m in mu["mutants"]:
        best, worst = m["strongest"], m["weakest"]
        lines.append(
            f"| `{m['id']}` | {m['topic']} | {', '.join(m['references'])} | "
            f"{len(m['caught_by'])} | "
            + (f"{best['scene']} ({_margin(best['margin'])}) | "
               f"{worst['scene']} ({_margin(worst['margin'])})" if best else
               "**NOT CAUGHT** | ") + " |")
    return "\n".join(lines)


# ------------------------------------------------------------------ HTML

_CSS = """
body { font: 14px/1.45 system-ui, sans-serif; margin: 24px auto; max-width: 1200px;
       color: #1d1d1f; padding: 0 16px; }
h1 { margin-bottom: 4px; } h2 { margin-top: 36px; border-bottom: 1px solid #ddd; }
.pass { color: #137333; font-weight: 600; } .fail { color: #c5221f; font-weight: 600; }
.expected { color: #8a5a00; font-weight: 600; }
table { border-collapse: collapse; margin: 8px 0; font-size: 13px; }
td, th { border: 1px solid #ddd; padding: 3px 8px; text-align: left; vertical-align: top; }
th { background: #f4f4f6; }
.imgs { display: flex; gap: 12px; flex-wrap: wrap; align-items: flex-start; }
.imgs figure { margin: 0; } .imgs figcaption { font-size: 12px; color: #555; }
.imgs img.render { width: 320px; image-rendering: pixelated; border: 1px solid #ccc; }
.imgs img.map { height: 270px; }
.imgs img.lpe { width: 200px; image-rendering: pixelated; border: 1px solid #ccc; }
.meta { color: #555; font-size: 12px; } code { background: #f4f4f6; padding: 0 3px; }
"""

_ONLOAD = """
window.addEventListener('load', function () {
  var imgs = Array.prototype.slice.call(document.images);
  var ok = imgs.filter(function (i) { return i.complete && i.naturalWidth > 0; }).length;
  document.body.setAttribute('data-images-loaded', ok + '/' + imgs.length);
  var el = document.getElementById('img-status');
  if (el) { el.textContent = ok + ' of ' + imgs.length + ' images loaded'; }
});
"""


def _img(data: bytes, cls: str, alt: str) -> str:
    b64 = base64.b64encode(data).decode("ascii")
    return f'<img class="{cls}" alt="{html.escape(alt)}" src="data:image/png;base64,{b64}">'


def _verdict(ok: bool) -> str:
    return '<span class="pass">PASS</span>' if ok else '<span class="fail">FAIL</span>'


def html_page(report: Report, outdir: Path) -> str:
    v, m = report.versions, report.machine
    llvm = v.get("libllvm") or {}
    esc = html.escape
    parts = [
        "<!doctype html><html lang='en'><head><meta charset='utf-8'>",
        "<title>whitted accuracy report</title>",
        f"<style>{_CSS}</style><script>{_ONLOAD}</script>{_viewer_assets()}</head><body>",
        f"<h1>whitted accuracy report: {_verdict(report.passed)}</h1>",
        f"<p class='meta'>{esc(report.date)} &middot; {'quick' if report.quick else 'full'} run "
        f"&middot; {report.seconds:.0f} s &middot; <span id='img-status'></span></p>",
        *(f"<p class='expected not-available'>{esc(s)}</p>"
          for s in _not_available_lines(report)),
        "<p>Each scene is rendered by whitted's Dr.Jit tracer and by Mitsuba 3 at the same "
        "strata. The <b>deterministic</b> reference evaluates the whole Whitted ray tree with "
        "Mitsuba's plugins: both lobes of every mirror and glass, each with the weight "
        "Mitsuba's BSDF gives it, and area lights at the tracer's own light samples, so "
        "nothing is random. <b>exact-strata</b>: the images must agree to float32 precision "
        "(median relative difference &lt; 1e-5, at most 0.1 % of pixels beyond 1e-3, image "
        "means within 1e-4). <b>tessellated</b>: the same with limits that allow for a "
        "paraboloid, which Mitsuba sees as a fine mesh. <b>z-test</b>: the <b>onelobe</b> "
        "reference (one lobe per sample, Mitsuba's own light sampling; the second opinion on "
        "scenes with area lights) is noisy and judged statistically: per pixel against its "
        "variance (Sidak-corrected, &ge; 99.75 % of pixels, zero-variance pixels within the "
        "bound of the paths they missed), on 4&times;4 blocks, and by signed sums over each "
        "material, tile and the whole image (family-wise false-alarm rate 1e-3).</p>",
        "<table><tr><th>whitted</th><th>mitsuba</th><th>drjit</th><th>backend</th>"
        "<th>libLLVM</th><th>python</th><th>machine</th></tr>",
        f"<tr><td>{esc(str(v.get('whitted')))}</td><td>{esc(str(v.get('mitsuba')))}</td>"
        f"<td>{esc(str(v.get('drjit')))}</td><td>{esc(str(v.get('backend')))} "
        f"({esc(str(v.get('mitsuba_variant')))})</td>"
        f"<td>{esc(str(llvm.get('major', 'n/a')))} {esc(str(llvm.get('path', '')))}</td>"
        f"<td>{esc(str(v.get('python')))}</td><td>{esc(str(m.get('cpu')))}, "
        f"{m.get('cores')} cores{', ' + esc(m['gpu']) if m.get('gpu') else ''}, "
        f"{esc(str(m.get('os')))}</td></tr></table>",
        "<h2>Summary</h2><table><tr><th>scene</th><th>reference</th><th>test</th>"
        "<th>median rel.</th><th>99.9th pct. rel.</th><th>result</th>"
        "<th>tracer s</th><th>Mitsuba s</th><th>Mitsuba / tracer</th>"
        + ("<th>LuxCore (three-way verdict)</th>"
           if any("luxcore" in s for s in report.scenes) else "") + "</tr>",
    ]
    for s in report.scenes:
        sec = s["seconds"]
        ratio = sec.get("ratio_mitsuba_over_tracer")
        extra = (f" <span class='expected'>(tracer-only: {esc(', '.join(s['tracer_only']))})"
                 "</span>" if s.get("tracer_only") else "")
        so = s.get("second_opinion")
        m = s["metrics"]
        parts.append(f"<tr><td><a href='#{esc(s['name'])}'>{esc(s['name'])}</a></td>"
                     f"<td>{esc(s.get('reference', ''))}"
                     f"{' + ' + esc(so['reference']) if so else ''}</td>"
                     f"<td>{s['test']}{' + ' + so['test'] if so else ''}</td>"
                     f"<td>{m['median_rel']:.1e}</td><td>{m.get('p999_rel', 0):.1e}</td>"
                     f"<td>{_verdict(s['pass'])}{extra}</td>"
                     f"<td>{sec['tracer']:.3f}</td><td>{sec['mitsuba']:.3f}</td>"
                     f"<td>{'' if ratio is None else f'{ratio:.2f}'}</td>"
                     + _luxcore_cell(s.get("luxcore")) + "</tr>")
    if report.fresnel:
        parts.append(f"<tr><td><a href='#fresnel'>Fresnel curves</a></td><td></td><td>float32 "
                     f"/ binomial CI</td><td></td><td></td><td>{_verdict(report.fresnel_passed)}"
                     "</td><td></td><td></td><td></td></tr>")
    parts.append("</table>")
    for s in report.scenes:
        parts.append(_scene_html(s, report))
    if report.fresnel:
        parts.append(_fresnel_html(report, outdir))
    if report.mutants:
        parts.append(_mutants_html(report.mutants))
    if report.imported:
        parts.append(_imported_html(report.imported))
    parts.append("</body></html>\n")
    return "\n".join(parts)


def _luxcore_cell(t: dict | None) -> str:
    """The summary's LuxCore cell: the three-way verdict, where and by how much."""
    if t is None:
        return ""
    esc = html.escape
    if not t["pairs"]:
        return f"<td>not compared: {esc(t['detail'])}</td>"
    cls = "pass" if t["verdict"] == "all agree" else "expected"
    detail = f" ({esc(t['detail'])})" if t["detail"] else ""
    return f"<td><span class='{cls}'>{esc(t['verdict'])}</span>{detail}</td>"


def _scene_html(s: dict, report: Report) -> str:
    esc = html.escape
    imgs = s["images"] if "images" in s else {}
    sec = s["seconds"]
    ratio = sec.get("ratio_mitsuba_over_tracer")
    rows = _check_rows(s["checks"])
    so = s.get("second_opinion")
    second = ""
    if so:
        second = (f"<p>Second opinion: the <b>{esc(so['reference'])}</b> reference (Mitsuba's "
                  f"own sampling, {so['reference_passes']} passes pooled; the tracer's image "
                  f"the mean of {so['tracer_seeds']} seeds): {_verdict(so['passed'])}</p>"
                  f"<table><tr><th>check ({esc(so['test'])})</th><th>value vs. limit</th>"
                  f"<th>result</th></tr>{''.join(_check_rows(so['checks']))}</table>")
    tm = s.get("tracer_only_model")
    if tm:
        second += (f"<p>The full render, tracer-only parts included, against the "
                   f"deterministic reference with the harness's own model of them "
                   f"({esc(', '.join(tm['models']))}): {_verdict(tm['passed'])}</p>"
                   f"<table><tr><th>check ({esc(tm['test'])})</th><th>value vs. limit</th>"
                   f"<th>result</th></tr>{''.join(_check_rows(tm['checks']))}</table>")
    m = s["metrics"]
    flip = "n/a" if m.get("flip") is None else f"{m['flip']:.4f}"
    figs = [f"<figure>{_img(imgs['tracer'], 'render', 'tracer')}<figcaption>tracer"
            "</figcaption></figure>",
            f"<figure>{_img(imgs['mitsuba'], 'render', 'Mitsuba')}<figcaption>Mitsuba"
            "</figcaption></figure>",
            f"<figure>{_img(imgs['diff'], 'map', 'relative difference')}<figcaption>relative "
            "difference (log scale)</figcaption></figure>"]
    dev = ""
    if "deviation" in imgs:
        figs.append(f"<figure>{_img(imgs['deviation'], 'map', 'expected deviation')}"
                    "<figcaption>expected deviation of the full render</figcaption></figure>")
        e = s.get("expected_deviation") or {}
        dev = (f"<p class='expected'>Expected deviation (tracer-only: "
               f"{esc(', '.join(s['tracer_only']))}): median rel. "
               f"{e.get('median_rel', 0):.2e}, pixels beyond 5 %: "
               f"{100 * e.get('frac_over_5pct', 0):.2f} %, image means differ by "
               f"{100 * e.get('mean_rel_diff', 0):.2f} %. Not a failure: Mitsuba has no "
               "counterpart; the check above uses Mitsuba's equivalent.</p>")
    lp = ""
    if "light_paths" in imgs:
        shares = s.get("light_paths", {})
        lp_figs = "".join(
            f"<figure>{_img(data, 'lpe', expr)}<figcaption><code>{esc(expr)}</code>: "
            f"{100 * shares.get(expr, 0):.1f} % of the light</figcaption></figure>"
            for expr, data in imgs["light_paths"].items())
        lp = ("<p>Light paths (Heckbert's notation, from the light to the eye): the tracer's "
              "image split by <code>whitted render --lpe</code>; the parts sum to the full "
              f"image (largest difference {shares.get('sum_minus_full_max_abs', 0):.1e}).</p>"
              f"<div class='imgs'>{lp_figs}</div>")
    return (f"<h2 id='{esc(s['name'])}'>{esc(s['name'])}: {_verdict(s['pass'])}</h2>"
            f"<p>{esc(s.get('description', ''))}</p>"
            f"<p class='meta'>{s['size'][0]}&times;{s['size'][1]}, {s['spp']} spp, max_depth "
            f"{s['max_depth']}, reference {esc(s.get('reference', ''))} (integrator "
            f"{esc(s['integrator'])}), {sec.get('reference_passes', 1)} reference pass(es)</p>"
            f"<div class='imgs'>{''.join(figs)}</div>{s.get('viewer', '')}"
            f"<table><tr><th>check ({esc(s['test'])})</th><th>value vs. limit</th>"
            f"<th>result</th></tr>{''.join(rows)}</table>"
            f"<p class='meta'>Why these limits: {esc(s['reason'])}.</p>{second}{dev}"
            f"<p class='meta'>RMSE {m['rmse']:.3e}, mean rel. {m['mean_rel']:.2e}, max rel. "
            f"{m['max_rel']:.2e}, FLIP {flip}; seconds: tracer {sec['tracer']:.3f}, Mitsuba "
            f"{sec['mitsuba']:.3f}" + (f" (Mitsuba / tracer {ratio:.2f})" if ratio else "") +
            "</p>" + lp)


def _check_rows(checks: dict) -> list[str]:
    rows = []
    for k, c in checks.items():
        note = ""
        if k == "region_max_z" and c.get("regions"):
            seen = sum(g["detectable_bias"] <= 0.01 for g in c["regions"])
            best = min(g["detectable_bias"] for g in c["regions"])
            note = (f" ({len(c['regions'])} regions; a 1 % bias is seen with 90 % power in "
                    f"{seen}; smallest detectable bias {100 * best:.2f} %)")
        if k == "z_fraction_passed" and c.get("zero_variance"):
            note = (f" ({c['zero_variance']} zero-variance pixel-channels, "
                    f"{c['zero_variance_passed']} within their bound)")
        rows.append(f"<tr><td>{html.escape(_LABEL.get(k, k))}</td><td>{_fmt_check(k, c)}"
                    f"{note}</td><td>{_verdict(c['pass'])}</td></tr>")
    return rows


def _fresnel_html(report: Report, outdir: Path) -> str:
    png = (outdir / "fresnel.png").read_bytes()
    rows = []
    for f in report.fresnel:
        ok = f["pass"]
        crit = "" if f["critical_angle_deg"] is None else f"{f['critical_angle_deg']:.1f}"
        rows.append(f"<tr><td>{f['ior']:g}</td><td>{f['side']}</td><td>{crit}</td>"
                    f"<td>{f['max_abs_exact_minus_mitsuba']:.1e} "
                    f"({f['worst_exact_vs_mitsuba_over_tolerance']:.2f} of tol.)</td>"
                    f"<td>{f['max_abs_plugin_minus_exact']:.1e} "
                    f"({f['worst_plugin_deviation_in_half_intervals']:.2f} of half-CI)</td>"
                    f"<td>{f['max_abs_schlick_minus_exact']:.4f} at "
                    f"{f['schlick_worst_theta_deg']:.1f}&deg;</td><td>{_verdict(ok)}</td></tr>")
    return ("<h2 id='fresnel'>Fresnel curves: " + _verdict(report.fresnel_passed) + "</h2>"
            "<p>Our exact Fresnel reflectance against <code>mi.fresnel</code> (must agree within "
            "float32 rounding, which near the critical angle is large) and against the "
            "reflection probability of Mitsuba's <code>dielectric</code> plugin measured by "
            "sampling (must lie in its binomial interval). Schlick's approximation is shown "
            "with its error, not checked.</p>"
            f"<div class='imgs'><figure>{_img(png, 'plot', 'Fresnel curves')}</figure></div>"
            "<table><tr><th>ior</th><th>side</th><th>critical angle</th><th>exact vs "
            "mi.fresnel</th><th>plugin vs exact</th><th>Schlick error</th><th>result</th></tr>"
            + "".join(rows) + "</table>")



def _mutants_html(mu: dict) -> str:
    """The formula-bug section: one row per bug, then the bug x scene matrix of margins."""
    esc = html.escape
    names = [s["name"] for s in mu["scenes"]]
    rows = []
    for m in mu["mutants"]:
        best, worst = m["strongest"], m["weakest"]
        caught = (f"{esc(best['scene'])} ({_margin(best['margin'])}, {esc(best['check'])})"
                  if best else "<span class='fail'>NOT CAUGHT</span>")
        weak = f"{esc(worst['scene'])} ({_margin(worst['margin'])})" if worst else ""
        rows.append(f"<tr><td><code>{esc(m['id'])}</code></td><td>{esc(m['summary'])}</td>"
                    f"<td>{esc(m['topic'])}</td><td>{esc(', '.join(m['references']))}</td>"
                    f"<td>{len(m['caught_by'])}</td><td>{caught}</td><td>{weak}</td></tr>")
    grid = []
    for m in mu["mutants"]:
        by = {c["scene"]: c for c in m["caught_by"]}
        cells = []
        for n in names:
            if n in by:
                cells.append(f"<td class='fail'>{_margin(by[n]['margin'])}</td>")
            elif n in m["passed"]:
                cells.append("<td>.</td>")
            elif n in m["blind"]:
                cells.append("<td>b</td>")
            else:
                cells.append("<td></td>")
        grid.append(f"<tr><td><code>{esc(m['id'])}</code></td>{''.join(cells)}</tr>")
    head = "".join(f"<th>{esc(n)}</th>" for n in names)
    clean = "".join(f"<td>{'pass' if s['passed'] else 'FAIL'} "
                    f"({max(v['margin'] for v in s['verdicts']):.2f})</td>"
                    for s in mu["scenes"])
    return ("<h2 id='mutants'>Formula bugs: " + _verdict(mu["pass"]) + "</h2>"
            f"<p>{len(mu['mutants'])} plausible bugs of the lectures' formulas "
            "(<code>reference/mutants.py</code>), each switched into the tracer in turn "
            "(<code>tracer/faults.py</code>: no file is edited) and judged on every scene "
            "as <code>whitted compare</code> judges it, at "
            f"{'quick' if mu['quick'] else 'full'} sizes, in {mu['seconds']:.0f} s. A bug is "
            "caught by a scene whose verdict fails; its <b>margin</b> is how many times the "
            "most violated check exceeds its limit. Bugs in code the deterministic reference "
            "shares with the tracer (its pixel positions and light samples) are seen only "
            "by the one-lobe reference, which runs on scenes with area lights. Bugs of the "
            "Mitsuba XML importer are judged by the <i>structure</i> verdict (each scene "
            "written by <code>whitted export</code> and imported back, and Mitsuba's own "
            "XML files, against Mitsuba's reading of the file), bugs of the image writer by "
            "the <i>image file</i> verdict (the tracer's PNG against Mitsuba's sRGB "
            "encoding of the same image).</p>"
            "<table><tr><th>mutant</th><th>bug</th><th>lecture topic</th><th>seen by</th>"
            "<th>scenes failing</th><th>strongest catch (margin, check)</th>"
            "<th>weakest catch</th></tr>" + "".join(rows) + "</table>"
            "<p>Margins per scene (a number: the scene's verdict fails; <code>.</code>: the "
            "bug reaches the scene and its verdict passes; <code>b</code>: only verdicts "
            "blind to it reach it; empty: the scene never runs the formula). Last row: the "
            "tracer as written, with its largest check / limit.</p>"
            f"<div style='overflow-x:auto'><table><tr><th>mutant</th>{head}</tr>"
            + "".join(grid) + f"<tr><td><b>tracer as written</b></td>{clean}</tr></table></div>")
