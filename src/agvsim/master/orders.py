"""Transport orders: from the scenario's list, or generated at a rate between stations.

Generation is a Poisson process (exponential gaps at ``rate_per_h``) with source and
destination drawn uniformly (never the same node), from a ``numpy`` generator seeded by the
scenario seed: the same seed places the same orders at the same times.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agvsim.master.config import MasterConfig
from agvsim.world.lif import Layout


@dataclass
class Transport:
    transport_id: str
    source: str  # node id
    destination: str  # node id
    created_s: float
    vehicle: str | None = None
    assigned_s: float | None = None
    picked_s: float | None = None
    delivered_s: float | None = None
    attempts: int = 0  # reassignments after a breakdown

    @property
    def lead_time_s(self) -> float | None:
        return None if self.delivered_s is None else self.delivered_s - self.created_s


def node_of(layout: Layout, name: str, where: str) -> str:
    """A station's (first) interaction node, or a node id; ValueError naming ``where``."""
    if name in layout.stations:
        return layout.stations[name].interaction_node_ids[0]
    if name in layout.nodes:
        return name
    stations = sorted(layout.stations)
    raise ValueError(
        f"{where}: {name!r} is neither a station nor a node of layout {layout.layout_id!r}; "
        f"stations: {stations[:12]}{' ...' if len(stations) > 12 else ''}"
    )


def transport_stations(layout: Layout) -> list[str]:
    """The stations that are not chargers (a charging station offers startCharging)."""
    out = []
    for sid, st in sorted(layout.stations.items()):
        node = layout.nodes.get(st.interaction_node_ids[0])
        if node is None:
            continue
        charges = any(
            a.get("actionType") == "startCharging" for p in node.types.values() for a in p.actions
        )
        if not charges:
            out.append(sid)
    return out


def scheduled_transports(
    layout: Layout, cfg: MasterConfig, seed: int, horizon_s: float
) -> list[Transport]:
    """Every transport order placed before ``horizon_s``, sorted by time then id."""
    out: list[Transport] = []
    for k, entry in enumerate(cfg.transports):
        where = f"master.transports[{k}]"
        src = node_of(layout, entry.source, f"{where}.source")
        dst = node_of(layout, entry.destination, f"{where}.destination")
        if src == dst:
            raise ValueError(f"{where}: source and destination are the same node {src!r}")
        out.append(Transport(f"T{k + 1:04d}", src, dst, entry.at_s))
    g = cfg.generate
    if g is not None:
        every = transport_stations(layout)
        srcs = [node_of(layout, s, "master.generate.sources") for s in g.sources or every]
        dsts = [node_of(layout, s, "master.generate.destinations") for s in g.destinations or every]
        if not srcs or not dsts or len(set(srcs) | set(dsts)) < 2:
            raise ValueError("master.generate: needs at least two distinct station nodes")
        rng = np.random.default_rng(seed)
        end = min(horizon_s, g.until_s if g.until_s is not None else horizon_s)
        t, k = 0.0, 0
        while True:
            t += float(rng.exponential(3600.0 / g.rate_per_h))
            if t >= end:
                break
            src = srcs[int(rng.integers(len(srcs)))]
            choices = [d for d in dsts if d != src]
            if not choices:
                continue
            dst = choices[int(rng.integers(len(choices)))]
            k += 1
            out.append(Transport(f"G{k:05d}", src, dst, round(t, 3)))
    out.sort(key=lambda x: (x.created_s, x.transport_id))
    return out
