"""Fixtures shared by several test modules (plain helper functions are in ``helpers.py``)."""

from __future__ import annotations

import functools
import os
import re
import signal
from pathlib import Path

import numba
import pytest
from xdist.scheduler import LoadScopeScheduling

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


# The longest modules (minutes each on 2 cores: the demos' simulated hours, the browser
# sessions, the long fuzz rounds, the fleet's hours, the false-closure graph): started first,
# so that no worker begins one of them while the other has run out of tests.
LONGEST_FIRST = (
    "test_demo_endurance.py",
    "test_app_firstrun_browser.py",
    "test_fuzz_inputs.py",
    "test_master_fleet.py",
    "test_posegraph_graduated.py",
)

# Every test that opens headless Chromium (helpers.chromium) runs on one worker, one after the
# other: the browsers take turns anyway (helpers.one_browser_at_a_time), and a worker that
# waited for the other's browser sat idle (over two minutes of the suite's worker time).
BROWSER_MODULES = frozenset(
    {
        "test_app_browser.py",
        "test_app_firstrun_browser.py",
        "test_dynamics_browser.py",
        "test_replay_browser.py",
    }
)
_SHARED_FIXTURE = re.compile(r"scope\s*=\s*[\"'](module|package|session)[\"']")


@functools.cache
def _shares_a_fixture(path: Path) -> bool:
    """True when a test module defines a fixture built once for all its tests."""
    try:
        return _SHARED_FIXTURE.search(path.read_text(encoding="utf-8")) is not None
    except OSError:
        return False


def work_unit(nodeid: str, rootdir: Path) -> str:
    """What a test is sent to a worker with: ``browser`` for the browser tests, its module for
    a module whose tests share a module fixture (built once), otherwise the test alone, so that
    the long tests spread over the workers one by one."""
    module = nodeid.split("::", 1)[0]
    if Path(module).name in BROWSER_MODULES:
        return "browser"
    if _shares_a_fixture(rootdir / module):
        return module
    return nodeid


class SuiteScheduling(LoadScopeScheduling):
    """xdist's scope scheduling with :func:`work_unit` as the scope: units go out in the order
    of :func:`pytest_collection_modifyitems` (with ``--no-loadscope-reorder``), the next one to
    whichever worker has at most two tests left. (xdist's own ``loadgroup`` does this from
    ``xdist_group`` marks, by renaming test ids, which pytest 9 no longer allows.)"""

    def _split_scope(self, nodeid: str) -> str:
        return work_unit(nodeid, self.config.rootpath)


def pytest_xdist_make_scheduler(config: pytest.Config, log: object) -> SuiteScheduling | None:
    """The suite's scheduler for ``--dist load`` (the default in pyproject.toml); any other
    ``--dist`` given on the command line is xdist's own."""
    if config.getvalue("dist") != "load":
        return None
    return SuiteScheduling(config, log)  # type: ignore[arg-type]


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Longest modules first, then the other modules with slow tests, then the rest; each
    module's tests stay together and in their order. xdist hands the work units out in this
    order (:class:`SuiteScheduling`)."""
    slow = {item.path for item in items if item.get_closest_marker("slow") is not None}

    def rank(item: pytest.Item) -> int:
        if item.path.name in LONGEST_FIRST:
            return LONGEST_FIRST.index(item.path.name)
        return len(LONGEST_FIRST) + (0 if item.path in slow else 1)

    items.sort(key=rank)
