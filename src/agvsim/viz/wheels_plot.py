"""``wheels.png``: wheel torque and slip over time of the robots with dynamics, and how far
their wheel odometry has drifted from the true pose, read back from ``trajectory.csv``
(written next to ``plot.png`` when a run has such robots)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from agvsim.viz.plot import save_figure

MAX_ROBOTS = 6  # rows of the figure; further robots are left out (their data stays in the CSV)


def read_wheels(csv_path: Path, robots: dict[str, list[str]]) -> dict[str, dict[str, np.ndarray]]:
    """Per robot of ``robots`` (name -> wheel names): ``t`` (T,), ``torque_nm`` and
    ``slip_m_s`` (T, W) and ``odometry_error_m`` (T,), the distance from the odometry's
    position to the true one, from a trajectory.csv with the dynamics columns."""
    rows: dict[str, list[list[float]]] = {name: [] for name in robots}
    with open(csv_path, encoding="utf-8", newline="") as f:
        reader = csv.reader(f)
        header = next(reader)
        col_t, col_robot = header.index("t"), header.index("robot")
        torque = [header.index(f"wheel{k + 1}_torque_nm") for k in range(4)]
        slip = [header.index(f"wheel{k + 1}_slip_m_s") for k in range(4)]
        pos = [header.index(c) for c in ("x", "y", "odom_x", "odom_y")]
        for r in reader:
            name = r[col_robot]
            if name in rows:
                n = len(robots[name])
                rows[name].append(
                    [float(r[col_t])]
                    + [float(r[c]) for c in torque[:n]]
                    + [float(r[c]) for c in slip[:n]]
                    + [float(r[c]) for c in pos]
                )
    out = {}
    for name, data in rows.items():
        n = len(robots[name])
        a = np.array(data, dtype=np.float64).reshape(-1, 5 + 2 * n)
        x, y, ox, oy = a[:, -4:].T
        out[name] = {
            "t": a[:, 0],
            "torque_nm": a[:, 1 : 1 + n],
            "slip_m_s": a[:, 1 + n : 1 + 2 * n],
            "odometry_error_m": np.hypot(ox - x, oy - y),
        }
    return out


def plot_wheels(
    csv_path: Path, png_path: Path, robots: dict[str, list[str]], title: str = ""
) -> None:
    """Torque and slip speed of each wheel and the odometry's error against time, one row
    per robot."""
    import matplotlib.pyplot as plt

    names = list(robots)[:MAX_ROBOTS]
    data = read_wheels(csv_path, {n: robots[n] for n in names})
    fig, axes = plt.subplots(len(names), 3, figsize=(13, 2.2 * len(names) + 0.6), squeeze=False)
    for row, name in enumerate(names):
        d = data[name]
        for k, wheel in enumerate(robots[name]):
            axes[row, 0].plot(d["t"], d["torque_nm"][:, k], lw=1, label=wheel)
            axes[row, 1].plot(d["t"], d["slip_m_s"][:, k], lw=1, label=wheel)
        axes[row, 0].set_ylabel(f"{name}\ntorque [N m]")
        axes[row, 1].set_ylabel("slip [m/s]")
        axes[row, 1].legend(loc="upper right", fontsize=7, frameon=False)
        axes[row, 2].plot(d["t"], d["odometry_error_m"], lw=1, color="k")
        axes[row, 2].set_ylabel("odometry error [m]")
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    fig.suptitle(title or "wheel torque, slip and odometry drift")
    fig.tight_layout()
    save_figure(fig, png_path)
