"""The world editor's friction brush (issue 20, point 6), through the Session (no browser)."""

from __future__ import annotations

import numpy as np
import pytest

from agvsim.app.friction_brush import paint_friction
from agvsim.app.session import Session
from agvsim.scenario import parse_scenario

ROOM = "\n".join(["#########"] + ["#.......#"] * 7 + ["#########"])


def session() -> Session:
    robot = {
        "name": "agv",
        "model": "differential",
        "mode": "forward",
        "pose": {"x_m": -2.0, "y_m": 0.0, "theta_deg": 0.0},
        "dynamics": {"mass_kg": 60.0, "motor": {"torque_max_nm": 5.0}},
        "controller": {"type": "script", "steps": [{"duration_s": 100, "wheels": [8.0, 8.0]}]},
    }
    return Session(
        parse_scenario({"name": "room", "world": {"picture": ROOM}, "robots": [robot]}), "t"
    )


def paint_track(s: Session, mu: float) -> None:
    for x in (-2.0, -1.0, 0.0, 1.0):
        cell = s.cell_at(x, 0.0)
        assert cell is not None
        paint_friction(s, *cell, mu)


def test_painted_cells_set_the_friction_the_robot_feels():
    """Ice painted under the robot: the floor says so where it drives, its wheels spin (slip
    far above the dry floor's) and it gets less far in the same time; a restart keeps it."""
    dry, ice = session(), session()
    paint_track(ice, 0.05)
    assert ice.sim.world.floor.mu_at(-2.0, 0.0) == pytest.approx(0.05)
    assert ice.sim.world.floor.mu_at(-2.0, 1.6) == pytest.approx(0.8)  # the next row: untouched
    for s in (dry, ice):
        s.step(25)
    slip_dry = dry.sim.state.wheel_slip_m_s[0, :2].max()
    slip_ice = ice.sim.state.wheel_slip_m_s[0, :2].max()
    assert slip_ice > 0.2 > 0.05 > slip_dry
    assert ice.sim.state.poses[0, 0] < dry.sim.state.poses[0, 0] - 0.05
    ice.reset()  # rebuilt from the session's scenario: the painted cells are in it
    assert ice.sim.world.floor.mu_at(-1.0, 0.0) == pytest.approx(0.05)
    assert len(ice.config["world"]["floor"]["regions"]) == 4


def test_repainting_a_cell_wins_and_bad_input_is_refused():
    s = session()
    cell = s.cell_at(0.0, 0.0)
    paint_friction(s, *cell, 0.1)
    paint_friction(s, *cell, 1.2)
    assert s.sim.world.floor.mu_at(0.0, 0.0) == pytest.approx(1.2)
    with pytest.raises(ValueError, match="outside"):
        paint_friction(s, 99, 0, 0.5)
    with pytest.raises(ValueError, match="mu"):
        paint_friction(s, *cell, 0.0)
    assert np.isfinite(s.sim.world.floor.mu)
