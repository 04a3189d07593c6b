"""What the master measures: throughput, lead times, utilisation, waiting per node, energy,
collisions and deadlocks; ``summary()`` is the ``master`` part of ``summary.json``."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from agvsim.master.master import Master
    from agvsim.master.orders import Transport

STATES = ("loaded", "empty", "waiting", "handling", "charging", "idle", "broken")


@dataclass
class Metrics:
    lead_times_s: list[float] = field(default_factory=list)
    time_s: dict[str, dict[str, float]] = field(default_factory=dict)  # serial -> state -> s
    node_wait_s: dict[str, float] = field(default_factory=lambda: defaultdict(float))
    energy_used_pct: float = 0.0
    energy_charged_pct: float = 0.0
    deadlocks: int = 0
    breakdowns: int = 0
    stalls: int = 0
    retimed: int = 0  # routes re-planned because their vehicle ran late
    collisions: int = 0  # filled in by the runner (the simulation counts contacts)
    _battery: dict[str, float] = field(default_factory=dict)

    def delivered(self, tr: Transport) -> None:
        if tr.lead_time_s is not None:
            self.lead_times_s.append(tr.lead_time_s)

    def step(self, m: Master, dt: float) -> None:
        for agv in m.agvs.values():
            st = agv.state
            if st is None:
                continue
            b = agv.battery_pct
            prev = self._battery.get(agv.serial, b)
            self.energy_used_pct += max(0.0, prev - b)
            self.energy_charged_pct += max(0.0, b - prev)
            self._battery[agv.serial] = b
            if dt <= 0:
                continue
            if agv.broken:
                what = "broken"
            elif agv.charging:
                what = "charging"
            elif st.get("driving"):
                what = "loaded" if st.get("loads") else "empty"
            elif m.waiting(agv):
                what = "waiting"
                self.node_wait_s[agv.route[agv.reached].node] += dt
            elif any(a.get("actionStatus") == "RUNNING" for a in st.get("actionStates", [])):
                what = "handling"
            elif not agv.order_done:
                what = "empty"  # between two messages: moving on
            else:
                what = "idle"
            row = self.time_s.setdefault(agv.serial, dict.fromkeys(STATES, 0.0))
            row[what] += dt

    def summary(self, m: Master, duration_s: float) -> dict[str, Any]:
        lt = np.array(self.lead_times_s)
        total = {k: sum(r[k] for r in self.time_s.values()) for k in STATES}
        all_s = sum(total.values()) or 1.0
        done = [t for t in m.transports if t.delivered_s is not None]
        return {
            "orders_placed": len(m.transports) - len(m.upcoming),
            "orders_completed": len(done),
            "orders_open": len(m.transports) - len(m.upcoming) - len(done),
            "orders_per_hour": round(len(done) / (duration_s / 3600.0), 3) if duration_s else 0,
            "lead_time_mean_s": round(float(lt.mean()), 3) if lt.size else None,
            "lead_time_p95_s": round(float(np.percentile(lt, 95)), 3) if lt.size else None,
            "utilisation": {k: round(v / all_s, 4) for k, v in total.items()},
            "waiting_s_by_node": {
                k: round(v, 2) for k, v in sorted(self.node_wait_s.items()) if v > 0
            },
            "energy_used_pct": round(self.energy_used_pct, 3),
            "energy_charged_pct": round(self.energy_charged_pct, 3),
            "collisions": self.collisions,
            "deadlocks": self.deadlocks,
            "stalls": self.stalls,
            "breakdowns": self.breakdowns,
            "replan_failures": m.replan_failures,
            "late_replans": self.retimed,
        }
