"""Write the five guidance scenarios (docs/guidance.md): one small warehouse, one route, one
guidance each (tape, floor codes, reflectors, odometry alone, reflectors with a blind spot).

    python scripts/make_guidance_scenarios.py      # rewrites scenarios/guidance_*.yaml
"""

from __future__ import annotations

import math
from pathlib import Path

import yaml

OUT = Path(__file__).resolve().parent.parent / "scenarios"

# the warehouse: 16 x 11 m in 0.5 m cells, walls round it, one rack block 6 x 2 m in the middle
COLS, ROWS, CELL = 32, 22, 0.5


def picture() -> str:
    rows = []
    for r in range(ROWS):
        y_top = ROWS * CELL / 2 - r * CELL
        line = ""
        for c in range(COLS):
            x_left = -COLS * CELL / 2 + c * CELL
            border = r in (0, ROWS - 1) or c in (0, COLS - 1)
            rack = -3.0 <= x_left < 3.0 and -1.0 < y_top <= 1.0
            line += "#" if border or rack else "."
        rows.append(line)
    return "\n".join(rows) + "\n"


# the route: round the rack block anticlockwise, 1 m corner radius, from (-3.5, -2.5) east
X, Y, R = 4.5, 2.5, 1.0
CORNERS = [  # arc centre, start angle (deg) of each quarter turn
    ((X - R, -Y + R), -90.0),
    ((X - R, Y - R), 0.0),
    ((-X + R, Y - R), 90.0),
    ((-X + R, -Y + R), 180.0),
]


def route_points(turns: int = 3, per_arc: int = 8) -> list[list[float]]:
    """The route as a polyline: straights and ``turns`` quarter arcs (chords every
    90/per_arc deg); it ends on the fourth side."""
    pts = [[-X + R, -Y]]
    for (cx, cy), a0 in CORNERS[:turns]:
        for k in range(per_arc + 1):
            a = math.radians(a0 + 90.0 * k / per_arc)
            pts.append([round(cx + R * math.cos(a), 4), round(cy + R * math.sin(a), 4)])
    pts.append([-X, -Y + R])
    return pts


def tape() -> dict:
    """The route as tape, a closed loop: four straights and four arcs, with a spot at the
    start of each straight."""
    lines: list[dict] = [
        {"points": [[-X + R, -Y], [X - R, -Y]]},
        {"points": [[X, -Y + R], [X, Y - R]]},
        {"points": [[X - R, Y], [-X + R, Y]]},
        {"points": [[-X, Y - R], [-X, -Y + R]]},
    ]
    for (cx, cy), a0 in CORNERS:
        lines.append({"arc": {"center": [cx, cy], "radius_m": R, "start_deg": a0, "sweep_deg": 90}})
    spots = [
        {"x_m": -X + R + 0.5, "y_m": -Y, "code": 1},
        {"x_m": X, "y_m": -Y + R + 0.5, "code": 2},
        {"x_m": X - R - 0.5, "y_m": Y, "code": 3},
        {"x_m": -X, "y_m": Y - R - 0.5, "code": 4},
    ]
    return {"width_m": 0.05, "lines": lines, "spots": spots}


FLOOR_CODES = {
    "cols": 14,
    "rows": 10,
    "spacing_m": 1.0,
    "size_m": 0.05,
    "origin_xy_m": [-6.5, -4.5],
}

# reflectors on the inner faces of the outer walls (x = +-7.5, y = +-5) and on the rack block
WALLS_SOUTH = [[x, -5.0] for x in (-6.0, -2.0, 2.0, 6.0)]
WALLS_NORTH = [[x, 5.0] for x in (-6.0, -2.0, 2.0, 6.0)]
WALLS_WEST = [[-7.5, y] for y in (-3.0, 0.0, 3.0)]
WALLS_EAST = [[7.5, y] for y in (-3.0, 0.0, 3.0)]
RACK_SOUTH = [[x, -1.0] for x in (-2.0, 2.0)]
RACK_NORTH = [[x, 1.0] for x in (-2.0, 2.0)]
ALL_REFLECTORS = WALLS_SOUTH + WALLS_NORTH + WALLS_WEST + WALLS_EAST + RACK_SOUTH + RACK_NORTH
# the blind spot: nothing on the north wall, the rack's north face or the upper side walls,
# so along the north side of the route no reflector is in sight
BLIND_REFLECTORS = WALLS_SOUTH + RACK_SOUTH + [[-7.5, -3.0], [7.5, -3.0]]

ROBOT = {
    "name": "agv",
    "model": "differential",
    "params": {"wheel_radius_m": 0.1, "half_track_m": 0.25},
    "body": {"length_m": 0.6, "width_m": 0.45},
    "pose": {"x_m": -X + R, "y_m": -Y, "theta_deg": 0},
    "odometry": {"wheel_noise_rel": 0.03},
}
LIDAR = {
    "type": "lidar",
    "beams": 1080,
    "rate_hz": 10,
    "range_max_m": 20.0,
    "noise_std_m": 0.01,
    "mount_x_m": 0.0,
}


def scenario(name: str, text: str, world_extra: dict, sensors: list, controller: dict) -> dict:
    return {
        "name": name,
        "seed": 0,
        "duration_s": 60,
        "world": {"cell_size_m": CELL, "picture": picture(), **world_extra},
        "robots": [{**ROBOT, "sensors": sensors, "controller": controller}],
        "_comment": text,
    }


def route(localization: str) -> dict:
    return {"type": "route", "points": route_points(), "localization": localization}


class _Dumper(yaml.SafeDumper):
    """Text of several lines (the map picture) as a literal block."""


def _text(dumper: yaml.SafeDumper, data: str) -> yaml.ScalarNode:
    style = "|" if "\n" in data else None
    return dumper.represent_scalar("tag:yaml.org,2002:str", data, style=style)


def _list(dumper: yaml.SafeDumper, data: list) -> yaml.SequenceNode:
    flat = all(isinstance(v, int | float) for v in data)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flat or None)


_Dumper.add_representer(str, _text)
_Dumper.add_representer(list, _list)


def main() -> None:
    files = {
        "guidance_tape": scenario(
            "Guidance: magnetic tape",
            "a line sensor over the tape, PID line following",
            {"tape": tape()},
            [{"type": "line", "elements": 16, "span_m": 0.16, "mount_x_m": 0.3}],
            {"type": "line_follow", "speed_m_s": 0.5},
        ),
        "guidance_floor_codes": scenario(
            "Guidance: floor codes",
            "a downward camera reads the floor codes; odometry between them",
            {"floor_codes": FLOOR_CODES},
            [{"type": "floor_camera", "rate_hz": 10}],
            route("floor_codes"),
        ),
        "guidance_reflectors": scenario(
            "Guidance: reflectors",
            "the lidar sees reflectors; an EKF fuses them with odometry",
            {"reflectors": {"width_m": 0.1, "points": ALL_REFLECTORS}},
            [LIDAR],
            route("reflectors"),
        ),
        "guidance_reflectors_blind_spot": scenario(
            "Guidance: reflectors with a blind spot",
            "no reflector in sight along the north side of the route: odometry alone there",
            {"reflectors": {"width_m": 0.1, "points": BLIND_REFLECTORS}},
            [LIDAR],
            route("reflectors"),
        ),
        "guidance_odometry": scenario(
            "Guidance: odometry alone (baseline)",
            "dead reckoning from the wheel encoders, no infrastructure",
            {},
            [],
            route("odometry"),
        ),
    }
    for stem, data in files.items():
        text = data.pop("_comment")
        body = yaml.dump(data, Dumper=_Dumper, sort_keys=False, width=100)
        head = (
            f"# {data['name']}: {text}.\n"
            "# The same route in the same warehouse as the other guidance_*.yaml\n"
            "# (docs/guidance.md);\n"
            "# generated by scripts/make_guidance_scenarios.py.\n"
        )
        (OUT / f"{stem}.yaml").write_text(head + body, encoding="utf-8")
        print(f"wrote scenarios/{stem}.yaml")


if __name__ == "__main__":
    main()
