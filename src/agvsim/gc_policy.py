"""Python's cycle collector, set for a long fleet run.

A fleet of VDA 5050 vehicles makes many small objects every step (each vehicle's state
message, once a second, is a nest of dicts and lists, and the master keeps the latest one of
each vehicle) while hundreds of thousands of long-lived objects stand still: the layout, its
road graph, the reservation table, the vehicles. With CPython's default thresholds
(700, 10, 10) those messages live just long enough to be promoted, and the promotions keep
triggering full collections that walk every long-lived object again: measured at 1,000
vehicles on a 5,000-node layout, about a quarter of a run's wall time went to the collector
(9.3x real time; 12.8x with the collector switched off over the same simulated minutes).

Inside :func:`long_run_gc` the objects that exist when the run starts (what the build made)
are frozen out of the collector's sight (:func:`gc.freeze`, made for this), and the youngest
generation is collected every ``gen0`` allocations instead of 700, so that a message is
usually dead before it is looked at. Nothing is switched off: reference cycles made during
the run are still found, only in larger batches. Both settings are restored on exit (the
frozen objects become collectable again), so a process that runs several simulations, or
tests, is left as it was. Results do not depend on when the collector runs.
"""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager

GEN0_THRESHOLD = 10_000  # allocations between young collections (CPython's default: 700)


@contextmanager
def long_run_gc(gen0: int = GEN0_THRESHOLD) -> Iterator[None]:
    """While inside: the objects alive now frozen, young collections every ``gen0``
    allocations (never more often than the current setting). Restored on exit; nesting is
    harmless (the inner one changes nothing that the outer did not)."""
    old = gc.get_threshold()
    frozen_before = gc.get_freeze_count()
    gc.freeze()
    gc.set_threshold(max(gen0, old[0]), *old[1:])
    try:
        yield
    finally:
        gc.set_threshold(*old)
        if frozen_before == 0:  # the outermost one thaws what it froze
            gc.unfreeze()
