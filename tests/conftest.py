"""Fixtures shared by several test modules (plain helper functions are in ``helpers.py``)."""

from __future__ import annotations

import os
from pathlib import Path

import numba
import pytest

MOST_WORKERS = 8  # each worker may hold a browser, a broker or a SLAM log at once


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
