"""Runs end cleanly whatever stops them: SIGTERM like Ctrl-C (every output written, status
``interrupted``), a controller that hangs (the per-call time limit), a controller that calls
``sys.exit`` (a controller failure, never "completed")."""

from __future__ import annotations

import csv
import json
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from yaml import safe_dump as yaml_dump
from yaml import safe_load as yaml_load

from agvsim.kinematics import DifferentialDrive
from agvsim.runner import run_scenario
from agvsim.signals import StepGuard, Terminated, hold_signals, terminate_as_interrupt
from agvsim.sim.engine import Binding, ControllerError, Simulation
from agvsim.sim.spec import RobotSpec, World
from agvsim.sim.watchdog import ControllerClock, TimeLimitExceeded, check_limit

from helpers import walled_room

ROOT = Path(__file__).resolve().parents[1]

SCENARIO = """
name: signals room
duration_s: {duration}
world: {{picture: "#####\\n#...#\\n#...#\\n#...#\\n#####", cell_size_m: 2.0}}
robots:
  - name: student
    model: differential
    pose: {{x_m: -1.0, y_m: 0.0}}
    controller: {{type: python, file: ctrl.py, name: step}}
"""


def _write(tmp_path: Path, controller: str, duration: float = 10.0) -> Path:
    (tmp_path / "ctrl.py").write_text(controller)
    path = tmp_path / "s.yaml"
    path.write_text(SCENARIO.format(duration=duration))
    return path


def _summary(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())["run"]


def _rows(out: Path) -> list[dict]:
    with (out / "trajectory.csv").open() as f:
        return list(csv.DictReader(f))


# ------------------------------------------------------------------------------ SIGTERM
# the controller says when the run is under way (a file), then drives on for a long time
STARTED = """
from pathlib import Path

def step(obs):
    if obs.t_s >= 1.0:
        Path(__file__).with_name("started").touch()
    return (0.05, 0.0, 0.0)
"""


def test_sigterm_ends_agvsim_run_like_ctrl_c(tmp_path):
    scen = _write(tmp_path, STARTED, duration=100000.0)
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [sys.executable, "-m", "agvsim.cli", "run", str(scen), "--out", str(out), "-q"],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 240
        while not (tmp_path / "started").exists():
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "the run did not start"
            time.sleep(0.05)
        proc.send_signal(signal.SIGTERM)
        _, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 143, stderr  # 128 + SIGTERM, as a shell reports it
    assert "interrupted (SIGTERM)" in stderr and "Traceback" not in stderr, stderr
    run = _summary(out)
    assert run["status"] == "interrupted"
    assert run["error"] == "terminated by SIGTERM"
    t_end = run["simulated_time_s"]
    assert t_end >= 1.0
    rows = _rows(out)
    assert len(rows) == run["steps"] + 1  # t = 0 and every step, nothing lost
    assert float(rows[-1]["t"]) == pytest.approx(t_end)
    assert float(rows[-1]["x"]) == pytest.approx(-1.0 + 0.05 * t_end)
    with Image.open(out / "plot.png") as im:
        assert im.size[0] > 100
    from mcap.reader import make_reader

    with open(out / "run.mcap", "rb") as f:
        mcap_summary = make_reader(f).get_summary()  # written only when the file is closed
    assert mcap_summary is not None and mcap_summary.statistics.message_count > 0


SWALLOWS_SIGTERM = """
import os, signal

def step(obs):
    if abs(obs.t_s - 0.5) < 1e-9:
        try:
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(1000):  # the handler runs here and raises Terminated ...
                pass
        except BaseException:  # ... which this careless controller swallows
            pass
    return (0.1, 0.0, 0.0)
"""


def test_a_controller_cannot_swallow_sigterm(tmp_path):
    scen = _write(tmp_path, SWALLOWS_SIGTERM)
    with pytest.raises(Terminated):
        run_scenario(scen, tmp_path / "out", plot=False, record_mcap=False)
    run = _summary(tmp_path / "out")
    assert run["status"] == "interrupted"
    # the run stops at the end of the very step in which the signal came
    assert run["simulated_time_s"] == pytest.approx(0.52)
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # handler given back


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_in_the_middle_of_a_step_ends_the_run_after_it_whole(
    tmp_path, monkeypatch, signum
):
    # a signal that comes while the step is half done (here: while the sensors are read, after
    # the clock moved) waits until the step and its trajectory row are done: no row is lost
    # and the summary's step count is the trajectory's
    scen = _write(tmp_path, "def step(obs):\n    return (0.05, 0.0, 0.0)\n")
    sense = Simulation._sense

    def interrupted_sense(self, *args, **kwargs):
        if self.state.step == 20:
            signal.raise_signal(signum)
        sense(self, *args, **kwargs)

    monkeypatch.setattr(Simulation, "_sense", interrupted_sense)
    with pytest.raises(KeyboardInterrupt):
        run_scenario(scen, tmp_path / "out", plot=False, record_mcap=False)
    run = _summary(tmp_path / "out")
    assert run["status"] == "interrupted" and run["steps"] == 20
    rows = _rows(tmp_path / "out")
    assert len(rows) == run["steps"] + 1
    assert float(rows[-1]["t"]) == pytest.approx(run["simulated_time_s"]) == pytest.approx(0.4)


def test_sigterm_waits_while_outputs_are_written():
    order = []
    with pytest.raises(Terminated), terminate_as_interrupt() as stop:
        with hold_signals():
            signal.raise_signal(signal.SIGTERM)
            order.append("still writing")  # not cut short
            assert stop.requested is False
        order.append("never")
    assert order == ["still writing"]
    assert stop.requested


def test_a_second_ctrl_c_breaks_through_a_hold():
    reached = []
    with pytest.raises(KeyboardInterrupt):
        with hold_signals():
            signal.raise_signal(signal.SIGINT)
            reached.append(1)
            signal.raise_signal(signal.SIGINT)  # the user insists
            reached.append(2)
    assert reached == [1]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_step_guard_holds_only_while_holding_and_a_second_ctrl_c_breaks_through():
    reached = []
    with pytest.raises(KeyboardInterrupt), StepGuard() as guard:
        guard.holding = True
        signal.raise_signal(signal.SIGINT)
        reached.append("held")
        guard.release()  # delivered here
        reached.append("never")
    assert reached == ["held"]
    with pytest.raises(KeyboardInterrupt), StepGuard() as guard:
        guard.holding = True
        signal.raise_signal(signal.SIGINT)
        signal.raise_signal(signal.SIGINT)  # the user insists
        reached.append("never")
    with pytest.raises(KeyboardInterrupt), StepGuard():
        signal.raise_signal(signal.SIGINT)  # not holding: at once
        reached.append("never")
    assert reached == ["held"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_off_the_main_thread_signals_are_left_alone():
    seen = []

    def work():
        with terminate_as_interrupt() as stop, hold_signals():
            seen.append((stop.requested, signal.getsignal(signal.SIGTERM)))

    t = threading.Thread(target=work)
    t.start()
    t.join()
    assert seen == [(False, signal.SIG_DFL)]


# ------------------------------------------------------------------------------ time limit
HANGS = """
import time

def step(obs):
    if obs.t_s >= 0.2 - 1e-9:
        {body}
    return (0.1, 0.0, 0.0)
"""


@pytest.mark.parametrize(
    "body",
    [
        "time.sleep(3600)",
        "while True: pass",
        # caught once by a careless `except BaseException`, then returns: still a failure
        "try:\n            time.sleep(3600)\n        except BaseException:\n            pass",
    ],
    ids=["sleeps", "spins", "swallows"],
)
def test_a_hanging_controller_is_stopped_at_its_time_limit(tmp_path, body):
    scen = _write(tmp_path, HANGS.format(body=body))
    out = tmp_path / "out"
    t0 = time.monotonic()
    with pytest.raises(ControllerError) as info:
        run_scenario(scen, out, record_mcap=True, controller_time_limit_s=0.3)
    assert time.monotonic() - t0 < 60  # not an hour
    assert isinstance(info.value.cause, TimeLimitExceeded)
    message = str(info.value)
    assert "'student'" in message and "t=0.200 s" in message
    assert "time limit of 0.3 s" in message
    run = _summary(out)
    assert run["status"] == "controller_error" and "time limit of 0.3 s" in run["error"]
    assert run["simulated_time_s"] == pytest.approx(0.2)  # the hanging step never finished
    assert len(_rows(out)) == 11  # t = 0 .. 0.2 s
    assert (out / "plot.png").stat().st_size > 10_000
    assert signal.getsignal(signal.SIGALRM) is signal.SIG_DFL
    assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)


def test_the_time_limit_changes_no_number(tmp_path):
    scen = _write(tmp_path, HANGS.format(body="pass"), duration=3.0)
    run_scenario(scen, tmp_path / "a", plot=False, record_mcap=False)
    run_scenario(scen, tmp_path / "b", plot=False, controller_time_limit_s=None, record_mcap=False)
    a, b = (tmp_path / "a" / "trajectory.csv"), (tmp_path / "b" / "trajectory.csv")
    assert a.read_bytes() == b.read_bytes()


class _Slow:
    def __init__(self, seconds: float):
        self.seconds = seconds

    def __call__(self, obs):
        time.sleep(self.seconds)
        return (0.0, 0.0, 0.0)


def _robot() -> RobotSpec:
    model = DifferentialDrive(wheel_radius_m=0.1, half_track_m=0.25)
    return RobotSpec(name="r", model=model, initial_pose=(3.0, 3.0, 0.0))


def _sim(user_code: bool, limit: float | None) -> Simulation:
    return Simulation(
        World(walled_room(6, 6)),
        [_robot()],
        [Binding(_Slow(0.2), (0,), user_code=user_code)],
        controller_time_limit_s=limit,
    )


def test_only_user_code_is_timed():
    builtin = _sim(user_code=False, limit=0.05)
    with builtin.enforcing_time_limit():
        builtin.step()  # a built-in controller: trusted, not timed
    sim = _sim(user_code=True, limit=0.05)
    sim.step()  # outside enforcing_time_limit(): not timed either
    with pytest.raises(ControllerError, match="time limit of 0.05 s"):
        with sim.enforcing_time_limit():
            sim.step()
    assert sim.state.stopped[0] and sim.state.step == 1
    assert signal.getsignal(signal.SIGALRM) is signal.SIG_DFL
    assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)


@pytest.mark.parametrize("bad", [0, -1.0, float("nan"), float("inf"), "1", True])
def test_a_bad_time_limit_is_refused(bad):
    with pytest.raises(ValueError, match="time limit"):
        check_limit(bad)
    with pytest.raises(ValueError, match="time limit"):
        _sim(user_code=True, limit=None).controller_time_limit_s = bad


def test_the_clock_is_not_enforced_off_the_main_thread():
    found = []

    def work():
        with ControllerClock(1.0) as clock:
            found.append((clock.enforced, clock.running))

    t = threading.Thread(target=work)
    t.start()
    t.join()
    assert found == [(False, False)] and ControllerClock(1.0).enforced


# ------------------------------------------------------------------------------ SystemExit
EXITS = """
import sys

def step(obs):
    if obs.t_s >= 0.4 - 1e-9:
        sys.exit({code})
    return (0.1, 0.0, 0.0)
"""


def test_sys_exit_in_a_controller_is_a_controller_failure(tmp_path):
    scen = _write(tmp_path, EXITS.format(code=0))
    out = tmp_path / "out"
    proc = subprocess.run(
        [sys.executable, "-m", "agvsim.cli", "run", str(scen), "--out", str(out), "-q"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert proc.returncode == 1, proc.stderr  # not 0: the run did not complete
    assert "controller error" in proc.stderr and "SystemExit(0)" in proc.stderr, proc.stderr
    run = _summary(out)
    assert run["status"] == "controller_error"
    assert run["simulated_time_s"] == pytest.approx(0.4)
    assert (out / "plot.png").exists()


@pytest.mark.parametrize("where", ["import", "construction"])
def test_sys_exit_while_loading_a_controller_is_a_clear_error(tmp_path, where):
    from agvsim.scenario import ScenarioError

    code = (
        "import sys\nsys.exit(3)\n"
        if where == "import"
        else "import sys\ndef step():\n    sys.exit(3)\n"
    )
    scen = _write(tmp_path, code)
    with pytest.raises(ScenarioError, match="SystemExit"):
        run_scenario(scen, tmp_path / "out")
    assert not (tmp_path / "out" / "summary.json").exists()  # nothing ran


def test_exceptions_from_reset_name_the_robot():
    class BadReset:
        def reset(self):
            raise SystemExit(0)

        def step(self, obs):
            return (0.0, 0.0, 0.0)

    with pytest.raises(ControllerError, match=r"'r' failed at t=0.000 s: it raised SystemExit"):
        Simulation(World(walled_room(6, 6)), [_robot()], [Binding(BadReset(), (0,))])


def test_keyboard_interrupt_from_a_controller_still_interrupts(tmp_path):
    # Ctrl-C arrives wherever Python is, often inside the controller: it stops the run
    scen = _write(tmp_path, HANGS.format(body="raise KeyboardInterrupt"))
    with pytest.raises(KeyboardInterrupt):
        run_scenario(scen, tmp_path / "out", plot=False, record_mcap=False)
    assert _summary(tmp_path / "out")["status"] == "interrupted"
    assert np.isclose(_summary(tmp_path / "out")["simulated_time_s"], 0.2)


SWEEP_CONTROLLERS = """
import time
from pathlib import Path

def quick(obs):
    return (0.05, 0.0, 0.0)

def slow(obs):
    Path(__file__).with_name("started").touch()
    time.sleep(0.02)
    return (0.05, 0.0, 0.0)
"""


def test_sigterm_stops_a_sweep_like_ctrl_c_and_keeps_finished_runs(tmp_path):
    (tmp_path / "ctrl.py").write_text(SWEEP_CONTROLLERS)
    base = yaml_load(SCENARIO.format(duration=20.0))
    sweep = {
        "name": "stopped",
        "base": base,
        "vary": {"robots.0.controller.name": ["quick", "slow"]},
        "out": str(tmp_path / "out"),
    }
    (tmp_path / "sweep.yaml").write_text(yaml_dump(sweep))
    proc = subprocess.Popen(
        [sys.executable, "-m", "agvsim.cli", "sweep", str(tmp_path / "sweep.yaml"),
         "--workers", "1", "-q", "--no-plot"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 240
        while not (tmp_path / "started").exists():
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "the slow run did not start"
            time.sleep(0.05)
        proc.send_signal(signal.SIGTERM)
        _, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 143, stderr
    assert "interrupted" in stderr and "Traceback" not in stderr, stderr
    kept = sorted(p.name for p in (tmp_path / "out" / "runs").iterdir())
    assert len(kept) == 1 and kept[0].endswith(".json"), kept  # the quick run, done before


def test_a_hanging_controller_ends_its_sweep_or_grading_run_not_the_whole_job(tmp_path):
    from agvsim.experiments.runs import RunTask, execute

    (tmp_path / "ctrl.py").write_text(HANGS.format(body="time.sleep(3600)"))
    data = yaml_load(SCENARIO.format(duration=5.0))
    task = RunTask("r0", 0, 0, data, str(tmp_path), "test", controller_time_limit_s=0.3)
    t0 = time.monotonic()
    row = execute(task)
    assert time.monotonic() - t0 < 60
    assert row["status"] == "controller_error"  # a finished run: its row is kept
    assert "time limit of 0.3 s" in row["error"] and row["simulated_time_s"] == pytest.approx(0.2)


GRADED = """
import os, time
from pathlib import Path

def controller(obs):
    Path(__file__).with_name("task.pid").write_text(str(os.getpid()))
    time.sleep(0.05)
    return (0.1, 0.0, 0.0)
"""


def test_sigterm_stops_grading_and_its_task_process(tmp_path):
    (tmp_path / "student.py").write_text(GRADED)
    room = {
        "world": {"picture": "############\n#..........#\n#..........#\n############"},
        "robots": [{"name": "agv", "model": "differential", "pose": {"x_m": -3.0, "y_m": 0.0}}],
    }
    suite = {
        "name": "stopped",
        "time_limit_s": 600,
        "tasks": [{"name": "long", "scenario": room, "duration_s": 1000,
                   "goal": {"reach": {"x_m": 4.0, "y_m": 0.0}}}],
    }  # fmt: skip
    (tmp_path / "suite.yaml").write_text(yaml_dump(suite))
    proc = subprocess.Popen(
        [sys.executable, "-m", "agvsim.cli", "grade", str(tmp_path / "student.py"),
         "--suite", str(tmp_path / "suite.yaml"), "--out", str(tmp_path / "out"), "-q"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    pid_file = tmp_path / "task.pid"
    try:
        deadline = time.monotonic() + 240
        while not pid_file.exists() or not pid_file.read_text():
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "the task did not start"
            time.sleep(0.05)
        proc.send_signal(signal.SIGTERM)
        _, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 143, stderr
    assert "interrupted" in stderr and "Traceback" not in stderr, stderr
    task_pid = int(pid_file.read_text())
    assert not Path(f"/proc/{task_pid}").exists()  # the task's process went with it
