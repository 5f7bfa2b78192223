"""Switches that put a known formula bug into the tracer at run time, for testing the harness.

A harness that claims to find a wrong formula must be shown to find it. The
catalog of plausible bugs (``reference/mutants.py``) names each one by an id,
and the formula it breaks carries one switch, a Python ``if`` on
:func:`on`::

    def reflect(d, n):
        if faults.on("reflect-sign"):
            return d + 2 * dr.dot(d, n) * n
        return d - 2 * dr.dot(d, n) * n

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
hashes and that switching off restores the image bit for bit). A switch
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


class UnknownFault(ValueError):
    """An id that no catalog declared; the message is one line."""


def on(fault_id: str) -> bool:
    """Whether the bug ``fault_id`` is switched on (decided in Python, at trace time)."""
    if _asked is not None:
        _asked.add(fault_id)
    return fault_id in _active


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
def active(*ids: str) -> Iterator[frozenset[str]]:
    """Switch the bugs ``ids`` on inside the block (nested blocks add to the outer ones).

    Raises :class:`UnknownFault` for an id that was not declared.
    """
    global _active
    unknown = sorted(set(ids) - _declared)
    if unknown:
        raise UnknownFault(f"unknown fault id {unknown[0]!r}" +
                           (f" (and {len(unknown) - 1} more)" if len(unknown) > 1 else "") +
                           (f"; known: {len(_declared)} ids, e.g. {sorted(_declared)[0]!r}"
                            if _declared else "; no catalog has declared any"))
    saved = _active
    _active = saved | frozenset(ids)
    try:
        yield _active
    finally:
        _active = saved


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
