"""The one place where the Dr.Jit backend (LLVM on the CPU, CUDA on a GPU) is chosen.

Every module of the tracer takes its array types from :data:`jit`, a proxy for
``drjit.llvm`` or ``drjit.cuda``; nothing else names a backend. The harness
maps the same choice onto Mitsuba's ``llvm_ad_rgb`` / ``cuda_ad_rgb`` variants.

The choice comes from, in order: :func:`use`'s argument, the ``WHITTED_BACKEND``
environment variable (``auto``, ``llvm`` or ``cuda``), and ``auto``, which takes
CUDA when a GPU driver answers and LLVM otherwise.
"""

from __future__ import annotations

import ctypes
import functools
import importlib
import os
from types import ModuleType

import numpy as np

from whitted.tracer import llvm

BACKENDS = ("auto", "llvm", "cuda")


class BackendUnavailable(RuntimeError):
    """The requested backend cannot run here; the message is one line."""


def _cuda_driver_has_device() -> bool:
    """Ask the CUDA driver (not Dr.Jit, which would print on failure) for a device."""
    for name in ("libcuda.so.1", "libcuda.so", "nvcuda.dll"):
        try:
            lib = ctypes.CDLL(name)
        except OSError:
            continue
        count = ctypes.c_int(0)
        try:
            if lib.cuInit(0) != 0 or lib.cuDeviceGetCount(ctypes.byref(count)) != 0:
                return False
        except AttributeError:
            return False
        return count.value > 0
    return False


_name: str | None = None
_module: ModuleType | None = None


def use(name: str | None = None) -> str:
    """Select the backend for this process and return ``"llvm"`` or ``"cuda"``.

    May be called again with the same or no name; switching backends after
    arrays were created is refused, because arrays of the two do not mix.
    """
    global _name, _module
    requested = (name or os.environ.get("WHITTED_BACKEND") or "auto").lower()
    if requested not in BACKENDS:
        raise BackendUnavailable(
            f"unknown backend {requested!r} (expected one of: {', '.join(BACKENDS)})")
    if _name is not None:
        if requested in ("auto", _name) or name is None:
            return _name
        raise BackendUnavailable(
            f"backend already set to {_name!r} in this process; cannot switch to {requested!r}")

    llvm.configure()
    if requested == "auto":
        requested = "cuda" if _cuda_driver_has_device() else "llvm"
    if requested == "llvm":
        llvm.check_loaded()  # drjit imported too early with a bad library
        llvm.require()  # raises LLVMUnavailable with its one-line advice

    import drjit as dr
    if requested == "cuda":
        if not _cuda_driver_has_device() or not dr.has_backend(dr.JitBackend.CUDA):
            raise BackendUnavailable("backend 'cuda' asked for, but no CUDA device is "
                                     "available here (use --backend llvm)")
        import drjit.cuda as module
    else:
        if not dr.has_backend(dr.JitBackend.LLVM):
            raise llvm.LLVMUnavailable(
                "Dr.Jit could not start its LLVM backend with "
                f"{os.environ.get('DRJIT_LIBLLVM_PATH')}: {llvm.INSTALL_HINT}")
        import drjit.llvm as module
    _name, _module = requested, module
    return requested


def name() -> str:
    """The selected backend, selecting the default one if none was chosen yet."""
    return use() if _name is None else _name


def new_scope() -> None:
    """Start a new basic block of Dr.Jit's tracing (``drjit.detail.new_scope``): values
    traced from here on are not merged by value numbering with those made before."""
    import drjit as dr

    dr.detail.new_scope(dr.JitBackend.CUDA if name() == "cuda" else dr.JitBackend.LLVM)


@functools.cache
def llvm_vector_width() -> int | None:
    """Lanes of the LLVM backend's SIMD packets on this CPU (16 with AVX-512, 8 with
    AVX/AVX2, 4 with SSE or NEON), or None where it cannot be asked.

    Dr.Jit 1.5's Python API does not expose it; libdrjit-core exports
    ``jit_llvm_vector_width()`` (a C++ function, so its name is mangled), read here
    through ctypes after the backend's first array has started the LLVM backend. The
    width is the process's (the backend cannot change), so it is asked once.
    """
    import drjit as dr

    if name() != "llvm":
        return None
    dr.llvm.UInt32(0)   # starts the LLVM backend (its target, so its width) if not yet
    try:
        core = ctypes.CDLL(os.path.join(os.path.dirname(dr.__file__), "libdrjit-core.so"))
        width = core["_Z21jit_llvm_vector_widthv"]
    except (OSError, AttributeError):
        return None
    width.restype = ctypes.c_uint32
    width.argtypes = []
    value = int(width())
    return value if value in (1, 2, 4, 8, 16, 32, 64) else None


def host3(v) -> np.ndarray:
    """(n, 3) numpy copy of an Array3f, a component at a time: ``v.numpy()`` of a
    3-vector runs a kernel with the width written into it, compiled anew for each
    width (a BVH level, a render's last chunk)."""
    import drjit as dr

    dr.eval(v)
    return np.stack([v.x.numpy(), v.y.numpy(), v.z.numpy()], axis=1)


def mitsuba_variant() -> str:
    """Mitsuba's variant for the selected backend (RGB, with autodiff types)."""
    return f"{name()}_ad_rgb"


class _Types:
    """Attribute access goes to ``drjit.llvm`` or ``drjit.cuda``, chosen on first use."""

    def __getattr__(self, attr: str):
        if _module is None:
            use()
        return getattr(_module, attr)


#: ``jit.Float``, ``jit.UInt32``, ``jit.Array3f``, ... of the selected backend.
jit = _Types()


class _Deferred:
    """A module imported on its first attribute access (see :func:`deferred`)."""

    def __init__(self, name: str):
        self._name = name
        self._module = None

    def __getattr__(self, attr: str):
        # The module is looked up once: importlib.import_module on every access (a
        # kernel's tracing reads dr.* thousands of times) took about 12 ms of a chunk's
        # 45 ms of tracing (the 1M-triangle benchmark scene, cProfile).
        if self._module is None:
            self._module = importlib.import_module(self._name)
        return getattr(self._module, attr)

    def __repr__(self) -> str:
        return f"<deferred module {self._name!r}>"


def deferred(name: str):
    """The module ``name``, imported when first used rather than now.

    Every material and emitter kind (tracer/materials/, tracer/emitters/) is
    imported whenever a scene is parsed, and parsing must not start Dr.Jit:
    a scene is validated first and the backend, with its libLLVM
    (:mod:`tracer.llvm`), chosen after. The kinds' modules therefore reach
    Dr.Jit and the formula modules through this:
    ``dr = deferred("drjit")``, ``fresnel = deferred("whitted.tracer.fresnel")``.
    """
    return _Deferred(name)


def lesser(a, b):
    """The smaller of ``a`` and ``b`` for values that are never NaN: ``select(a < b, a, b)``.

    ``drjit.minimum`` becomes LLVM's ``llvm.minimum``, which orders -0 below +0
    and returns NaN where either side is NaN; on x86 without AVX10.2 its
    lowering spends several more instructions than one ``vminps`` on those
    cases. Where neither can matter (box slabs and bounds of finite numbers,
    whose t values are compared, never divided by), the select is the one
    instruction: the BVH's shadow rays on the 144,000-triangle knot 101 ms to
    93 ms (medians of 7, a throwaway script of the traversal alone). Not measured
    on a GPU (none was lent), where ``drjit.minimum`` is PTX's ``min``.
    """
    import drjit as dr
    return dr.select(a < b, a, b)


def greater(a, b):
    """The larger of ``a`` and ``b`` for values that are never NaN (see :func:`lesser`)."""
    import drjit as dr
    return dr.select(a > b, a, b)


def any_mask(masks):
    """The lanes where any of the masks (a non-empty sequence of jit.Bool) is true."""
    out = masks[0]
    for m in masks[1:]:
        out = out | m
    return out


#: Byte boundary :func:`upload` puts an array's first element on.
ALIGNMENT = 64


def upload(array_type, values, dtype):
    """``array_type`` (e.g. ``jit.Float``) holding ``values`` as ``dtype``, its first element
    on a 64-byte boundary.

    On the CPU, Dr.Jit uses the memory of a contiguous numpy array it is given
    instead of copying it, and writes into each kernel whether that memory is
    aligned (an array of one float at an address that is not a multiple of 64
    is loaded with ``align 1``, else ``align 4``). numpy places small arrays on
    16- or 32-byte boundaries as it happens, so the same scene built twice gave
    kernels that differed in that one word: another hash, so no hit in Dr.Jit's
    kernel cache, and LLVM compiled the kernel again (about 0.1 s for the
    one-kernel recursion of :class:`tracer.integrator.Integrator`, at every
    render of the formula-bug sweep). Placed on a 64-byte boundary, the
    arrays give the same kernel every time, and a 16-float record fills one
    cache line (the BVH's node records). Elsewhere (CUDA) Dr.Jit copies the
    data into its own memory, aligned too.
    """
    import numpy as np

    src = np.asarray(values)
    dtype = np.dtype(dtype)
    if src.dtype == dtype and src.flags.c_contiguous and src.ctypes.data % ALIGNMENT == 0:
        return array_type(src.reshape(-1))
    # Converted and placed in one pass (a column of an (N, 3) array, int64 indices made
    # uint32), rather than a converted copy and then an aligned copy of that.
    pad = ALIGNMENT // dtype.itemsize
    buf = np.empty(src.size + pad, dtype=dtype)
    start = (-buf.ctypes.data % ALIGNMENT) // dtype.itemsize
    view = buf[start:start + src.size]
    np.copyto(view.reshape(src.shape), src, casting="unsafe")
    return array_type(view)


def aligned_zeros(shape, dtype):
    """A zeroed numpy array whose first element is on a 64-byte boundary: filled in place,
    it goes to :func:`upload` without a copy. For the large arrays built to be uploaded
    (a BVH's records), whose copy into fresh pages (64 MB of triangle records for a
    1,000,000-triangle mesh) was a cost of every ``whitted render`` of such a mesh
    (issue 33)."""
    import numpy as np

    dtype = np.dtype(dtype)
    n = int(np.prod(shape))
    pad = ALIGNMENT // dtype.itemsize
    buf = np.zeros(n + pad, dtype=dtype)
    start = (-buf.ctypes.data % ALIGNMENT) // dtype.itemsize
    return buf[start:start + n].reshape(shape)


def upload_rows(array_type, rows, dtype="float32"):
    """A vector array type (``jit.Array3f``, ``jit.Array2f``) of (N, k) rows, one
    :func:`upload` per component."""
    import drjit as dr
    import numpy as np

    width = dr.size_v(array_type)
    a = np.asarray(rows, dtype=dtype).reshape(-1, width)
    return array_type(*(upload(dr.value_t(array_type), a[:, k], dtype) for k in range(width)))
