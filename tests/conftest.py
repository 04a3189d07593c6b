"""Fixtures shared by several test modules (plain helper functions are in ``helpers.py``)."""

from __future__ import annotations

import numba
import pytest


@pytest.fixture
def one_numba_thread():
    """One ray-casting thread: with a single sensor the parallel kernel only adds thread
    wake-up latency (milliseconds per step on a busy 2-core machine)."""
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(before)
