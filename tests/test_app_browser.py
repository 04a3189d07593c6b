"""End-to-end: the browser app in a real headless Chromium, driven by Playwright.

Needs Debian's chromium at /usr/bin/chromium (``.ci/run`` installs it). Without it these tests
are skipped, unless AGVSIM_REQUIRE_BROWSER=1 (CI sets it), which turns the skip into a failure.
"""

from __future__ import annotations

import io

import numpy as np
import pytest

from helpers import (
    ANSWER_MS,
    PAGE_LOAD_MS,
    chromium,
    click_scene_centre,
    room_yaml,
    served_app,
    wait_for,
)

pytestmark = pytest.mark.slow  # a real browser

ROOM = room_yaml(["{type: lidar, beams: 8, range_max_m: 10.0, rate_hz: 50}"])


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    with served_app(ROOM, tmp_path_factory.mktemp("app")) as a:
        yield a


@pytest.fixture(scope="module")
def page(app):
    with chromium() as browser:
        pg = browser.new_page(viewport={"width": 1280, "height": 800})
        pg.errors = []  # type: ignore[attr-defined]
        pg.outside = []  # type: ignore[attr-defined]
        pg.on("console", lambda m: m.type == "error" and pg.errors.append(m.text))
        pg.on("pageerror", lambda e: pg.errors.append(str(e)))
        pg.on(
            "request",
            lambda r: (
                not r.url.startswith(("http://127.0.0.1", "ws://127.0.0.1", "data:", "blob:"))
                and pg.outside.append(r.url)
            ),
        )
        pg.goto(app.url)
        pg.get_by_role("tab", name="Run").wait_for(timeout=PAGE_LOAD_MS)
        pg.wait_for_timeout(1500)
        yield pg


def canvas_shot(page) -> np.ndarray:
    from PIL import Image

    canvases = page.locator("canvas")
    areas = [
        (b["width"] * b["height"], k)
        for k in range(canvases.count())
        if (b := canvases.nth(k).bounding_box())
    ]
    main = canvases.nth(max(areas)[1])
    return np.asarray(Image.open(io.BytesIO(main.screenshot())).convert("RGB"))


def choose(page, label: str, option: str) -> None:
    page.get_by_label(label).first.click()
    page.get_by_role("option", name=option, exact=True).click()


def apply_robot_field(page, label: str, value: str) -> None:
    """Type ``value`` into the Robot tab's field ``label`` and press Apply."""
    page.get_by_role("tab", name="Robot").click()
    field = page.get_by_label(label)
    field.fill(value)
    field.press("Enter")
    page.wait_for_timeout(300)
    page.get_by_role("button", name="Apply").click()


def test_page_loads_without_errors_and_draws_the_scene(app, page):
    img = canvas_shot(page)
    colours = len(np.unique(img.reshape(-1, 3) // 8, axis=0))
    assert colours > 20, f"canvas looks blank ({colours} colours)"
    # the walls (grey) and the floor (light) both show
    grey = np.all(np.abs(img.astype(int) - [150, 150, 160]) < 40, axis=-1).mean()
    assert grey > 0.02
    assert page.errors == []
    assert page.outside == []  # works offline: nothing fetched from outside this machine


def test_play_moves_the_robot(app, page):
    page.get_by_role("tab", name="Run").click()
    page.get_by_role("button", name="Reset").click()
    wait_for(lambda: app.session.sim.state.step == 0, what="reset")
    page.get_by_role("button", name="Play").click()
    wait_for(lambda: app.session.sim.state.distance_m[0] > 0.2, what="the robot to move")
    page.get_by_role("button", name="Pause").click()
    wait_for(lambda: not app.session.playing, what="pause")
    vx = app.session.sim.state.twists[0, 0]
    assert vx == pytest.approx(5.0 * 0.1)  # wheels 5 rad/s, radius 0.1 m
    assert page.errors == []


def test_wheel_radius_in_the_panel_changes_the_motion(app, page):
    page.get_by_role("tab", name="Run").click()
    page.get_by_role("button", name="Reset").click()
    apply_robot_field(page, "wheel radius (m)", "0.05")
    wait_for(
        lambda: app.session.robot_config("agv").get("params", {}).get("wheel_radius_m") == 0.05,
        what="the new wheel radius",
    )
    page.get_by_role("tab", name="Run").click()
    page.get_by_role("button", name="Play").click()
    wait_for(lambda: app.session.sim.state.distance_m[0] > 0.2, what="the robot to move")
    page.get_by_role("button", name="Pause").click()
    assert app.session.sim.state.twists[0, 0] == pytest.approx(5.0 * 0.05)
    # an invalid value is refused in the panel with the schema's message
    apply_robot_field(page, "body length (m)", "-1")
    page.get_by_text("greater than 0").wait_for(timeout=ANSWER_MS)
    assert app.session.robot_config("agv")["body"].get("length_m", 0.6) > 0
    assert page.errors == []


def test_a_maze_cell_clicked_in_the_editor_becomes_a_wall_the_lidar_sees(app, page):
    s = app.session
    page.get_by_role("tab", name="Run").click()
    page.get_by_role("button", name="Reset").click()
    choose(page, "view", "top plan")
    page.wait_for_timeout(800)
    page.get_by_role("tab", name="World").click()
    page.get_by_label("edit maze").check()
    wait_for(lambda: app.panel.edit.value, what="edit maze on the server")
    s.step(1)
    x = s.sim.state.poses[0, 0]
    assert s.sim.state.scans[0, 4] == pytest.approx(3.5 - x, abs=1e-6)  # the east wall ahead
    # the top view looks straight down on the map's centre: the middle cell (0, 0) m
    click_scene_centre(page)
    wait_for(lambda: s.sim.world.grid.occupied[4, 4], what="the clicked cell to become a wall")
    s.step(1)
    x = s.sim.state.poses[0, 0]
    assert s.sim.state.scans[0, 4] == pytest.approx(-0.5 - x, abs=1e-6)  # the new wall's face
    page.get_by_text("is now a wall").wait_for(timeout=ANSWER_MS)
    click_scene_centre(page)
    wait_for(lambda: not s.sim.world.grid.occupied[4, 4], what="the wall to go again")
    page.get_by_label("edit maze").uncheck()
    assert page.errors == []


def test_a_second_tab_watches_and_closing_it_does_not_stop_the_run(app, page):
    s = app.session
    other = page.context.browser.new_page()
    other.goto(app.url)
    other.get_by_role("tab", name="Run").wait_for(timeout=PAGE_LOAD_MS)
    wait_for(lambda: len(app.server.get_clients()) == 2, what="two clients")
    s.play()
    other.close()
    t0 = s.sim.state.t_s
    wait_for(lambda: s.sim.state.t_s > t0 + 0.3, what="the run to go on")
    s.pause()
    wait_for(lambda: len(app.server.get_clients()) == 1, what="one client")
    assert page.errors == []


def test_keyboard_drives_the_picked_robot(app, page):
    s = app.session
    page.get_by_role("tab", name="Run").click()
    page.get_by_label("drive with keys").check()
    wait_for(lambda: s.keyboard_robot == "agv", what="keyboard driving")
    page.mouse.click(5, 400)  # focus the page, away from the panel's inputs
    for key in ("w", "w", "ArrowLeft"):
        page.keyboard.press(key)
    wait_for(lambda: tuple(s.keyboard.twist) == (0.2, 0.0, 0.25), what="the key presses")
    s.step(25)
    assert s.sim.state.twists[0, 0] == pytest.approx(0.2)
    assert s.sim.state.twists[0, 2] == pytest.approx(0.25)
    page.keyboard.press("Space")
    wait_for(lambda: not s.keyboard.twist.any(), what="space to stop")
    page.get_by_label("drive with keys").uncheck()
    wait_for(lambda: s.keyboard_robot is None, what="keyboard driving to stop")
    assert s.config["robots"][0]["controller"]["type"] == "script"
    print("\n".join(page.errors))
    assert page.errors == []
