"""Speed targets against Mitsuba and minray, each measured as a ratio in the same run.

One subcommand per target; each prints its figures, the ratio and the target,
and the peak resident memory (ru_maxrss) of every child process it times.
Timings are medians of ``--repeat`` runs after one warm-up run (which also
fills Dr.Jit's on-disk kernel cache), so a whole-process time is that of a
process whose kernels are cached, the everyday case.

    python benchmarks/bench_speed.py direct     [--size 800x480] [--spp 64] [--repeat 3]
    python benchmarks/bench_speed.py mesh       [--triangles 1000000] [--repeat 3]
    python benchmarks/bench_speed.py recursion  [--size 256] [--spp 16] [--depth 25] [--repeat 3]
                                                [--schedule auto|wavefront|stack]
    python benchmarks/bench_speed.py quality    [--size 200x150] [--rel-rmse 0.02] [SCENE ...]
    python benchmarks/bench_speed.py memory     [--size 1920x1080] [--spp 256] [--depth 25]
    python benchmarks/bench_speed.py report     [--quick] [--cold] [--against COMMIT [--rounds 2]]
    python benchmarks/bench_speed.py process    [--size 640x480] [--spp 16] [--repeat 5]
                                                [--triangles 160000] [--ply-triangles 1000000]
    python benchmarks/bench_speed.py all        (all of them at their defaults, but memory
                                                 at 16 spp: 256 spp takes about 15 minutes
                                                 on a 2-core CPU)

Targets (what each prints beside its figures): direct light, the whole
`whitted render` process <= 0.5x a whole `mitsuba` process rendering the same
scene with `direct`, and in-process >= 3x faster; meshes, the BVH built no
slower than Mitsuba loads the scene and a render <= 1.5x Embree's; recursion,
>= 150 M rays/s on two cores beside minray's own rate; equal quality, the
tracer reaching an RMSE >= 10x sooner than Mitsuba's `path`; memory, the peak
of a 1920x1080, 256 spp, DEPTH 25 render < 4 GB; `whitted report` (full) timed
with the commit it ran on, and with --cold a cold report <= 2x a warm one, the
warm one no slower than --against's; whole processes on mesh scenes <= 1.0x a
whole Mitsuba process, cold and warm.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BIN = Path(sys.executable).parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from whitted import tracer  # noqa: E402,F401  (chooses libLLVM before drjit loads)
from whitted.tracer import llvm  # noqa: E402

# The libLLVM the tracer uses, chosen now (the import may only have started its probe)
# and exported as DRJIT_LIBLLVM_PATH, so that every child process, Mitsuba's included,
# loads the same one: left to itself, Dr.Jit loads the system's libLLVM, which on
# Debian 12 (LLVM 15) aborts Mitsuba's kernels (tracer/llvm.py).
LIBLLVM = llvm.require()

#: minray's C source (Heckbert 1987, with the fixes it needs to build), kept beside the
#: checkout in ../shared/minray/ and built at benchmark time; MINRAY_SOURCE for another.
_SHARED = Path(__file__).resolve().parents[2] / "shared"
MINRAY = Path(os.environ.get("MINRAY_SOURCE", _SHARED / "minray" / "minray.c"))
GB = 1024 ** 3


# ------------------------------------------------------------------ child processes


def _gnu_time() -> str | None:
    """GNU time, which reports its child's peak memory as measured from a small process."""
    exe = shutil.which("time") or ("/usr/bin/time" if Path("/usr/bin/time").exists() else None)
    if exe is None:
        return None
    out = subprocess.run([exe, "-f", "%M", "true"], capture_output=True, text=True)
    return exe if out.returncode == 0 and out.stderr.strip().isdigit() else None


GNU_TIME = _gnu_time()


def run_child(cmd: list[str], stdout=subprocess.DEVNULL, check: bool = True) -> tuple[float, int]:
    """Wall seconds and peak resident bytes (ru_maxrss of this child alone) of one process.

    Linux keeps a forked child's peak across exec, so a child forked from this
    (large) Python process would report at least this process's memory. GNU
    time, a small process, forks the command and reports its ru_maxrss; without
    it the figure is wait4's, an upper bound that includes this process's size.
    """
    cmd = [str(c) for c in cmd]
    with tempfile.NamedTemporaryFile("r") as rss:
        full = [GNU_TIME, "-o", rss.name, "-f", "%M", *cmd] if GNU_TIME else cmd
        t0 = time.perf_counter()
        proc = subprocess.Popen(full, stdout=stdout, stderr=subprocess.PIPE)
        _, status, usage = os.wait4(proc.pid, 0)
        seconds = time.perf_counter() - t0
        lines = rss.read().split()
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode(errors="replace")
    proc.stderr.close()
    if proc.returncode < 0 or (check and proc.returncode != 0):
        raise SystemExit(f"error: {' '.join(cmd)} exited {proc.returncode}: "
                         f"{err.strip().splitlines()[-1:] or ''}")
    kb = int(lines[-1]) if GNU_TIME and lines and lines[-1].isdigit() else usage.ru_maxrss
    return seconds, kb * 1024  # both report kilobytes


def timed_children(cmd: list[str], repeat: int, stdout=subprocess.DEVNULL,
                   check: bool = True) -> tuple[float, int]:
    """Median seconds of ``repeat`` runs after one warm-up run, and the largest peak memory."""
    _, peak = run_child(cmd, stdout, check)
    times = []
    for _ in range(repeat):
        s, m = run_child(cmd, stdout, check)
        times.append(s)
        peak = max(peak, m)
    return statistics.median(times), peak


def mb(n: int) -> str:
    return f"{n / 2 ** 20:,.0f} MB"


def self_peak() -> int:
    import resource
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def machine_note() -> str:
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    return (f"{os.cpu_count()} CPU cores, load average {load} at the start "
            "(a shared machine: other jobs ran at the same time); libLLVM "
            f"{LIBLLVM.major} ({LIBLLVM.source}) in every process")


def commit() -> str:
    try:
        rev = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                             capture_output=True, text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "--",
                                "tracer", "reference"],
                               capture_output=True, text=True).stdout.strip()
        return rev + (" (tracer/ or reference/ modified)" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def verdict(ok: bool) -> str:
    return "met" if ok else "NOT met"


# ------------------------------------------------------------------ 1. direct light


def cmd_direct(args) -> int:
    size = f"{args.size[0]}x{args.size[1]}"
    print(f"direct light: {args.scene}, {size}, {args.spp} spp; {machine_note()}")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        common = [args.scene, "--size", size, "--spp", str(args.spp)]
        # the XML is written once, untimed: the Mitsuba process only reads and renders it
        run_child([BIN / "whitted", "export", *common, "--integrator", "direct",
                   "-o", tmp / "scene.xml"])
        tracer_cmd = [BIN / "whitted", "render", *common, "-o", tmp / "tracer.exr"]
        mitsuba_cmd = [BIN / "mitsuba", "-m", "llvm_ad_rgb", tmp / "scene.xml",
                       "-o", tmp / "mitsuba.exr"]
        t_tr, m_tr = timed_children(tracer_cmd, args.repeat)
        t_mi, m_mi = timed_children(mitsuba_cmd, args.repeat)
    print(f"  whole process, median of {args.repeat} after a warm-up:")
    print(f"    whitted render              {t_tr:8.2f} s   peak {mb(m_tr)}")
    print(f"    mitsuba (direct, XML)       {t_mi:8.2f} s   peak {mb(m_mi)}")
    ratio = t_tr / t_mi
    print(f"    ratio tracer / Mitsuba = {ratio:.2f} (target <= 0.5: {verdict(ratio <= 0.5)})")
    print("  in-process (benchmarks/bench_direct.py):", flush=True)
    out = subprocess.run([sys.executable, ROOT / "benchmarks" / "bench_direct.py", args.scene,
                          "--size", size, "--spp", str(args.spp), "--repeat", str(args.repeat)],
                         capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"error: bench_direct.py failed: {out.stderr.strip()[-300:]}")
    lines = out.stdout.strip().splitlines()
    for line in lines:
        print("    " + line)
    r = float(lines[-1].split("=")[1].split()[0])
    print(f"    target Mitsuba direct / tracer >= 3: {verdict(r >= 3)}")
    return 0


# ------------------------------------------------------------------ 2. meshes


def cmd_mesh(args) -> int:
    print(f"meshes: {args.triangles:,} triangles; {machine_note()}", flush=True)
    cmd = [sys.executable, ROOT / "benchmarks" / "bench_mesh.py", "--triangles",
           str(args.triangles), "--repeat", str(args.repeat), "--size",
           f"{args.size[0]}x{args.size[1]}", "--spp", str(args.spp)]
    with tempfile.TemporaryFile("w+") as f:
        seconds, peak = run_child(cmd, stdout=f)
        f.seek(0)
        text = f.read()
    for line in text.strip().splitlines():
        print("  " + line)
    print(f"  the whole benchmark process: {seconds:.1f} s, peak {mb(peak)} "
          "(both meshes, the tracer's and Mitsuba's, in one process)")
    return 0


# ------------------------------------------------------------------ 3. recursion


def _minray_rate(size: int, depth: int, repeat: int, count: int) -> float | None:
    cc = shutil.which("cc")
    if cc is None or not MINRAY.exists():
        print(f"  minray: not run ({'no C compiler (cc)' if cc is None else f'no {MINRAY}'})")
        return None
    with tempfile.TemporaryDirectory() as tmp:
        exe = Path(tmp) / "minray"
        subprocess.run([cc, "-std=gnu89", "-w", "-O2", f"-DSIZE={size}", f"-DDEPTH={depth}",
                        MINRAY, "-o", exe, "-lm"], check=True)
        # minray's main returns no value (K&R C), so its exit status is arbitrary
        secs, peak = timed_children([exe], repeat, check=False)
    print(f"  minray (cc -O2, one thread)  {secs:8.2f} s   {count / secs / 1e6:7.1f} M rays/s"
          f"   peak {mb(peak)}  (its count from reference.teaching.minray.ray_count)")
    return secs


def _kernel_figures(integ) -> None:
    """One more render with Dr.Jit's kernel history: how many kernels, and where the time goes."""
    import drjit as dr

    dr.kernel_history_clear()
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        integ.render()
        history = dr.kernel_history()
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    ms = [k.get("execution_time", 0.0) / 1000 for k in history]
    # a kernel that traces and shades (a level's, or a chunk's with the stack schedule) has
    # over a thousand operations; the rest are the scatters, compactions and sums around it
    big = sum(t for k, t in zip(history, ms, strict=True) if k.get("operation_count", 0) > 1000)
    print(f"  schedule {integ.schedule}; kernels per render {len(history):,}; executing "
          f"{sum(ms):.3f} s, of which {big:.3f} s in the tracing and shading kernels "
          "(dr.kernel_history)")


def cmd_recursion(args) -> int:
    from whitted.reference.cli import resolve_scene
    from whitted.reference.teaching.minray import ray_count
    from whitted.tracer import backend, load_scene
    from whitted.tracer.integrator import Integrator

    name = backend.use(args.backend)
    n, depth = args.size, args.depth
    scene = load_scene(resolve_scene("heckbert_minray")).with_overrides(
        size=(n, n), max_depth=depth + 1, spp=args.spp)
    print(f"recursion: heckbert_minray, {n}x{n}, {args.spp} spp, DEPTH {depth}, backend "
          f"{name}; {machine_note()}", flush=True)
    def rate(schedule):
        integ = Integrator(scene, schedule=schedule)
        integ.render()  # warm-up: compiles the first render's kernels ...
        res = integ.render()  # ... and the later renders' (README, Speed)
        times = []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            res = integ.render()
            times.append(time.perf_counter() - t0)
        return integ, res, statistics.median(times)

    integ, res, t = rate(args.schedule)
    peak = self_peak()  # before minray's count, which is computed in numpy
    ours = res.rays_total
    _kernel_figures(integ)
    other = "wavefront" if integ.schedule == "stack" else "stack"
    o_integ, o_res, o_t = rate(other)
    if o_integ.schedule == other:
        assert o_res.rays_per_level == res.rays_per_level  # the same rays, ray for ray
        print(f"  the {other} schedule, for comparison: {o_t:.2f} s, "
              f"{o_res.rays_total / o_t / 1e6:.1f} M rays/s (the tracer below: {integ.schedule})")
    mr = ray_count(scene.with_overrides(spp=1), depth)  # minray: one ray a pixel
    print(f"  rays: tracer {ours:,} ({sum(res.rays_per_level):,} + "
          f"{sum(res.shadow_rays_per_level):,} shadow), minray {mr.total:,} "
          f"({sum(mr.trace):,} + {sum(mr.shadow):,} shadow)")
    rate = ours / t
    print(f"  tracer (in-process, median of {args.repeat})  {t:8.2f} s   {rate / 1e6:7.1f} M rays/s"
          f"   peak {mb(peak)} (this process)")
    secs = _minray_rate(n, depth, args.repeat, mr.total)
    if args.spp == 1:  # the same image as minray's: compare the times too
        print(f"  tracer's time at minray's count: {mr.total / t / 1e6:.1f} M rays/s (the same "
              "work measured by minray's rays; the tracer skips rays that cannot change the "
              "image)")
        if secs is not None:
            print(f"  ratio minray time / tracer time = {secs / t:.2f} (> 1: the tracer is "
                  "faster)")
    elif secs is not None:
        print(f"  ratio of rates tracer / minray = {rate / (mr.total / secs):.2f} (per ray; "
              f"minray renders one ray a pixel, the tracer {args.spp})")
    print(f"  target >= 150 M rays/s on two cores: {verdict(rate >= 150e6)}")
    return 0


# ------------------------------------------------------------------ 4. equal quality


GLASS = ["glass_sphere", "whitted_1980", "tir_prisms", "emitter_in_glass"]


def _rmse(a, b) -> float:
    import numpy as np
    return float(np.sqrt(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2)))


def cmd_quality(args) -> int:
    """Samples, and seconds, each integrator needs to come within an RMSE of its own limit.

    The two integrators converge to different images: Mitsuba's `path` adds the
    indirect diffuse light that Whitted's model leaves out by definition, so a
    single reference would measure that difference rather than noise, and no
    number of samples would close it. Each is therefore measured against its own
    converged image. The tracer: against its own render at ``--ref-spp`` (its
    camera samples are stratum centres, so its error is deterministic aliasing
    plus the area lights' noise; the reference's own error is at most that of
    ``--ref-spp`` samples). Mitsuba `path` (jittered strata, box filter): the
    RMSE of one render against its expectation is estimated without a reference
    from two renders of independent seeds, RMSE(a, b) / sqrt(2), since
    E|a - b|^2 = 2 E|a - mu|^2. Samples per pixel climb by about sqrt(2) (squares
    of 1, 2, 3, 4, 6, 8, 11, ...), so a ratio is resolved to within about 1.4x.
    """
    import drjit as dr
    import numpy as np

    from whitted.reference import mitsuba
    from whitted.reference.cli import resolve_scene
    from whitted.reference.renderers.mitsuba.scene import load
    from whitted.tracer import backend, load_scene
    from whitted.tracer.integrator import Integrator

    name = backend.use(args.backend)
    mi = mitsuba()
    w, h = args.size
    print(f"equal quality: {w}x{h}, relative RMSE target {args.rel_rmse} (RMSE / mean of "
          f"the converged image), backend {name}; {machine_note()}")
    print("  the tracer against its own render at "
          f"{args.ref_spp} spp; Mitsuba path against its own expectation (two seeds)")
    ladder = [n * n for n in (1, 2, 3, 4, 6, 8, 11, 16, 23, 32, 45, 64, 91, 128)]
    for sname in args.scenes:
        base = load_scene(resolve_scene(sname)).with_overrides(size=(w, h))
        ref = Integrator(base.with_overrides(spp=args.ref_spp)).render().image
        scale = float(np.mean(ref))
        goal = args.rel_rmse * scale
        t_tr = spp_tr = None
        for spp in ladder:
            if spp >= args.ref_spp:
                break
            integ = Integrator(base.with_overrides(spp=spp))
            # Compiles: an Integrator's first render and its later ones are two kernels
            # to Dr.Jit (README, Speed), so the timed render is the third.
            integ.render()
            integ.render()
            t0 = time.perf_counter()
            img = integ.render().image
            t = time.perf_counter() - t0
            if _rmse(img, ref) <= goal:
                t_tr, spp_tr, err_tr = t, spp, _rmse(img, ref)
                break
        # jittered strata, as Mitsuba samples by default: its pixel integral converges too
        ms = load(base, mi, "path", jitter=True)
        t_mi = spp_mi = None
        for spp in ladder:
            if spp > args.max_mitsuba_spp:
                break
            imgs, ts = [], []
            for seed in (0, 1):
                t0 = time.perf_counter()
                img = mi.render(ms, spp=spp, seed=seed)
                dr.eval(img)
                dr.sync_thread()
                ts.append(time.perf_counter() - t0)
                # a copy: the next render writes into the same film's storage
                imgs.append(np.array(img, dtype=np.float64, copy=True)[..., :3])
            err = _rmse(*imgs) / np.sqrt(2)
            if err <= goal:
                t_mi, spp_mi, err_mi = min(ts), spp, err
                break
        tr = (f"{spp_tr} spp, {t_tr:.3f} s (RMSE {err_tr:.4g})" if t_tr is not None
              else f"not reached below {args.ref_spp} spp")
        mt = (f"{spp_mi} spp, {t_mi:.3f} s (RMSE {err_mi:.4g})" if t_mi is not None
              else f"not reached by {args.max_mitsuba_spp} spp (last RMSE {err:.4g})")
        print(f"  {sname} (max_depth {base.film.max_depth}, goal RMSE {goal:.4g}):")
        print(f"    tracer       {tr}")
        print(f"    Mitsuba path {mt}")
        if t_tr is not None and t_mi is not None:
            r = t_mi / t_tr
            print(f"    ratio Mitsuba / tracer = {r:.1f} (target >= 10: {verdict(r >= 10)})")
        elif t_tr is not None:
            print(f"    ratio Mitsuba / tracer > {min(ts) / t_tr:.1f} "
                  "(Mitsuba did not reach the goal; a lower bound)")
        sys.stdout.flush()
    print(f"  peak resident memory of this process {mb(self_peak())}")
    return 0


# ------------------------------------------------------------------ 5. memory


def cmd_memory(args) -> int:
    size = f"{args.size[0]}x{args.size[1]}"
    print(f"memory: whitted render {args.scene} --size {size} --spp {args.spp} --depth "
          f"{args.depth}; {machine_note()}", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        secs, peak = run_child([BIN / "whitted", "render", args.scene, "--size", size,
                                "--spp", str(args.spp), "--depth", str(args.depth),
                                "-o", Path(tmp) / "out.exr"])
    print(f"  {secs:.1f} s, peak resident memory {mb(peak)} ({peak / GB:.2f} GB)")
    full = args.size == (1920, 1080) and args.spp >= 256 and args.depth >= 25
    print(f"  target < 4 GB at 1920x1080, 256 spp, DEPTH 25: {verdict(peak < 4 * GB)}"
          + ("" if full else " at the size run here, not the target's (the peak grows "
                             "with spp)"))
    return 0


# ------------------------------------------------------------------ 6. whitted report


def _import_root(root: Path) -> Path:
    """A folder that, first on PYTHONPATH, makes ``import whitted.tracer`` (and .reference,
    .scenes) load the checkout at ``root``: a ``whitted`` folder of links to its tracer/,
    reference/ and scenes/. This environment's editable install maps those names to its
    own checkout, which PYTHONPATH=root alone does not override (the repository's root is
    not a ``whitted`` folder): a baseline's report would run this checkout's code."""
    if root.resolve() == ROOT:
        return ROOT
    top = root / ".whitted-import"
    (top / "whitted").mkdir(parents=True, exist_ok=True)
    for name in ("tracer", "reference", "scenes"):
        link = top / "whitted" / name
        if not link.exists():
            link.symlink_to(root / name, target_is_directory=True)
    return top


def _time_report(root: Path, quick: bool, caches: Path | None = None
                 ) -> tuple[float, int, int]:
    """One full `whitted report` of the checkout at ``root``, run as ``python -m
    reference.cli`` with this environment's Python: (seconds, exit status, peak bytes).
    ``caches``: a folder that holds its HOME, XDG_CACHE_HOME and DRJIT_CACHE_DIR (empty
    before a cold run; kept for a warm one), else this user's own."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-m", "whitted.reference.cli", "report", "-o", tmp]
        cmd += ["--quick"] if quick else []
        env = dict(os.environ, PYTHONPATH=str(_import_root(root)))
        if caches is not None:
            env.update(HOME=str(caches), XDG_CACHE_HOME=str(caches / ".cache"),
                       DRJIT_CACHE_DIR=str(caches / ".drjit"))
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, cwd=root, env=env, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
        _, status, usage = os.wait4(proc.pid, 0)
        secs = time.perf_counter() - t0
    return secs, os.waitstatus_to_exitcode(status), usage.ru_maxrss * 1024


def _cold_and_warm(root: Path, quick: bool) -> tuple[float, float]:
    """A report with every cache empty (Dr.Jit's kernels, whitted's), then one more with
    the caches the first one left: (cold seconds, warm seconds)."""
    caches = Path(tempfile.mkdtemp(prefix="whitted-cold-"))
    try:
        cold, rc_cold, _ = _time_report(root, quick, caches)
        warm, rc_warm, _ = _time_report(root, quick, caches)
    finally:
        shutil.rmtree(caches, ignore_errors=True)
    if rc_cold or rc_warm:
        print(f"  exit status {rc_cold} cold, {rc_warm} warm")
    return cold, warm


def compile_bytecode(root: Path) -> None:
    """Byte-code for ``root``'s own modules, as ``make setup`` writes it, where it is
    missing or older than its source. An editable install leaves it to Python, and where
    PYTHONDONTWRITEBYTECODE is set (as on the machine used here) Python never writes it:
    a checkout edited since its set-up, or a new worktree, then compiles those modules
    in every process it starts, which a user's installed copy does not. Without this,
    each timed process paid that compile (a `whitted render`'s import step, as
    ``process`` splits it, was clearly longer in this checkout)."""
    subprocess.run([sys.executable, "-m", "compileall", "-q", "tracer", "reference",
                    "scenes"], cwd=root, check=True, stdout=subprocess.DEVNULL)


@contextlib.contextmanager
def _baseline_tree(rev: str):
    """A git worktree of commit ``rev``, removed afterwards: the baseline's report runs
    there, with this environment's packages (through :func:`_import_root`), alternating
    with this checkout's, so that both see the same drift of the machine."""
    wt = Path(tempfile.mkdtemp(prefix="whitted-baseline-")) / "tree"
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(wt), rev],
                   check=True, capture_output=True)
    try:
        compile_bytecode(wt)
        yield wt
    finally:
        subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(wt)],
                       capture_output=True)
        shutil.rmtree(wt.parent, ignore_errors=True)


def cmd_report_cold(args, rev: str) -> int:
    """Cold against warm, for this checkout and (--against) a baseline commit."""
    figures = {}
    with contextlib.ExitStack() as stack:
        roots = [(rev, ROOT)]
        if args.against:
            roots.insert(0, (args.against, stack.enter_context(_baseline_tree(args.against))))
        for k in range(args.rounds if args.against else 1):
            for label, root in roots:
                cold, warm = _cold_and_warm(root, args.quick)
                figures.setdefault(label, []).append((cold, warm))
                print(f"  round {k + 1}: {label:<12} cold {cold:6.1f} s, warm {warm:6.1f} s, "
                      f"cold / warm {cold / warm:.2f} (target <= 2: "
                      f"{verdict(cold <= 2 * warm)})", flush=True)
    if args.against:
        ratios = [t[1] / b[1] for t, b in zip(figures[rev], figures[args.against],
                                              strict=True)]
        print(f"  warm, this checkout's time over {args.against}'s, round by round: "
              + ", ".join(f"{r:.2f}x" for r in ratios)
              + f" (target <= 1.0: {verdict(max(ratios) <= 1.0)})")
    print("  cold: empty HOME, XDG_CACHE_HOME and DRJIT_CACHE_DIR; warm: the same folders "
          "again, as the cold run left them")
    return 0


def cmd_report(args) -> int:
    rev = commit()
    what = "--quick" if args.quick else "full"
    print(f"whitted report ({what}) at commit {rev}; {machine_note()}", flush=True)
    if args.cold:
        return cmd_report_cold(args, rev)
    if not args.against:
        secs, rc, peak = _time_report(ROOT, args.quick)
        print(f"  {secs:.0f} s ({secs / 60:.1f} min), exit status {rc}, peak {mb(peak)}")
        print("  target: half of the time measured at the baseline commit on the same "
              "machine (--against COMMIT measures both)")
        return 0
    with _baseline_tree(args.against) as wt:
        times: dict[str, list[float]] = {"baseline": [], "this": []}
        for k in range(args.rounds):
            for name, root in (("baseline", wt), ("this", ROOT)):
                secs, rc, peak = _time_report(root, args.quick)
                times[name].append(secs)
                label = args.against if name == "baseline" else rev
                print(f"  round {k + 1}: {label:<12} {secs:6.1f} s, exit status {rc}, "
                      f"peak {mb(peak)}", flush=True)
    ratios = [b / t for b, t in zip(times["baseline"], times["this"], strict=True)]
    print(f"  {args.against}'s time over this checkout's, round by round: "
          + ", ".join(f"{r:.2f}x" for r in ratios))
    print(f"  target >= 2x faster than {args.against}: {verdict(min(ratios) >= 2)} "
          "(in every round)")
    return 0



# ------------------------------------------------------------------ 7. whole process, meshes


PROCESS_SCENE = """
[film]
width = {w}
height = {h}
spp = {spp}
max_depth = 2

[camera]
origin = [0, 4.5, 7]
target = [0, 0, 0]
fov = 45

[materials.clay]
type = "diffuse"
reflectance = [0.7, 0.5, 0.3]

[materials.floor]
type = "diffuse"
reflectance = 0.5

[[lights]]
type = "point"
position = [2, 6, 4]
intensity = 60

[[shapes]]
type = "rectangle"
material = "floor"
to_world = [ {{ scale = [8, 8, 1] }}, {{ rotate = {{ axis = [1, 0, 0], angle = -90 }} }},
             {{ translate = [0, -0.6, 0] }} ]

[groups.mesh]
[[groups.mesh.shapes]]
type = "mesh"
file = "{mesh}"
material = "clay"
{instances}
"""

#: A whole Python process that imports Mitsuba, loads the exported scene and renders it.
MITSUBA_PROCESS = """
import sys
import mitsuba as mi
mi.set_variant("llvm_ad_rgb")
scene = mi.load_file(sys.argv[1])
mi.util.write_bitmap(sys.argv[2], mi.render(scene))
"""

#: The split scripts' llvm(): the seconds LLVM has spent compiling kernels so far in the
#: process (Dr.Jit's kernel history: the JIT kernels not found in its cache); called once
#: here to start the count.
_LLVM_SECONDS = """dr.set_flag(dr.JitFlag.KernelHistory, True)
def llvm():
    return sum(k["backend_time"] for k in dr.kernel_history()
               if k["type"] == dr.KernelType.JIT and not k["cache_hit"]) / 1000
llvm()
"""

#: Mitsuba's side of :data:`MITSUBA_PROCESS`, split the same way: import (with the
#: variant set), scene load (its meshes read and Embree's build), render, EXR; after the
#: load and the render, the seconds LLVM spent compiling their kernels (Dr.Jit's kernel
#: history: the kernels not found in its cache).
MITSUBA_SPLIT = """
import sys, time
t0 = time.perf_counter()
import drjit as dr
import mitsuba as mi
mi.set_variant("llvm_ad_rgb")
""" + _LLVM_SECONDS + """t1 = time.perf_counter()
scene = mi.load_file(sys.argv[1])
t2 = time.perf_counter()
c1 = llvm()
image = mi.render(scene)
dr.eval(image)
dr.sync_thread()
t3 = time.perf_counter()
c2 = llvm()
mi.util.write_bitmap(sys.argv[2], image)
t4 = time.perf_counter()
print(t1 - t0, t2 - t1, c1, t3 - t2, c2, t4 - t3)
"""

#: The tracer's first render in a fresh process, split in the order `whitted render`
#: runs it: import, mesh read, rest of the scene load, Dr.Jit's start (the libLLVM
#: choice, waiting for its probe where that is not cached, and Dr.Jit's import),
#: Integrator (BVH builds), render, EXR; after the Integrator and the render, the
#: seconds LLVM spent compiling their kernels (as in :data:`MITSUBA_SPLIT`). Freed
#: memory kept as `whitted` keeps it (reference.malloc, the command's first step).
SPLIT = """
import sys, time
t0 = time.perf_counter()
from whitted.reference.malloc import keep_freed_memory
keep_freed_memory()
from whitted.tracer import load_scene, meshio
from whitted.tracer.imageio import write_image
t1 = time.perf_counter()
read = [0.0]
load_mesh = meshio.load_mesh
def timed_load(*a, **k):
    t = time.perf_counter()
    try:
        return load_mesh(*a, **k)
    finally:
        read[0] += time.perf_counter() - t
meshio.load_mesh = timed_load
scene = load_scene(sys.argv[1])  # its film: the size and spp of the command lines
t2 = time.perf_counter()
from whitted.tracer import backend
backend.use()
import drjit as dr
from whitted.tracer.integrator import Integrator
""" + _LLVM_SECONDS + """t3 = time.perf_counter()
integ = Integrator(scene)
t4 = time.perf_counter()
c1 = llvm()
result = integ.render()
t5 = time.perf_counter()
c2 = llvm()
write_image(sys.argv[2], result.image)
t6 = time.perf_counter()
print(t1 - t0, read[0], t2 - t1 - read[0], t3 - t2, t4 - t3, c1, t5 - t4, c2, t6 - t5)
"""

#: A split's column that is the LLVM seconds of the step before it (printed beside it).
LLVM_COLUMN = "LLVM"


def _split_line(names, values) -> str:
    """``import 0.180 s, ..., render 0.900 s (LLVM 0.380 s), ...``."""
    parts = []
    for name, x in zip(names, values, strict=True):
        if name == LLVM_COLUMN:
            parts[-1] += f" ({LLVM_COLUMN} {x:.3f} s)"
        else:
            parts.append(f"{name} {x:.3f} s")
    return ", ".join(parts)


def _steps_and_llvm(names, values) -> tuple[float, float]:
    """(the sum of a split's steps, the sum of its LLVM columns, which lie within them)."""
    steps = sum(x for n, x in zip(names, values, strict=True) if n != LLVM_COLUMN)
    return steps, sum(x for n, x in zip(names, values, strict=True) if n == LLVM_COLUMN)


def write_process_scenes(folder: Path, triangles: int, ply_triangles: int, size: tuple,
                         spp: int) -> list[Path]:
    """The 160,000-triangle OBJ torus (v, vt, vn; v/vt/vn corners) placed 4 times, and a
    1,000,000-triangle binary PLY knot placed twice; each a scene beside its mesh."""
    sys.path.insert(0, str(ROOT / "scenes" / "meshes"))
    from bench_mesh_load import write_torus_obj
    from generate import torus_knot

    from whitted.tracer.meshio import write_ply

    obj = folder / "torus.obj"
    write_torus_obj(obj, triangles)
    v, fk = torus_knot(max(3, ply_triangles // 200), 100)
    ply = folder / "knot.ply"
    write_ply(ply, v * 0.8, fk)

    def instances(places):
        return "".join(
            f'\n[[shapes]]\ntype = "instance"\ngroup = "mesh"\nto_world = [ {{ rotate = '
            f'{{ axis = [0, 1, 0], angle = {angle} }} }}, {{ translate = [{x}, 0, {z}] }} ]\n'
            for x, z, angle in places)

    scenes = []
    for mesh, places in ((obj, [(-1.6, -1.2, 0), (1.6, -1.2, 30), (-1.6, 1.4, 60),
                                (1.6, 1.4, 90)]),
                         (ply, [(-1.4, 0, 0), (1.4, 0, 45)])):
        scene = folder / f"{mesh.stem}.toml"
        scene.write_text(PROCESS_SCENE.format(mesh=mesh, instances=instances(places),
                                              w=size[0], h=size[1], spp=spp))
        scenes.append(scene)
    return scenes


def _fresh_env(folder: Path) -> dict:
    """An environment whose caches are empty: HOME, XDG_CACHE_HOME and DRJIT_CACHE_DIR
    (Dr.Jit's kernel cache, ~/.drjit unless that is set) in a new folder."""
    env = dict(os.environ)
    home = Path(tempfile.mkdtemp(dir=folder))
    env.update(HOME=str(home), XDG_CACHE_HOME=str(home / ".cache"),
               DRJIT_CACHE_DIR=str(home / ".drjit"))
    return env


def _timed_process(cmd: list, env: dict | None) -> float:
    return _timed_process_cpu(cmd, env)[0]


def _timed_process_cpu(cmd: list, env: dict | None) -> tuple[float, float]:
    """(wall seconds, CPU seconds: user and system time of the process and its children)
    of one run of ``cmd``. On the 2-core machine a process that keeps both cores busy
    shows CPU time near twice its wall time: work moved onto a thread then gains nothing."""
    import resource

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([str(c) for c in cmd], env=env, check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


#: `whitted` run by a Python command line, for a baseline checkout (PYTHONPATH chooses it).
WHITTED_BY_PYTHON = ("import sys; from whitted.reference.cli import entrypoint; "
                     "sys.argv[0] = 'whitted'; sys.exit(entrypoint())")


def _with_env(env: dict | None, extra: dict) -> dict | None:
    return dict(os.environ if env is None else env, **extra) if extra else env


def cmd_process(args) -> int:
    w, h = args.size
    size = f"{w}x{h}"
    rev = commit()
    print(f"whole process with meshes: {size}, {args.spp} spp, medians of {args.repeat} "
          f"(each side alternating); commit {rev}; {machine_note()}", flush=True)
    with contextlib.ExitStack() as stack:
        tmp = Path(stack.enter_context(tempfile.TemporaryDirectory()))
        # The tracer's sides: this checkout's `whitted`, and --against's, with their
        # environment's additions.
        tracers = [(rev, [BIN / "whitted"], {})]
        if args.against:
            wt = stack.enter_context(_baseline_tree(args.against))
            tracers.insert(0, (args.against, [sys.executable, "-c", WHITTED_BY_PYTHON],
                               {"PYTHONPATH": str(_import_root(wt))}))
        script = tmp / "mitsuba_direct.py"
        script.write_text(MITSUBA_PROCESS)
        split = tmp / "split.py"
        split.write_text(SPLIT)
        mitsuba_split = tmp / "mitsuba_split.py"
        mitsuba_split.write_text(MITSUBA_SPLIT)
        for scene in write_process_scenes(tmp, args.triangles, args.ply_triangles, args.size,
                                          args.spp):
            mesh = next(tmp.glob(scene.stem + ".*[jy]"))
            xml = tmp / f"{scene.stem}.xml"
            run_child([BIN / "whitted", "export", scene, "--integrator", "direct", "--size",
                       size, "--spp", str(args.spp), "-o", xml])
            sides = [(f"whitted render ({label})", [*cmd, "render", scene, "-o",
                      tmp / "x.exr", "--size", size, "--spp", str(args.spp)], extra)
                     for label, cmd, extra in tracers]
            sides.append(("Mitsuba direct (Python process)",
                          [sys.executable, script, xml, tmp / "m.exr"], {}))
            print(f"  {scene.stem}: {mesh.name} {mesh.stat().st_size / 1e6:.1f} MB",
                  flush=True)
            for label, fresh in (("cold", True), ("warm", False)):
                if not fresh:  # fill the caches of this user's HOME first
                    for _, cmd, extra in sides:
                        _timed_process(cmd, _with_env(None, extra))
                times = {name: [] for name, _, _ in sides}
                cpu = {name: [] for name, _, _ in sides}
                for _ in range(args.repeat):
                    for name, cmd, extra in sides:
                        env = _fresh_env(tmp) if fresh else None
                        wall, used = _timed_process_cpu(cmd, _with_env(env, extra))
                        times[name].append(wall)
                        cpu[name].append(used)
                m = statistics.median(times[sides[-1][0]])
                for name, _, _ in sides:
                    t = statistics.median(times[name])
                    ratio = "" if name == sides[-1][0] else (
                        f"  ratio to Mitsuba {t / m:.2f} (target <= 1.0: {verdict(t <= m)})")
                    print(f"    {label}: {name:<34} {t:6.2f} s [{min(times[name]):.2f}-"
                          f"{max(times[name]):.2f}], CPU {statistics.median(cpu[name]):.2f} s"
                          f"{ratio}", flush=True)
            splits = [(f"tracer ({lab})", [sys.executable, split, scene, tmp / "s.exr"],
                       extra, ("import", "mesh read", "rest of scene load", "Dr.Jit start",
                               "Integrator (BVH)", LLVM_COLUMN, "render", LLVM_COLUMN, "EXR"))
                      for lab, _, extra in tracers]
            splits.append(("Mitsuba", [sys.executable, mitsuba_split, xml, tmp / "ms.exr"],
                           {}, ("import", "scene load (meshes, Embree)", LLVM_COLUMN,
                                "render", LLVM_COLUMN, "EXR")))
            for label, fresh in (("cold", True), ("warm", False)):
                rows = {name: [] for name, *_ in splits}
                for _ in range(args.repeat):
                    for name, cmd, extra, names in splits:
                        env = _with_env(_fresh_env(tmp) if fresh else None, extra)
                        out = subprocess.run([str(c) for c in cmd], capture_output=True,
                                             text=True, check=True, env=env)
                        rows[name].append([float(x) for x in
                                           out.stdout.split()[-len(names):]])
                steps = {}
                for name, _, _, names in splits:
                    med = [statistics.median(col) for col in zip(*rows[name], strict=True)]
                    steps[name] = _steps_and_llvm(names, med)
                    print(f"    {name} in-process, first of a process ({label} caches), "
                          f"medians: {_split_line(names, med)}", flush=True)
                if fresh:
                    m_total, _ = steps[splits[-1][0]]
                    for name, *_ in splits[:-1]:
                        total, compiled = steps[name]
                        print(f"    {name} cold, its LLVM time taken out: {total - compiled:.3f} "
                              f"s against Mitsuba's whole {m_total:.3f} s, ratio "
                              f"{(total - compiled) / m_total:.2f} (above 1: no cut in "
                              f"compile time alone meets the cold target)", flush=True)
    print("  the cold runs have empty HOME, XDG_CACHE_HOME and DRJIT_CACHE_DIR (Dr.Jit's "
          "kernel cache); Python's own bytecode caches stay warm")
    return 0


# ------------------------------------------------------------------ main


def main(argv=None) -> int:
    from whitted.reference.cli import _size

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--backend", default=None, help="Dr.Jit backend for in-process runs")
    sub = p.add_subparsers(dest="cmd", required=True)

    d = sub.add_parser("direct", help="whole process and in-process against Mitsuba direct")
    d.add_argument("--scene", default="three_lights")
    d.add_argument("--size", type=_size, default=(800, 480))
    d.add_argument("--spp", type=int, default=64)
    d.add_argument("--repeat", type=int, default=3)

    m = sub.add_parser("mesh", help="BVH build and render against Mitsuba/Embree")
    m.add_argument("--triangles", type=int, default=1_000_000)
    m.add_argument("--size", type=_size, default=(640, 480))
    m.add_argument("--spp", type=int, default=16)
    m.add_argument("--repeat", type=int, default=3)

    r = sub.add_parser("recursion", help="rays/s on Heckbert's scene against minray")
    r.add_argument("--size", type=int, default=256)
    r.add_argument("--depth", type=int, default=25)
    r.add_argument("--spp", type=int, default=16,
                   help="samples per pixel (16: the issue's figure; 1 renders minray's image)")
    r.add_argument("--repeat", type=int, default=3)
    r.add_argument("--schedule", choices=("auto", "wavefront", "stack"), default="auto",
                   help="the tracer's recursion schedule (auto: the stack here); the other "
                        "one's rate is printed beside it")

    q = sub.add_parser("quality", help="time to an RMSE against Mitsuba's path")
    q.add_argument("scenes", nargs="*", default=GLASS)
    q.add_argument("--size", type=_size, default=(200, 150))
    q.add_argument("--rel-rmse", type=float, default=0.02)
    q.add_argument("--ref-spp", type=int, default=1024)
    q.add_argument("--max-mitsuba-spp", type=int, default=4096)

    e = sub.add_parser("memory", help="peak memory of a large deep render")
    e.add_argument("--scene", default="heckbert_minray")
    e.add_argument("--size", type=_size, default=(1920, 1080))
    e.add_argument("--spp", type=int, default=256)
    e.add_argument("--depth", type=int, default=25)

    rp = sub.add_parser("report", help="time `whitted report`")
    rp.add_argument("--quick", action="store_true")
    rp.add_argument("--against", metavar="COMMIT",
                    help="also time COMMIT's report (a git worktree of it, run with this "
                         "environment), alternating with this checkout's, and print the "
                         "ratios (the target's baseline: 8535128)")
    rp.add_argument("--rounds", type=lambda v: max(1, int(v)), default=2,
                    help="rounds of the two reports with --against (default 2)")
    rp.add_argument("--cold", action="store_true",
                    help="each report twice: with every cache empty (a fresh machine, CI's "
                    "case), then warm; with --against, the warm times compared")

    pr = sub.add_parser("process", help="whole `whitted render` process against a whole "
                        "Python process rendering with Mitsuba's direct, on mesh scenes, "
                        "cold and warm")
    pr.add_argument("--size", type=_size, default=(640, 480))
    pr.add_argument("--spp", type=int, default=16)
    pr.add_argument("--repeat", type=int, default=5)
    pr.add_argument("--triangles", type=int, default=160_000)
    pr.add_argument("--ply-triangles", type=int, default=1_000_000)
    pr.add_argument("--against", metavar="COMMIT",
                    help="also time the `whitted render` of this commit (a git worktree "
                         "run with this environment's packages), alternating")

    sub.add_parser("all", help="every subcommand at its defaults (memory at 16 spp)")
    args = p.parse_args(argv)
    cmds = {"direct": cmd_direct, "mesh": cmd_mesh, "recursion": cmd_recursion,
            "quality": cmd_quality, "memory": cmd_memory, "report": cmd_report,
            "process": cmd_process}
    compile_bytecode(ROOT)   # the timed processes start as an installed copy's would
    if args.cmd == "all":
        for c in cmds:
            extra = ["--spp", "16"] if c == "memory" else []
            subprocess.run([sys.executable, __file__, c, *extra], check=False)
        return 0
    return cmds[args.cmd](args)


if __name__ == "__main__":
    sys.exit(main())
