"""What the master measures: throughput, lead times, utilisation, waiting per node, energy,
collisions and deadlocks; ``summary()`` is the ``master`` part of ``summary.json``.

Kept incrementally: each vehicle is in one state (driving loaded or empty, waiting at a node,
handling a load, charging, idle, broken) from a tick on; the master re-classifies only the
vehicles that reported or that it changed since the last tick, and a vehicle's time goes to
its state when the state changes (the same sums as adding every tick's duration to every
vehicle's state at that tick, at O(changes) rather than O(fleet) a tick).
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from agvsim.master.agv import Agv
    from agvsim.master.master import Master
    from agvsim.master.orders import Transport

STATES = ("loaded", "empty", "waiting", "handling", "charging", "idle", "broken")


def classify(m: Master, agv: Agv) -> tuple[str, str | None]:
    """What the vehicle is doing now, and the node it waits at (waiting only)."""
    st = agv.state or {}
    if agv.broken:
        return "broken", None
    if agv.charging:
        return "charging", None
    if st.get("driving"):
        return ("loaded" if st.get("loads") else "empty"), None
    if m.waiting(agv):
        return "waiting", agv.route[agv.reached].node
    if any(a.get("actionStatus") == "RUNNING" for a in st.get("actionStates", [])):
        return "handling", None
    if not agv.order_done:
        return "empty", None  # between two messages: moving on
    return "idle", None


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
    # serial -> (state, node waited at, since when (s)): time not yet added to time_s
    _now: dict[str, tuple[str, str | None, float]] = field(default_factory=dict)
    _t_s: float = 0.0  # the last tick

    def delivered(self, tr: Transport) -> None:
        if tr.lead_time_s is not None:
            self.lead_times_s.append(tr.lead_time_s)

    def battery(self, serial: str, pct: float) -> None:
        """A vehicle reported its battery: the change counts as used or charged energy."""
        prev = self._battery.get(serial, pct)
        self.energy_used_pct += max(0.0, prev - pct)
        self.energy_charged_pct += max(0.0, pct - prev)
        self._battery[serial] = pct

    def step(self, m: Master, t_s: float, serials: Iterable[str]) -> None:
        """The tick at ``t_s``: re-classify ``serials`` (everyone whose state may have changed
        since the last tick). A state seen at a tick holds since the tick before."""
        t0 = self._t_s
        for s in serials:
            agv = m.agvs[s]
            if agv.state is None:
                continue
            what, node = classify(m, agv)
            cur = self._now.get(s)
            if cur is None:
                self.time_s.setdefault(s, dict.fromkeys(STATES, 0.0))
                self._now[s] = (what, node, t0)
            elif (what, node) != cur[:2]:
                self._add(s, cur, t0)
                self._now[s] = (what, node, t0)
        self._t_s = max(t0, t_s)

    def _add(self, serial: str, cur: tuple[str, str | None, float], until_s: float) -> None:
        what, node, since = cur
        if until_s > since:
            self.time_s[serial][what] += until_s - since
            if node is not None:
                self.node_wait_s[node] += until_s - since

    def summary(self, m: Master, duration_s: float) -> dict[str, Any]:
        lt = np.array(self.lead_times_s)
        total = {k: sum(r[k] for r in self.time_s.values()) for k in STATES}
        waits = defaultdict(float, self.node_wait_s)
        for what, node, since in self._now.values():  # the time in the current states
            if self._t_s > since:
                total[what] += self._t_s - since
                if node is not None:
                    waits[node] += self._t_s - since
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
            "waiting_s_by_node": {k: round(v, 2) for k, v in sorted(waits.items()) if v > 0},
            "energy_used_pct": round(self.energy_used_pct, 3),
            "energy_charged_pct": round(self.energy_charged_pct, 3),
            "collisions": self.collisions,
            "deadlocks": self.deadlocks,
            "stalls": self.stalls,
            "breakdowns": self.breakdowns,
            "replan_failures": m.replan_failures,
            "late_replans": self.retimed,
            "plan_pace": m.pace_summary(),
        }
