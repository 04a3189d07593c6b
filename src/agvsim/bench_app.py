"""Benchmark of the browser app (``agvsim bench --app``): 10 robots with 240-beam lidars.

Workload (issue #4): the thesis App. C.1 maze tiled 2 x 2 (40 m x 40 m), ten differential
robots carrying the thesis's four rangers and its 240-beam 10 m lidar at 10 Hz, the thesis's
obstacle avoidance, 50 Hz kinematics, run at real-time speed with every beam drawn. A real
browser (Debian's headless Chromium, driven by Playwright, software WebGL) watches it. Printed:

- server frames/s: scene updates the app sent each second;
- client frames/s: websocket messages the browser received each second, and the browser's
  own animation frames per second (what it drew; software rendering on a busy CPU is slower
  than a desktop GPU);
- real-time factor: simulated seconds per wall second (1.0 = keeps real time).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from agvsim.net import free_port
from agvsim.scenario import parse_scenario

FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]


def _scenario(n: int = 10) -> dict:
    import numpy as np

    from agvsim.bench import free_starts
    from agvsim.world.grid import OccupancyGrid

    occ = _tiled_c1()
    starts = free_starts(OccupancyGrid.from_matrix(occ), n, np.random.default_rng(0))
    picture = "\n".join("".join("#" if v else "." for v in row) for row in occ)
    robots = [
        {
            "name": f"agv{k}",
            "model": "differential",
            "pose": {"x_m": float(x), "y_m": float(y), "theta_deg": float(np.degrees(th))},
            "sensors": [
                {"type": "rangers", "range_max_m": 1.5},
                {"type": "lidar", "beams": 240, "range_max_m": 10.0, "rate_hz": 10},
            ],
            "controller": {"type": "avoid", "sensor": "rangers"},
        }
        for k, (x, y, th) in enumerate(starts)
    ]
    return {"name": "app benchmark", "world": {"picture": picture}, "robots": robots}


def _tiled_c1():
    from agvsim.world.mazes import thesis_maze, tile

    return tile(thesis_maze("thesis_c1"), 2, 2).occupied


def run_app_benchmark(
    seconds: float = 10.0, browser: bool = True, log: Callable[[str], None] | None = print
) -> dict:
    from agvsim.app.server import App
    from agvsim.app.session import Session

    sc = parse_scenario(_scenario())
    session = Session(sc, "app benchmark")
    session.step(1)  # compile the kernels before timing
    app = App(session, port=free_port()).start()
    result: dict = {"robots": 10, "lidar_beams": 240, "seconds": seconds}
    pw = None
    try:
        page, counts = None, {"ws": 0}
        if browser and Path("/usr/bin/chromium").exists():
            from playwright.sync_api import sync_playwright

            pw = sync_playwright().start()
            br = pw.chromium.launch(executable_path="/usr/bin/chromium", args=FLAGS)
            page = br.new_page(viewport={"width": 1280, "height": 800})
            page.on(
                "websocket",
                lambda ws: ws.on(
                    "framereceived", lambda _f: counts.__setitem__("ws", counts["ws"] + 1)
                ),
            )
            page.goto(app.url)
            page.get_by_role("tab", name="Run").wait_for(timeout=60000)
            page.wait_for_timeout(3000)
            page.evaluate(
                "() => { window.__raf = 0; const f = () => { window.__raf++;"
                " requestAnimationFrame(f); }; requestAnimationFrame(f); }"
            )
        elif log:
            log("no browser (needs /usr/bin/chromium and playwright): server side only")
        session.play()
        time.sleep(1.0)
        with session.lock:
            t_sim0 = session.sim.state.t_s
        f0, ws0, w0 = app.stats.frames, counts["ws"], time.perf_counter()
        raf0 = page.evaluate("() => window.__raf") if page else 0
        time.sleep(seconds)
        wall = time.perf_counter() - w0
        with session.lock:
            t_sim1 = session.sim.state.t_s
        result["server_frames_per_s"] = round((app.stats.frames - f0) / wall, 1)
        result["real_time_factor"] = round((t_sim1 - t_sim0) / wall, 3)
        if page is not None:
            result["client_messages_per_s"] = round((counts["ws"] - ws0) / wall, 1)
            result["client_animation_frames_per_s"] = round(
                (page.evaluate("() => window.__raf") - raf0) / wall, 1
            )
        if log:
            log(
                f"app: {result['server_frames_per_s']} frames/s sent, real-time factor "
                f"{result['real_time_factor']}"
                + (
                    f", browser got {result['client_messages_per_s']} messages/s and drew "
                    f"{result['client_animation_frames_per_s']} frames/s"
                    if page is not None
                    else ""
                )
            )
    finally:
        if pw is not None:
            pw.stop()
        app.stop()
    return result
