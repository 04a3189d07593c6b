"""How long vehicles really take to drive the road graph, learnt while they drive.

The road graph times an edge at its length over the vehicle's top speed (the slower of the
edge's limit and the factsheet's ``speedMax``). A real vehicle is slower than that on
average: it turns at nodes, slows for curves, its controller trails the path. A master that
plans with the optimistic times sees every vehicle run late, and since execution keeps the
planned order of the visits on each node, a late vehicle keeps the ones planned after it
waiting; at 1,000 vehicles the lateness compounds until most of the fleet waits
(docs/master.md, "Pace"). So the master measures it: each edge a vehicle drives without
having had to stop for it (granted well before the vehicle reached the node before it, no
action at that node, no planned wait) is a sample of (time taken, the graph's time), and
routes are planned with the graph's times scaled by the ratio of the two sums, per routing
graph (vehicle type and speed). Recent samples weigh more (``memory`` samples), so a change
of floor or load is followed; the scale stays within [1, ``max_scale``] and is 1 until
``min_samples`` were seen. Everything here is a function of the simulated times at which the
master saw the vehicles pass nodes: the same run gives the same scales.
"""

from __future__ import annotations

from dataclasses import dataclass

GRANT_LEAD_S = 2.0  # an edge counts if its end was granted this long before its start was reached
SAMPLE_CAP = 3.0  # one edge counts at most this many times its graph time (a stop mid-edge)


@dataclass
class Pace:
    min_samples: int = 30
    memory: float = 500.0  # samples: each new one weighs 1, one ``memory`` ago about 1/e
    max_scale: float = 3.0
    taken_s: float = 0.0  # weighted sums
    graph_s: float = 0.0
    samples: int = 0

    def add(self, taken_s: float, graph_s: float) -> None:
        """One edge driven in ``taken_s`` that the graph times at ``graph_s``."""
        if not graph_s > 0.0 or not taken_s >= 0.0:
            return
        keep = 1.0 - 1.0 / self.memory
        self.taken_s = self.taken_s * keep + min(taken_s, SAMPLE_CAP * graph_s)
        self.graph_s = self.graph_s * keep + graph_s
        self.samples += 1

    @property
    def scale(self) -> float:
        """What to multiply the graph's travel times by when planning."""
        if self.samples < self.min_samples or self.graph_s <= 0.0:
            return 1.0
        return min(self.max_scale, max(1.0, self.taken_s / self.graph_s))
