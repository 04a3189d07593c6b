"""The master's outputs: ``summary.json`` and ``waiting.png``, a heat map of the time vehicles
spent waiting for reservations at each node, drawn on the layout."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from agvsim.world.lif import Layout


def write_summary(path: Path, scenario: str, seed: int, summary: dict[str, Any]) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    doc = {"scenario": scenario, "seed": seed, "master": summary}
    path.write_text(json.dumps(doc, indent=2, sort_keys=False) + "\n", encoding="utf-8")
    return path


def waiting_heatmap(path: Path, layout: Layout, waiting_s: dict[str, float], title: str) -> Path:
    """Edges in grey, nodes as dots coloured (and sized) by their waiting time (s)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    xs = [n.x_m for n in layout.nodes.values()]
    ys = [n.y_m for n in layout.nodes.values()]
    w = max(xs) - min(xs) or 1.0
    h = max(ys) - min(ys) or 1.0
    fig, ax = plt.subplots(figsize=(10, max(3.0, min(12.0, 10 * h / w)) + 0.8), dpi=110)
    for e in layout.edges.values():
        (x0, y0), (x1, y1) = layout.node_xy(e.start), layout.node_xy(e.end)
        ax.plot([x0, x1], [y0, y1], color="0.8", lw=1.5, zorder=1)
    ids = sorted(layout.nodes)
    vals = [waiting_s.get(n, 0.0) for n in ids]
    top = max(vals) or 1.0
    sc = ax.scatter(
        [layout.nodes[n].x_m for n in ids],
        [layout.nodes[n].y_m for n in ids],
        c=vals,
        s=[12 + 200 * v / top for v in vals],
        cmap="inferno_r",
        vmin=0,
        vmax=top,
        edgecolors="0.3",
        linewidths=0.4,
        zorder=2,
    )
    for n, v in sorted(zip(ids, vals, strict=True), key=lambda p: -p[1])[:5]:
        if v > 0:
            ax.annotate(n, layout.node_xy(n), fontsize=7, xytext=(4, 4), textcoords="offset points")
    fig.colorbar(sc, ax=ax, label="waiting for reservations (s)", shrink=0.8)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title, fontsize=10)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)
    return path
