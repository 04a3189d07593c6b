"""agvsim.gc_policy: the collector set for a long run, and left as it was afterwards."""

from __future__ import annotations

import gc
import weakref

from agvsim.gc_policy import long_run_gc


class Node:
    def __init__(self) -> None:
        self.other: Node | None = None


def test_thresholds_and_frozen_objects_restored():
    before = gc.get_threshold()
    assert gc.get_freeze_count() == 0
    with long_run_gc(gen0=12_345):
        assert gc.get_threshold() == (max(12_345, before[0]), *before[1:])
        assert gc.get_freeze_count() > 0  # what existed on entry is out of the collector's way
        with long_run_gc(gen0=20_000):  # nested: the inner exit leaves the outer's setting
            pass
        assert gc.get_freeze_count() > 0
        assert gc.get_threshold()[0] == max(12_345, before[0])
    assert gc.get_threshold() == before
    assert gc.get_freeze_count() == 0


def test_never_collects_more_often_than_before():
    before = gc.get_threshold()
    try:
        gc.set_threshold(50_000, *before[1:])
        with long_run_gc(gen0=1_000):
            assert gc.get_threshold()[0] == 50_000
    finally:
        gc.set_threshold(*before)


def test_cycles_made_inside_are_still_collected():
    with long_run_gc():
        a, b = Node(), Node()
        a.other, b.other = b, a
        gone = weakref.ref(a)
        del a, b
        assert gone() is not None  # a cycle: reference counting alone does not free it
        gc.collect()
        assert gone() is None


def test_restored_when_the_run_raises():
    before = gc.get_threshold()
    try:
        with long_run_gc():
            raise RuntimeError("a controller raised")
    except RuntimeError:
        pass
    assert gc.get_threshold() == before
    assert gc.get_freeze_count() == 0


def test_overlapping_runs_in_threads_restore_the_setting_when_the_last_leaves():
    import threading

    before = gc.get_threshold()
    inside, leave_first = threading.Event(), threading.Event()

    def first() -> None:
        with long_run_gc(gen0=20_000):
            inside.set()
            leave_first.wait(10)

    t = threading.Thread(target=first)
    t.start()
    assert inside.wait(10)
    with long_run_gc(gen0=5_000):  # the second run starts while the first is inside ...
        leave_first.set()
        t.join(10)  # ... and the first one leaves before it
        assert gc.get_threshold()[0] == max(20_000, before[0])  # still set for this run
        assert gc.get_freeze_count() > 0
    assert gc.get_threshold() == before
    assert gc.get_freeze_count() == 0
