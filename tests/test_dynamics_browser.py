"""Dynamics in the browser app (issue 20, point 6), end to end in headless Chromium: the
Robot tab's mask turns dynamics on with a mass, and the World tab's friction brush paints a
floor cell that the running simulation then uses. Skipped without Debian's chromium (see
tests/test_app_browser.py)."""

from __future__ import annotations

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

ROOM = room_yaml()


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    with served_app(ROOM, tmp_path_factory.mktemp("app")) as a:
        yield a


@pytest.fixture(scope="module")
def page(app):
    with chromium() as browser:
        pg = browser.new_page(viewport={"width": 1280, "height": 800})
        pg.errors = []  # type: ignore[attr-defined]
        pg.on("pageerror", lambda e: pg.errors.append(str(e)))
        pg.goto(app.url)
        pg.get_by_role("tab", name="Run").wait_for(timeout=PAGE_LOAD_MS)
        pg.wait_for_timeout(1500)
        yield pg


def test_the_mask_turns_dynamics_on_with_its_mass(app, page):
    s = app.session
    assert s.sim.dynamics is None
    page.get_by_role("tab", name="Robot").click()
    page.get_by_label("dynamics on").check()
    mass = page.get_by_label("mass (kg)")
    mass.fill("90")
    mass.press("Enter")
    page.wait_for_timeout(300)
    page.get_by_role("button", name="Apply").click()
    wait_for(lambda: s.sim.dynamics is not None, what="the robot to get dynamics")
    assert s.robot_config("agv")["dynamics"]["mass_kg"] == 90
    assert s.sim.dynamics.mass_kg().tolist() == [90.0]
    s.step(5)  # the wheels now spin up through the motors: slower than commanded at first
    assert 0.0 < s.sim.state.twists[0, 0] < 5.0 * 0.1
    assert page.errors == []


def test_the_friction_brush_paints_the_floor_under_a_click(app, page):
    s = app.session
    page.get_by_role("tab", name="Run").click()
    page.get_by_role("button", name="Reset").click()
    page.get_by_label("view").first.click()
    page.get_by_role("option", name="top plan", exact=True).click()
    page.wait_for_timeout(800)
    page.get_by_role("tab", name="World").click()
    brush = page.get_by_label("paint friction mu")
    brush.fill("0.1")
    brush.press("Enter")
    page.get_by_label("edit maze").check()
    # the click counts only once the server has the brush and the tick
    wait_for(lambda: app.panel.edit.value and app.panel.brush_mu.value == 0.1, what="the brush on")
    # the top view looks straight down on the map's centre: the middle cell (0, 0) m
    click_scene_centre(page)
    wait_for(lambda: s.sim.world.floor.mu_at(0.0, 0.0) == 0.1, what="the painted friction")
    page.get_by_text("now has friction 0.1").wait_for(timeout=ANSWER_MS)
    assert s.sim.world.floor.mu_at(1.0, 0.0) == 0.8  # the next cell: the floor's
    assert not s.sim.world.grid.occupied[4, 4]  # painted, not turned into a wall
    assert s.config["world"]["floor"]["regions"][-1]["mu"] == 0.1  # kept in the scenario
    page.get_by_label("edit maze").uncheck()
    assert page.errors == []
