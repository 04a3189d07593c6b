"""Builders and waits shared by several test modules (shared fixtures are in ``conftest.py``).

Import them as ``from helpers import ...``: pytest puts this folder on ``sys.path``.
"""

from __future__ import annotations

import fcntl
import os
import shutil
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from agvsim.world.grid import OccupancyGrid

CHROMIUM = "/usr/bin/chromium"

# Waits on the page (Playwright's milliseconds). Headless Chromium renders WebGL in software:
# on a busy 2-core machine a page takes up to tens of seconds to load and seconds to answer
# a click, so the waits are long. They cost nothing when the page answers sooner.
PAGE_LOAD_MS = 120_000  # the page's panel showing after goto()
ANSWER_MS = 60_000  # a message or field appearing after a click


def walled_room(rows: int, cols: int) -> OccupancyGrid:
    """A walled room of ``rows`` x ``cols`` 1 m cells, origin (0, 0): free x in
    [1, cols - 1], y in [1, rows - 1]."""
    m = np.zeros((rows, cols), dtype=int)
    m[0, :] = m[-1, :] = m[:, 0] = m[:, -1] = 1
    return OccupancyGrid.from_matrix(m, 1.0, (0.0, 0.0))


def cast_segments(pose: np.ndarray, walls: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Ranges of beams at ``angles`` (laser frame) from ``pose`` to the nearest of the wall
    segments ``walls`` (k, 4: x0, y0, x1, y1); inf where a beam meets none (exact geometry,
    for scans of hand-made rooms)."""
    th = pose[2] + angles
    d = np.stack([np.cos(th), np.sin(th)], axis=1)[:, None, :]
    p, e = walls[None, :, :2], walls[None, :, 2:] - walls[None, :, :2]
    w = p - pose[:2]
    den = d[..., 0] * e[..., 1] - d[..., 1] * e[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[..., 0] * e[..., 1] - w[..., 1] * e[..., 0]) / den
        u = (w[..., 0] * d[..., 1] - w[..., 1] * d[..., 0]) / den
    t = np.where((np.abs(den) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1), t, np.inf)
    return t.min(axis=1)


def need_browser() -> None:
    """Skip the test without Debian's chromium and playwright; fail it instead when
    AGVSIM_REQUIRE_BROWSER=1 (CI sets it)."""
    missing = []
    if not Path(CHROMIUM).exists() and shutil.which("chromium") is None:
        missing.append("Debian's chromium (apt-get install -y chromium)")
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        missing.append("playwright (pip install -e '.[test]')")
    if missing:
        why = "browser tests need " + " and ".join(missing)
        if os.environ.get("AGVSIM_REQUIRE_BROWSER") == "1":
            pytest.fail(why)
        pytest.skip(why)


def wait_for(cond: Callable[[], object], timeout_s: float = 15.0, what: str = "condition") -> None:
    """Poll ``cond`` every 50 ms until it is true; fail after ``timeout_s`` seconds."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        if cond():
            return
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")


def room_yaml(sensors: Sequence[str] = (), wheels_rad_s: float = 5.0, more: str = "") -> str:
    """The browser tests' scenario: a walled 7 x 7 m room, robot ``agv`` (differential, forward
    mode, at (-2, 0) facing east) driving both wheels at ``wheels_rad_s`` with ``sensors``
    (YAML flow mappings), and ``more`` robot entries appended."""
    rows = "\n".join(["    #########", *["    #.......#"] * 7, "    #########"])
    listed = "".join(f"\n      - {x}" for x in sensors)
    return (
        f"name: room\nworld:\n  picture: |\n{rows}\nrobots:\n  - name: agv\n"
        "    model: differential\n    mode: forward\n"
        "    pose: {x_m: -2.0, y_m: 0.0, theta_deg: 0.0}\n"
        + (f"    sensors:{listed}\n" if sensors else "")
        + "    controller: {type: script, steps: [{duration_s: 10000, "
        f"wheels: [{wheels_rad_s}, {wheels_rad_s}]}}]}}\n" + more
    )


@contextmanager
def served_app(scenario_yaml: str, folder: Path) -> Iterator:
    """The browser app serving ``scenario_yaml`` (written to ``folder``) on a free local port,
    its loops running; stopped on exit. Calls :func:`need_browser` first."""
    need_browser()
    from agvsim.app.server import App, open_session
    from agvsim.net import free_port

    path = folder / "scenario.yaml"
    path.write_text(scenario_yaml)
    app = App(open_session(path), port=free_port()).start()
    try:
        yield app
    finally:
        app.stop()


def click_scene_centre(page) -> None:
    """Click the middle of the 3D view as a hand does: the pointer moves there first and
    rests (a paused scene sends nothing, and the page draws only on demand)."""
    box = page.locator("canvas").first.bounding_box()
    x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    page.mouse.move(x, y)
    page.wait_for_timeout(300)
    page.mouse.click(x, y)


@contextmanager
def one_browser_at_a_time() -> Iterator[None]:
    """Hold this machine's browser-test lock (a ``flock`` on a file in the temp folder) while
    the block runs: one headless Chromium at a time across pytest-xdist's workers (and
    concurrent runs). A software-rendered page takes about a core while it loads and about
    half a core idle; two at once on 2 cores starved each other past any wait."""
    path = Path(tempfile.gettempdir()) / "agvsim-browser-tests.lock"
    with open(path, "a") as f:
        fcntl.flock(f, fcntl.LOCK_EX)  # released when the file closes, or the process dies
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


@contextmanager
def chromium() -> Iterator:
    """Debian's headless chromium driven by Playwright (never a downloaded browser), the only
    one running on this machine's tests while it is open (:func:`one_browser_at_a_time`)."""
    from playwright.sync_api import sync_playwright

    from agvsim.bench_app import FLAGS

    with one_browser_at_a_time(), sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=FLAGS)
        try:
            yield browser
        finally:
            browser.close()
