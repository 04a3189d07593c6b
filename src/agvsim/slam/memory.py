"""Giving freed heap memory back to the operating system.

Online SLAM frees large arrays all the time: branch-and-bound pyramids evicted from the loop
detector's cache, the likelihood fields and distance transforms they are built from (several
MB each). glibc's malloc raises its mmap threshold each time such a block is freed, so the
next ones come from the heap, where they are freed between long-lived small objects (keyframes,
edges) and the pages stay resident: the process's resident memory then grows with the log
although the live data do not. :class:`HeapReleaser` counts the bytes a caller freed and,
every ``every_bytes``, calls glibc's ``malloc_trim(0)``, which hands the free pages inside the
heap back to the system. Elsewhere (musl, macOS, Windows) it does nothing.
"""

from __future__ import annotations

import ctypes
import sys
from collections.abc import Callable

__all__ = ["HeapReleaser", "release_free_heap"]


def _load_trim() -> Callable[[int], int] | None:
    if not sys.platform.startswith("linux"):
        return None
    try:
        trim = ctypes.CDLL(None).malloc_trim  # the process's own libc, no library search
    except (OSError, AttributeError):  # not glibc
        return None
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    return trim  # type: ignore[no-any-return]


_TRIM = _load_trim()


def release_free_heap() -> bool:
    """Hand the heap's free pages back to the system (glibc); True if it could be asked."""
    if _TRIM is None:
        return False
    _TRIM(0)
    return True


class HeapReleaser:
    """Calls :func:`release_free_heap` once ``every_bytes`` have been freed (counted by the
    caller through :meth:`freed`)."""

    def __init__(self, every_bytes: int) -> None:
        self.every_bytes = every_bytes
        self.pending = 0
        self.releases = 0

    def freed(self, nbytes: int) -> None:
        self.pending += nbytes
        if self.pending >= self.every_bytes:
            self.pending = 0
            self.releases += 1
            release_free_heap()
