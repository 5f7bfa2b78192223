"""Switches that put a known formula bug into the tracer at run time, for testing the harness.

A harness that claims to find a wrong formula must be shown to find it. The
catalog of plausible bugs (``reference/mutants.py``) names each one by an id,
and the formula it breaks carries one switch: :func:`pick`, where the bug is
another value of the same kind, else a Python ``if`` on :func:`on`::

    def reflect(d, n):
        return faults.pick("reflect-sign", lambda: d + 2 * dr.dot(d, n) * n,
                           d - 2 * dr.dot(d, n) * n)

and a caller turns switches on for a block::

    with faults.active("reflect-sign"):
        image = Integrator(scene).render().image

Why this costs nothing when no switch is on, and why a switched kernel is
never reused unswitched: Dr.Jit traces the tracer's Python code into a
kernel each time it renders, and the ``if`` is decided then, in Python. With
no switch on, the traced operations are exactly those of the code without
the ``if``, so the kernels are the same (same IR, same hash: Dr.Jit's kernel
cache, in memory and on disk under ``~/.drjit``, is keyed by a hash of the
generated IR). A switch that is on changes the traced operations, hence the
IR and its hash, so its kernel is compiled and cached under another key and
is never taken for the unswitched one (``tests/tracer/test_faults.py`` checks the
hashes and that switching off restores the image bit for bit). :func:`pick`
calls the wrong value's function only when its bug is on, so it traces the
same operations as that ``if``. Inside ``active(id, shared_kernel=True)``
(the formula-bug sweep) a :func:`pick` is decided in the kernel instead, by
the bug's number, an input of the kernel that is not written into its IR:
every bug so decided shares one kernel, compiled once a scene; the scene's
numbers enter that kernel as inputs too (:func:`number`), so that a scene read
again with a bug of its placements shares it as well. A switch
decided where a scene is prepared (an emitter's area, an instance's normal
matrix) holds for Integrators built while it is on.

The tracer does not know the catalog (it never imports ``reference``): the
catalog declares its ids here (:func:`declare`), and :func:`active` refuses
an id nobody declared, in one line, so that a misspelt id cannot pass for a
bug that the harness failed to see.

:func:`recording` collects the ids that the code asked about while it ran:
a switch never asked about while a scene was traced cannot change that
scene's image, which lets a sweep skip renders that cannot differ.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from contextlib import contextmanager

#: The ids switched on now (empty: the tracer as written).
_active: frozenset[str] = frozenset()
#: Ids a catalog has declared (see :func:`declare`).
_declared: set[str] = set()
#: While :func:`recording`: the ids asked about.
_asked: set[str] | None = None
#: Inside :func:`active` with ``shared_kernel``: a jit.UInt32 (opaque) holding the
#: number of the bug switched on (:func:`_number`), which :func:`pick` compares with.
_selector = None


class UnknownFault(ValueError):
    """An id that no catalog declared; the message is one line."""


def on(fault_id: str) -> bool:
    """Whether the bug ``fault_id`` is switched on (decided in Python, at trace time)."""
    if _asked is not None:
        _asked.add(fault_id)
    return fault_id in _active


def pick(fault_id: str, buggy, correct):
    """``correct``, the formula's value, or ``buggy()`` where the bug ``fault_id`` is on.

    For a switch that chooses between two values of the same kind (numbers, Dr.Jit
    arrays, or tuples of them). Decided in Python as :func:`on` is, so that the tracer
    as written traces exactly the formula's operations; inside :func:`active` with
    ``shared_kernel``, decided in the kernel: ``select(bug == fault_id, buggy(),
    correct)`` with the bug's number an opaque value, so that every bug decided by
    :func:`pick` traces the same operations and Dr.Jit compiles one kernel for all of
    them (issue 33: a formula-bug sweep compiled a kernel per scene and bug).
    """
    if _asked is not None:
        _asked.add(fault_id)
    if _selector is not None:
        import drjit as dr

        return _select(_selector == _number(fault_id), buggy(), correct, dr)
    return buggy() if fault_id in _active else correct


def number(x):
    """A number of the scene (a position, a matrix entry, a radius, an area) as the
    kernel takes it: a Python float, written into the kernel, as the tracer is written;
    inside :func:`active` with ``shared_kernel`` an opaque jit.Float, an input of the
    kernel, so that the scene read again with a bug of its placement (the catalog's
    "parse" stage: a rotation turned the wrong way, steps composed in reverse) shares
    the sweep's one kernel a scene instead of compiling its own (issue 33)."""
    if _selector is None:
        return float(x)
    import drjit as dr

    from whitted.tracer.backend import jit
    return dr.opaque(jit.Float, float(x))


def _select(mask, a, b, dr):
    if isinstance(b, tuple):
        return tuple(_select(mask, x, y, dr) for x, y in zip(a, b, strict=True))
    numbers = (int, float)
    if (isinstance(a, numbers) and isinstance(b, numbers)
            and not isinstance(a, bool) and not isinstance(b, bool)):
        a, b = float(a), float(b)   # two Python numbers: a Float, not an Int, select
    return dr.select(mask, a, b)


_numbers: dict[str, int] = {}


def _number(fault_id: str) -> int:
    """A bug's number in the kernel: its rank among the declared ids (fixed while a
    catalog is loaded, so that a kernel's constants do not depend on which bug is on)."""
    if len(_numbers) != len(_declared):
        _numbers.clear()
        _numbers.update((k, i) for i, k in enumerate(sorted(_declared)))
    return _numbers.get(fault_id, len(_declared))


def declare(ids: Iterable[str]) -> None:
    """Make ``ids`` known to :func:`active` (a catalog of bugs calls this once)."""
    _declared.update(ids)


def declared() -> frozenset[str]:
    """The ids declared so far."""
    return frozenset(_declared)


def current() -> frozenset[str]:
    """The ids switched on now."""
    return _active


def asked(ids: Iterable[str]) -> None:
    """Count ``ids`` as asked about, as if :func:`on` had been (for a result computed
    earlier inside a :func:`recording` and reused now)."""
    if _asked is not None:
        _asked.update(ids)


@contextmanager
def active(*ids: str, shared_kernel: bool = False) -> Iterator[frozenset[str]]:
    """Switch the bugs ``ids`` on inside the block (nested blocks add to the outer ones).

    ``shared_kernel`` (one bug, no outer block): the switches of :func:`pick` are
    decided in the kernel, by a number that is not written into it, so that the bugs
    decided there share one kernel a scene; :func:`on`'s are decided in Python as
    always. The image is the same either way, up to the order in which the compiler
    rounds the same operations (tests/tracer/test_faults.py).

    Raises :class:`UnknownFault` for an id that was not declared.
    """
    global _active, _selector
    unknown = sorted(set(ids) - _declared)
    if unknown:
        raise UnknownFault(f"unknown fault id {unknown[0]!r}" +
                           (f" (and {len(unknown) - 1} more)" if len(unknown) > 1 else "") +
                           (f"; known: {len(_declared)} ids, e.g. {sorted(_declared)[0]!r}"
                            if _declared else "; no catalog has declared any"))
    saved, saved_selector = _active, _selector
    _active = saved | frozenset(ids)
    if shared_kernel and len(ids) == 1 and not saved:
        import drjit as dr

        from whitted.tracer.backend import jit
        _selector = dr.opaque(jit.UInt32, _number(ids[0]))
    else:
        _selector = None
    try:
        yield _active
    finally:
        _active, _selector = saved, saved_selector


@contextmanager
def recording() -> Iterator[set[str]]:
    """Collect, into the yielded set, every id that :func:`on` is asked about in the block."""
    global _asked
    saved = _asked
    asked: set[str] = set()
    _asked = asked
    try:
        yield asked
    finally:
        _asked = saved
        if saved is not None:
            saved.update(asked)
