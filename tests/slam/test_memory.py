"""Freed heap memory is handed back every so many bytes freed (glibc's malloc_trim)."""

from __future__ import annotations

import sys

from agvsim.slam.memory import HeapReleaser, release_free_heap


def test_releaser_trims_once_enough_was_freed() -> None:
    rel = HeapReleaser(every_bytes=100)
    rel.freed(60)
    assert rel.releases == 0 and rel.pending == 60
    rel.freed(60)
    assert rel.releases == 1 and rel.pending == 0
    rel.freed(250)  # one large block: one release, nothing carried over
    assert rel.releases == 2 and rel.pending == 0


def test_release_is_available_on_glibc_and_harmless_elsewhere() -> None:
    done = release_free_heap()
    if sys.platform.startswith("linux"):
        import platform

        if platform.libc_ver()[0] == "glibc":
            assert done
    else:
        assert not done
