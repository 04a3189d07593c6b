"""The master's utilisation metrics, kept incrementally (a vehicle's time goes to its state
when the state changes), against the sums of the per-tick definition worked by hand."""

from __future__ import annotations

import pytest

from agvsim.master.agv import Agv
from agvsim.master.metrics import Metrics
from agvsim.master.traffic import Step


class FakeMaster:
    """What the metrics read of the master: the vehicles, and whether one waits."""

    def __init__(self, agvs: dict[str, Agv]):
        self.agvs, self.transports, self.upcoming, self.replan_failures = agvs, [], [], 0
        self.waiting_at: dict[str, bool] = {}

    def waiting(self, agv: Agv) -> bool:
        return self.waiting_at.get(agv.serial, False)

    def pace_summary(self) -> dict:
        return {}


def state(driving: bool, loaded: bool = False, battery: float = 80.0) -> dict:
    return {
        "driving": driving,
        "loads": [{"loadId": "x"}] if loaded else [],
        "actionStates": [],
        "batteryState": {"batteryCharge": battery, "charging": False},
    }


def test_time_per_state_and_waiting_node_by_hand() -> None:
    a = Agv("A", "m", "2.1.0", None, order_done=False)  # type: ignore[arg-type]
    b = Agv("B", "m", "2.1.0", None)  # type: ignore[arg-type]
    a.route = [Step("n0", 0.0, 1.0), Step("n1", 2.0, 3.0)]
    m = FakeMaster({"A": a, "B": b})
    met = Metrics()
    # t=1: A drives loaded, B is idle (a state seen at a tick holds since the tick before)
    a.state, b.state = state(True, loaded=True), state(False)
    met.step(m, 1.0, ["A", "B"])  # type: ignore[arg-type]
    met.step(m, 2.0, [])  # type: ignore[arg-type]  # nothing new: both keep their states
    # t=3: A stopped at n1 waiting for a reservation
    a.state, a.reached = state(False, loaded=True), 1
    m.waiting_at["A"] = True
    met.step(m, 3.0, ["A"])  # type: ignore[arg-type]
    # t=4.5: A drives on, empty
    a.state = state(True)
    m.waiting_at["A"] = False
    met.step(m, 4.5, ["A"])  # type: ignore[arg-type]
    met.step(m, 6.0, [])  # type: ignore[arg-type]
    s = met.summary(m, 6.0)  # type: ignore[arg-type]
    # per tick: A loaded on (0,1], (1,2]; waiting on (2,3]; empty on (3,4.5], (4.5,6];
    # B idle all 6 s: 12 vehicle-seconds in all
    u = s["utilisation"]  # (rounded to 4 decimals)
    assert u["loaded"] == pytest.approx(2 / 12, abs=1e-4)
    assert u["waiting"] == pytest.approx(1 / 12, abs=1e-4)
    assert u["empty"] == pytest.approx(3 / 12, abs=1e-4)
    assert u["idle"] == pytest.approx(6 / 12, abs=1e-4)
    assert s["waiting_s_by_node"] == {"n1": 1.0}
    # credited when the state changed: loaded at t=3, waiting at t=4.5; B and A's empty
    # time are still open (in the summary, not yet in time_s)
    assert met.time_s["A"] == {**dict.fromkeys(met.time_s["A"], 0.0), "loaded": 2.0, "waiting": 1.0}
    assert met.time_s["B"]["idle"] == 0.0


def test_energy_counts_every_state_message() -> None:
    met = Metrics()
    for pct in (80.0, 79.5, 79.0, 85.0, 90.0, 89.75):
        met.battery("A", pct)
    assert met.energy_used_pct == pytest.approx(0.5 + 0.5 + 0.25)
    assert met.energy_charged_pct == pytest.approx(6.0 + 5.0)
