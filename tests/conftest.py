"""Fixtures shared by several test modules (plain helper functions are in ``helpers.py``)."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import numba
import pytest

MOST_WORKERS = 8  # each worker may hold a browser, a broker or a SLAM log at once

# A shell starts a background job (`pytest &` without job control, nohup) with Ctrl-C
# ignored, and every process started from it inherits that: the tests of Ctrl-C handling
# would fail. Ctrl-C is given back its default here (the processes the tests start then get
# it too: a caught signal is reset to the default in a new program).
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


def pytest_xdist_auto_num_workers(config: pytest.Config) -> int:
    """``-n auto``: the cores this process may use, not the host's. xdist asks psutil, which
    counts every core of the host: in a container limited to 2 of 64 cores that would start 64
    workers. The affinity mask and a cgroup v2 CPU quota are what the suite really gets."""
    n = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    try:
        quota, period = Path("/sys/fs/cgroup/cpu.max").read_text().split()[:2]
        if quota != "max":
            n = min(n, max(1, int(quota) // int(period)))
    except (OSError, ValueError):
        pass
    return max(1, min(n, MOST_WORKERS))


@pytest.fixture
def one_numba_thread():
    """One ray-casting thread: with a single sensor the parallel kernel only adds thread
    wake-up latency (milliseconds per step on a busy 2-core machine)."""
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(before)


# The longest modules (minutes each on 2 cores: the demos' simulated hours, the first-run
# browser session, the long fuzz rounds, the fleet's hours, the false-closure graph): started
# first, so that no worker begins one of them while the other has run out of tests.
LONGEST_FIRST = (
    "test_demo_endurance.py",
    "test_app_firstrun_browser.py",
    "test_fuzz_inputs.py",
    "test_master_fleet.py",
    "test_posegraph_graduated.py",
)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Longest modules first, then the other modules with slow tests, then the rest; each
    module's tests stay together and in their order (module fixtures are built once a
    worker). xdist hands the tests out in this order and lets an idle worker take over the
    queue's tail."""
    slow = {item.path for item in items if item.get_closest_marker("slow") is not None}

    def rank(item: pytest.Item) -> int:
        if item.path.name in LONGEST_FIRST:
            return LONGEST_FIRST.index(item.path.name)
        return len(LONGEST_FIRST) + (0 if item.path in slow else 1)

    items.sort(key=rank)
