"""The one run loop (agvsim.run_loop): observers in order after every step, the run ended by
one of them, the status it reports, SIGTERM after a step; the runner and a sweep's run share
it and agree."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_sim import arena, robot

from agvsim.control.script import ScriptController, ScriptStep
from agvsim.run_loop import Metrics, Progress, Recording, Rows, Trail, close_all, run_loop
from agvsim.signals import StopRequest, Terminated
from agvsim.sim.engine import Binding, Simulation

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"


class Log:
    """An observer writing (name, step) into a shared log; ends the run at ``end_at``."""

    def __init__(self, name: str, log: list, end_at: int | None = None):
        self.name, self.log, self.end_at = name, log, end_at

    def on_step(self, sim: Simulation) -> bool:
        self.log.append((self.name, sim.state.step))
        return sim.state.step == self.end_at

    def close(self) -> None:
        self.log.append((self.name, "closed"))


def driving() -> Simulation:
    steps = [ScriptStep(10.0, twist=(0.5, 0.0, 0.0))]
    return Simulation(
        arena(), [robot(pose=(-3.0, 0.0, 0.0))], [Binding(ScriptController(steps), (0,))]
    )


def test_observers_see_every_step_in_order_and_close_in_order():
    sim, log = driving(), []
    obs = [Log("a", log), Log("b", log)]
    assert run_loop(sim, 3, obs) == "completed"
    assert log == [("a", 1), ("b", 1), ("a", 2), ("b", 2), ("a", 3), ("b", 3)]
    close_all(obs)
    assert log[-2:] == [("a", "closed"), ("b", "closed")]
    assert sim.state.step == 3
    # 3 steps of 0.02 s at 0.5 m/s: 0.03 m east
    assert sim.state.poses[0, 0] == pytest.approx(-3.0 + 0.03, abs=1e-12)


def test_an_observer_ends_the_run_and_the_ones_after_it_miss_that_step():
    sim, log = driving(), []
    obs = [Log("a", log), Log("m", log, end_at=2), Log("z", log)]
    assert run_loop(sim, 10, obs) == "ended_by_metric"
    assert log == [("a", 1), ("m", 1), ("z", 1), ("a", 2), ("m", 2)]
    assert sim.state.step == 2


def test_stop_robot_errors_are_reported_even_when_a_metric_ends_the_run():
    def bad(obs):
        raise RuntimeError("boom")

    sim = Simulation(
        arena(),
        [robot("ok", pose=(-3.0, 0.0, 0.0)), robot("bad", pose=(3.0, 0.0, 0.0))],
        [Binding(lambda obs: (0.1, 0.0, 0.0), (0,)), Binding(bad, (1,))],
        on_controller_error="stop_robot",
    )
    assert run_loop(sim, 5, [Log("m", [], end_at=3)]) == "completed_with_controller_errors"
    assert sim.state.step == 3 and sim.state.stopped.tolist() == [False, True]


def test_a_swallowed_sigterm_stops_after_the_step():
    sim, log, stop = driving(), [], StopRequest()

    class Swallow(Log):
        def on_step(self, sim):
            stop.requested = sim.state.step == 2
            return super().on_step(sim)

    with pytest.raises(Terminated):
        run_loop(sim, 10, [Swallow("s", log)], stop)
    assert log == [("s", 1), ("s", 2)]


def test_adapters_record_the_start_when_made_and_every_step_after():
    class Target:
        def __init__(self) -> None:
            self.calls: list[str] = []

        def record(self) -> None:
            self.calls.append("record")

        def close(self) -> None:
            self.calls.append("close")

    sim = driving()
    rows, plain = Target(), Target()
    obs = [Rows(rows), Recording(plain)]
    assert rows.calls == ["record"] and plain.calls == []
    run_loop(sim, 2, obs)
    close_all(obs)
    assert rows.calls == ["record", "record", "record", "close"]
    assert plain.calls == ["record", "record", "close"]


def test_trail_progress_and_metrics_observers():
    class Goal:
        def __init__(self) -> None:
            self.seen = 0

        def update(self, sim):
            self.seen += 1
            return sim.state.step == 4

        def result(self):
            return {"seen": self.seen}

    sim, reports = driving(), []
    other = Goal()
    metrics = Metrics({"goal": Goal(), "other": other})
    trail = Trail(sim, every=2)
    progress = Progress(lambda t, total: reports.append(round(t, 9)), 1.0, 10)
    assert run_loop(sim, 10, [metrics, trail, progress]) == "ended_by_metric"
    assert metrics.results() == {"goal": {"seen": 4}, "other": {"seen": 4}}  # both saw step 4
    xs = [float(p[0]) for p in trail.xy["r"]]
    np.testing.assert_allclose(xs, [-3.0 + 0.01 * 1, -3.0 + 0.01 * 3], atol=1e-12)
    assert reports == [0.02]  # the first step (then every 50th and the last of 10)


def test_run_and_sweep_row_agree(tmp_path):
    from agvsim.experiments.runs import RunTask, execute
    from agvsim.runner import run_scenario
    from agvsim.safe_yaml import load_yaml_file

    path = SCENARIOS / "thesis_pursuit.yaml"
    data = run_scenario(path, tmp_path / "run", duration_s=4.0, seed=3, plot=False)
    cfg = dict(load_yaml_file(path))
    cfg["duration_s"] = 4.0
    row = execute(RunTask("r", 0, 3, cfg, str(path.parent), str(path)))
    assert row["status"] == data["run"]["status"]
    assert row["steps"] == data["run"]["steps"] == 200
    for rb in data["robots"]:
        assert row[f"{rb['name']}.final_x_m"] == rb["final_pose"]["x_m"]
        assert row[f"{rb['name']}.distance_m"] == rb["distance_m"]
