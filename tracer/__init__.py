"""whitted's tracer: a Whitted ray tracer vectorised with Dr.Jit, and its scene model.

Importing this package first finds a libLLVM that Dr.Jit's LLVM backend can
use (see :mod:`tracer.llvm`), or starts the child process that checks one and
holds the first import of drjit until its answer; it must therefore be
imported before drjit.

>>> from tracer import load_scene, render                 # doctest: +SKIP
>>> result = render(load_scene("scenes/sphere_point.toml"))  # doctest: +SKIP
>>> result.image.shape                                     # doctest: +SKIP
(240, 320, 3)
"""

from whitted.tracer import llvm as _llvm

# Dr.Jit loads libLLVM when it is imported: too late to choose then. A bad
# library already loaded is refused by tracer.backend.use() with advice.
_llvm.configure_before_drjit()

from whitted.tracer.errors import SceneError, UserError  # noqa: E402
from whitted.tracer.scene import Scene, load_scene  # noqa: E402

__version__ = "0.1.0"


def render(scene, progress=None, seed=0, lpe=None):
    """Render a :class:`~tracer.scene.Scene`; return a :class:`~tracer.integrator.RenderResult`.

    ``lpe`` keeps only the light on paths matching a light-path expression such
    as ``"LDS+E"`` (Heckbert's notation, written from the light to the eye).
    """
    from whitted.tracer.integrator import render as _render

    return _render(scene, progress, seed, lpe)


__all__ = ["Scene", "SceneError", "UserError", "load_scene", "render", "__version__"]
