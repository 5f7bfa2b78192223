"""Results computed once and reused inside one job (``whitted report``).

The report judges each scene in its comparison and again in the formula-bug sweep
(:mod:`reference.mutants`), against the same references (the deterministic one, the
second opinion's one-lobe passes, seed for seed) and with the same clean tracer
renders. Inside :func:`shared` each of these is computed once per scene and
arguments; outside it nothing is kept.

Only the tracer as written is shared: while a bug is switched on
(:func:`tracer.faults.active`) everything is computed afresh and nothing is kept. The
sweep learns which bugs a scene's render can reach by recording the switches the
render asks about (:func:`tracer.faults.recording`); a shared result keeps the
switches its computation asked about and reports them again at each reuse
(:func:`tracer.faults.asked`), so a reused render reaches what a new one would.
"""

from __future__ import annotations

import hashlib
import pickle
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from whitted.tracer import faults

#: Inside :func:`shared`: key -> (result, the switches its computation asked about).
_kept: dict | None = None


@contextmanager
def shared() -> Iterator[None]:
    """Inside the block, :func:`reused` computes each result once."""
    global _kept
    saved, _kept = _kept, {}
    try:
        yield
    finally:
        _kept = saved


def reused(make: Callable, *key):
    """``make()``, or inside :func:`shared` the result of an earlier call with an equal
    key (compared by pickled content: a scene is equal to another with the same data)."""
    if _kept is None or faults.current():
        return make()
    k = hashlib.blake2b(pickle.dumps(key), digest_size=20).digest()
    if k not in _kept:
        with faults.recording() as asked:
            value = make()
        _kept[k] = (value, frozenset(asked))
    value, asked = _kept[k]
    faults.asked(asked)
    return value
