"""Endurance of the shipped demos with several robots: a simulated hour (or until the
scenario's own metric ends the run, as the pursuit's capture does) without one robot-robot
collision and without a robot standing stuck for more than a few seconds.

Every built-in behaviour sees the other robots on its lidar (``agvsim.control.traffic``):
the thesis's obstacle avoidance turns away from a robot in its path as from a wall, and every
command is slowed to stop before another robot. A robot is *stuck* while it neither moves
``STUCK_MOVE_M`` nor turns ``STUCK_TURN_RAD`` from where it last did.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from agvsim.runner import build_metrics
from agvsim.scenario import build, load_scenario

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
HOUR_S = 3600.0
STUCK_S = 8.0  # "a few seconds"
STUCK_MOVE_M = 0.05
STUCK_TURN_RAD = 0.1


def _fleet_scenarios() -> list[str]:
    """Every shipped scenario with more than one robot driven by the built-in behaviours: not
    VDA 5050 vehicles (parked until a master orders: tests/test_master_*.py drive those) nor
    timed scripts (the dynamics experiments drive, brake and stand, by design)."""
    out = []
    for path in sorted((ROOT / "scenarios").glob("*.yaml")):
        data = yaml.safe_load(path.read_text())
        robots = data.get("robots", [])
        scripted = all((r.get("controller") or {}).get("type") == "script" for r in robots)
        if len(robots) > 1 and data.get("vda5050") is None and not scripted:
            out.append(path.name)
    return out


def test_the_shipped_fleets_are_the_ones_the_issue_names():
    names = _fleet_scenarios()
    assert {"thesis_maze_avoid.yaml", "warehouse_fleet.yaml", "thesis_pursuit.yaml"} <= set(names)


def _longest_stuck_s(sim, until_s: float, metrics: dict) -> np.ndarray:
    """Run to ``until_s`` (or until a metric ends the run); (N,) longest stuck spell, s."""
    ref = sim.state.poses.copy()
    since = np.full(sim.n, sim.state.t_s)
    longest = np.zeros(sim.n)
    while sim.state.t_s < until_s - 1e-9:
        sim.step()
        p, t = sim.state.poses, sim.state.t_s
        turned = np.abs(np.angle(np.exp(1j * (p[:, 2] - ref[:, 2]))))
        moved = (np.hypot(p[:, 0] - ref[:, 0], p[:, 1] - ref[:, 1]) > STUCK_MOVE_M) | (
            turned > STUCK_TURN_RAD
        )
        ref[moved] = p[moved]
        since[moved] = t
        longest = np.maximum(longest, t - since)
        if any([m.update(sim) for m in metrics.values()]):
            break
    return longest


@pytest.mark.parametrize("name", _fleet_scenarios())
def test_an_hour_without_robot_collisions_or_a_stuck_robot(name, one_numba_thread):
    sc = load_scenario(ROOT / "scenarios" / name)
    sim = build(sc)
    metrics = build_metrics(sc, sim, name)
    longest = _longest_stuck_s(sim, HOUR_S, metrics)
    st = sim.state
    robots = [r.name for r in sim.robots]
    ended_early = st.t_s < HOUR_S - 1e-9
    if ended_early:  # only a metric may end it (the pursuit's capture)
        assert "capture" in metrics and metrics["capture"].captured
    hits = dict(zip(robots, st.robot_collisions.tolist(), strict=True))
    assert not any(hits.values()), f"{name}: robot-robot collisions {hits} by t={st.t_s:.1f} s"
    stuck = dict(zip(robots, np.round(longest, 1).tolist(), strict=True))
    assert longest.max() <= STUCK_S, f"{name}: longest stuck spells (s) {stuck}"
    # and they drove: every robot covered ground (none parked the hour away)
    assert np.all(st.distance_m > (0.3 * st.t_s if not ended_early else 1.0)), st.distance_m
