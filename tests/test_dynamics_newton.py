"""Newton non-convergence of the implicit dynamics (docs/dynamics.md): counted per robot in
the stages kept, in summary.json's ``dynamics[].newton_unconverged`` and in one warning line
per ``agvsim run``; ordinary robots and the shipped scenarios report none."""

from __future__ import annotations

import json

import numpy as np
import yaml
from typer.testing import CliRunner

from agvsim.cli import app
from agvsim.dynamics import DynamicsSpec, FloorFriction, MotorSpec
from agvsim.dynamics import kernel as K
from agvsim.dynamics.vehicle import Dynamics, newton_warning
from agvsim.kinematics import Tricycle
from agvsim.kinematics.base import integrate_se2
from agvsim.sim.spec import OdometrySpec, RobotSpec

DT = 0.02
# half a second at 10 rad/s from rest, then half a second told to stand
PLAN = [[10.0, 10.0, 0.0, 0.0]] * 25 + [[0.0, 0.0, 0.0, 0.0]] * 25


def robot(name: str = "r", slip_speed_m_s: float = 0.05) -> RobotSpec:
    """A 60 kg tricycle (steered and driven front wheel)."""
    return RobotSpec(
        name,
        Tricycle(wheel_radius_m=0.1, wheelbase_m=0.6, half_track_m=0.25),
        body_length_m=0.7,
        body_width_m=0.5,
        body_offset_x_m=0.3,
        odometry=OdometrySpec(0.0),
        dynamics=DynamicsSpec(
            mass_kg=60.0, motor=MotorSpec(torque_max_nm=1.5), slip_speed_m_s=slip_speed_m_s
        ),
    )


def drive(dyn: Dynamics, plan=PLAN, steer_rad: float = 0.0) -> tuple[np.ndarray, int]:
    """Step the robots of ``dyn`` through ``plan`` (one row of targets a step, for all)
    with a constant steering target; returns the final poses and the sub-steps taken by
    robot 0."""
    n = len(dyn.idx)
    pose, t, taken = np.zeros((n, 3)), 0.0, 0
    delta = np.full(n, steer_rad)
    for targets in plan:
        out = dyn.step(pose, np.tile(targets, (n, 1)), delta, np.zeros(n, bool), DT, t)
        pose = integrate_se2(pose, out.twist, DT)
        t += DT
        taken += int(out.substeps[0])
    return pose, taken


def test_an_ordinary_robot_converges_everywhere():
    dyn = Dynamics([robot()], FloorFriction(0.8), 4, 2)
    drive(dyn)
    assert dyn.newton_unconverged.tolist() == [0]
    assert dyn.newton_first == [None] and dyn.newton_max_residual_m_s.tolist() == [0.0]
    summary = dyn.summary()
    assert summary[0]["newton_unconverged"] == {
        "stages": 0,
        "first_t_s": None,
        "first_residual_m_s": None,
        "max_residual_m_s": 0.0,
    }
    assert newton_warning(summary) is None


def test_one_iteration_a_stage_is_counted_from_the_first_step():
    """With one Newton iteration a stage stops after its first correction: at the first
    step (new targets from rest) that correction is far above the tolerance, so the stage
    counts; a stage can count once at most, so never more than two a sub-step kept."""
    dyn = Dynamics([robot()], FloorFriction(0.8), 4, 2)
    dyn.newton_iterations = 1
    _, taken = drive(dyn)
    stages = int(dyn.newton_unconverged[0])
    assert 0 < stages <= 2 * taken
    first = dyn.newton_first[0]
    assert first is not None and first[0] == 0.0
    assert first[1] > K.NEWTON_TOL_M_S
    assert dyn.newton_max_residual_m_s[0] >= first[1]
    line = newton_warning(dyn.summary())
    assert line is not None
    assert "robot 'r'" in line and "t = 0 s" in line and f"{first[1]:.3g} m/s" in line
    assert f"{stages} implicit stage(s) of 1 robot(s)" in line
    # reset starts the count again; the default cap converges the same drive
    dyn.reset(np.zeros(1))
    dyn.newton_iterations = K.NEWTON_ITERATIONS
    drive(dyn)
    assert dyn.newton_unconverged.tolist() == [0] and dyn.newton_first == [None]


def test_an_absurdly_stiff_friction_law_does_not_converge_and_is_reported():
    """A Coulomb law whose slip zone is 1 nm/s (the scenario allows any positive
    ``slip_speed_m_s``) is a step function to Newton's method: turning on it, even the
    shortest sub-step leaves stages unconverged. The robot beside it, with the default
    5 cm/s, converges and reports nothing. The motion stays finite."""
    dyn = Dynamics([robot("ok"), robot("stiff", 1e-9)], FloorFriction(0.8), 4, 2)
    pose, _ = drive(dyn, steer_rad=0.3)
    assert np.all(np.isfinite(pose))
    assert dyn.newton_unconverged[0] == 0 and dyn.newton_unconverged[1] > 0
    line = newton_warning(dyn.summary())
    assert line is not None and "robot 'stiff'" in line and "1 robot(s)" in line


def test_the_warning_names_the_earliest_robot_and_the_totals():
    def entry(name, stages, t, res):
        nu = {"stages": stages, "first_t_s": t, "first_residual_m_s": res}
        return {"name": name, "newton_unconverged": nu | {"max_residual_m_s": res or 0.0}}

    rows = [entry("a", 0, None, None), entry("b", 3, 2.5, 0.25), entry("c", 4, 1.25, 0.5)]
    assert newton_warning(rows) == (
        "dynamics: Newton's method did not converge for robot 'c' in the step from t = 1.25 s "
        "(residual 0.5 m/s); 7 implicit stage(s) of 2 robot(s) in all, see summary.json "
        "dynamics[].newton_unconverged (docs/dynamics.md)"
    )


def test_agvsim_run_prints_one_warning_line_and_writes_the_counts(tmp_path):
    scenario = {
        "name": "stiff",
        "duration_s": 0.6,
        "world": {"picture": "\n".join(["." * 10] * 10)},
        "robots": [
            {
                "name": name,
                "model": "tricycle",
                "pose": {"x_m": 0.0, "y_m": y},
                "controller": {"type": "script", "steps": [{"duration_s": 1, "twist": [0.8, 0.6]}]},
                "dynamics": {"mass_kg": 60, "slip_speed_m_s": slip},
            }
            for name, slip, y in (("calm", 0.05, -2.0), ("stiff", 1e-9, 2.0))
        ],
    }
    path = tmp_path / "stiff.yaml"
    path.write_text(yaml.safe_dump(scenario))
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["run", str(path), "--out", str(out), "-q", "--no-plot"])
    assert res.exit_code == 0, res.output
    lines = [ln for ln in res.output.splitlines() if "Newton's method did not converge" in ln]
    assert len(lines) == 1 and "robot 'stiff'" in lines[0], res.output
    data = json.loads((out / "summary.json").read_text())
    counts = {r["name"]: r["newton_unconverged"]["stages"] for r in data["dynamics"]}
    assert counts["calm"] == 0 and counts["stiff"] > 0
    assert f"{counts['stiff']} implicit stage(s) of 1 robot(s)" in lines[0]
