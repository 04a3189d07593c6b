"""Shared by the scripts that draw a SLAM-suite building (``make_slam_*.py``): write a route
into the waypoint list that ends a scenario file."""

from __future__ import annotations

import math
import re
from pathlib import Path


def write_route(root: Path, name: str, route: list[tuple[float, float]], script: str) -> None:
    """Replace the ``points:`` list at the end of ``root / (name + ".yaml")`` with ``route``
    (m, two decimals; consecutive repeats dropped) and print what was written."""
    kept: list[tuple[float, float]] = []
    for x, y in route:
        if not kept or math.hypot(x - kept[-1][0], y - kept[-1][1]) > 1e-6:
            kept.append((float(x), float(y)))
    path = root / f"{name}.yaml"
    head = re.split(r"(?m)^      points:.*\n", path.read_text())[0]
    points = "".join(f"        - [{x:.2f}, {y:.2f}]\n" for x, y in kept)
    path.write_text(head + f"      points:  # written by scripts/{script}\n" + points)
    length = sum(math.dist(a, b) for a, b in zip(kept[:-1], kept[1:], strict=True))
    print(f"wrote {root / (name + '.png')} and {len(kept)} waypoints ({length:.0f} m)")
