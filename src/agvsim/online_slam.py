"""SLAM inside a run: a robot's ``slam:`` block feeds its lidar scans and wheel odometry to
:class:`agvsim.slam.GraphSlam` as the simulation goes.

The SLAM sees only what a real robot would: the scans (with the sensor's noise and dropouts)
and the dead-reckoned odometry, starting from the robot's known initial pose (so its map is in
the world frame). Ground truth is kept beside it only to score the result: the trajectory's
absolute error and the map's IoU against the true wall surfaces
(:mod:`agvsim.metrics.map_quality`).

Outputs (``write``): ``slam_<robot>/trajectory.txt`` (``timestamp x y theta`` per scan, robot
base pose), ``map.pgm`` + ``map.yaml`` (ROS map_server), ``map.png`` and ``compare.png`` (the
map over the true walls, with the true, SLAM and odometry paths).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from agvsim.metrics.map_quality import map_iou, trajectory_error
from agvsim.scenario_schema import Scenario, SlamBlock
from agvsim.sim.engine import Simulation
from agvsim.slam.graph_slam import GraphSlam, SlamConfig
from agvsim.slam.loop_closure import LoopConfig
from agvsim.slam.mapping import OccupancyMap, save_map_png, save_ros_map
from agvsim.slam.offline import write_trajectory

__all__ = ["OnlineSlam", "SlamResult", "build_online_slams"]


@dataclass(frozen=True)
class SlamResult:
    """A finished online SLAM: its map, one pose per scan fed and the scores."""

    map: OccupancyMap
    stamps_s: np.ndarray  # (M,) scan times
    slam_poses: np.ndarray  # (M, 3) x, y, theta: SLAM's robot base pose at each scan
    true_poses: np.ndarray  # (M, 3) ground truth at each scan
    odom_poses: np.ndarray  # (M, 3) dead-reckoned odometry at each scan
    scores: dict  # summary.json's ``slam.<robot>`` (without ``dir``)


class OnlineSlam:
    """Graph SLAM fed by one robot's lidar, an observer of the run (agvsim.run_loop): fed the
    scan the robot has when it is made, then after every step (:meth:`on_step`)."""

    def __init__(self, sim: Simulation, robot: int, cfg: SlamBlock) -> None:
        self.sim, self.robot, self.cfg = sim, robot, cfg
        self.name = sim.robots[robot].name
        self.slot = sim.sensors.slot(robot, cfg.sensor)
        spec = sim.sensors.specs[self.slot]
        self.angles = np.asarray(spec.beam_angles_rad, np.float64)
        mount = (spec.mount_xy_m[0], spec.mount_xy_m[1], spec.mount_yaw_rad)
        base = SlamConfig() if cfg.long_corridors else SlamConfig.point_samples()
        config = SlamConfig(
            tracking=dataclasses.replace(base.tracking, resolution_m=cfg.resolution_m),
            loop=LoopConfig(min_score=cfg.loop_min_score, search_radius_m=cfg.loop_search_radius_m),
            max_range_m=cfg.max_range_m,
        )
        self.slam = GraphSlam(spec.range_max_m, np.array(mount), config)
        self.start_xy = tuple(float(v) for v in sim.robots[robot].initial_pose[:2])
        self._last_stamp = -np.inf
        self._live: OccupancyMap | None = None
        self._live_at = -np.inf
        self.true_poses: list[np.ndarray] = []
        self.odom_poses: list[np.ndarray] = []
        self.finished = False
        self._final_map: OccupancyMap | None = None
        self._result: SlamResult | None = None
        self.update()

    def on_step(self, sim: Simulation) -> None:
        self.update()

    def close(self) -> None:
        """Nothing to write: the caller reads :meth:`results` or calls :meth:`write`."""

    def update(self) -> bool:
        """Feed the robot's newest scan if there is one; True when one was fed."""
        st = self.sim.state
        stamp = float(st.scan_stamp[self.slot])
        if stamp <= self._last_stamp or self.finished:
            return False
        self._last_stamp = stamp
        n = len(self.angles)
        ranges = st.scans[self.slot, :n].astype(np.float64)
        odom = st.odom_poses[self.robot].copy()
        self.slam.update(stamp, ranges, self.angles, odom)
        self.true_poses.append(st.poses[self.robot].copy())
        self.odom_poses.append(odom)
        return True

    def live_map(self, now_s: float | None = None) -> OccupancyMap | None:
        """The current map (re-rendered at most every ``map_period_s`` of simulated time)."""
        if not self.slam.keyframes:
            return None
        t = self.sim.state.t_s if now_s is None else now_s
        if self._live is None or t - self._live_at >= self.cfg.map_period_s or t < self._live_at:
            self._live, self._live_at = self.slam.occupancy_map(), t
        return self._live

    def finish(self) -> None:
        """End the SLAM: its final optimisation runs once, however often this is called; later
        scans are ignored."""
        if not self.finished and self.slam.keyframes:
            self.slam.finish()
        self.finished = True

    def final_map(self) -> OccupancyMap:
        """The map once the SLAM is finished (finishes it; rendered once)."""
        self.finish()
        if self._final_map is None:
            self._final_map = self.slam.occupancy_map()
        return self._final_map

    def results(self) -> SlamResult:
        """Finish the SLAM and score it: the final map, the trajectories and the scores
        (trajectory error -- SLAM and, for scale, odometry alone --, map IoU against the true
        wall surface, counts). Computed once; later calls return the same result."""
        if self._result is not None:
            return self._result
        grid = self.final_map()
        stamps, est = self.slam.trajectory()
        truth = np.asarray(self.true_poses).reshape(-1, 3)
        odom = np.asarray(self.odom_poses).reshape(-1, 3)
        world = self.sim.world
        scores = {
            "sensor": self.cfg.sensor,
            "scans": len(self.true_poses),
            "keyframes": len(self.slam.keyframes),
            "submaps": len(self.slam.submaps),
            "loop_closures": len(self.slam.loop_edges),
            "trajectory_error": trajectory_error(est, truth),
            "odometry_error": trajectory_error(odom, truth),
            "map": map_iou(
                grid.probability,
                grid.origin_xy_m,
                grid.resolution_m,
                world.grid,
                world.boxes,
                self.start_xy,
            ),
        }
        self._result = SlamResult(grid, stamps, est, truth, odom, scores)
        return self._result

    def write(self, out_dir: str | Path) -> dict:
        """Write the robot's SLAM outputs under ``out_dir/slam_<robot>/``; returns the scores
        (with the file names)."""
        r = self.results()
        d = Path(out_dir) / f"slam_{self.name}"
        d.mkdir(parents=True, exist_ok=True)
        write_trajectory(d / "trajectory.txt", r.stamps_s, r.slam_poses)
        save_ros_map(r.map, d / "map.yaml")
        save_map_png(r.map, d / "map.png")
        try:
            from agvsim.viz.slam_plot import plot_slam_comparison

            plot_slam_comparison(
                r.map,
                self.sim.world.grid,
                r.slam_poses,
                r.true_poses,
                r.odom_poses,
                d / "compare.png",
                f"SLAM of {self.name}: map IoU {r.scores['map']['tolerant']['iou']:.3f}, "
                f"mean error {r.scores['trajectory_error'].get('mean_m', float('nan')):.3f} m",
            )
        except ImportError:  # plotting is optional
            pass
        return {**r.scores, "dir": d.name}


def build_online_slams(sc: Scenario, sim: Simulation) -> list[OnlineSlam]:
    """One :class:`OnlineSlam` per robot with a ``slam:`` block; a block naming a sensor the
    robot lacks (or one that is not a range fan) raises ValueError naming the field."""
    out = []
    for i, rc in enumerate(sc.robots):
        if rc.slam is None:
            continue
        names = [s.name for s in sim.robots[i].sensors]
        if rc.slam.sensor not in names:
            import difflib

            close = difflib.get_close_matches(rc.slam.sensor, names, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise ValueError(
                f"robots[{i}].slam.sensor: robot {rc.name!r} has no sensor {rc.slam.sensor!r}"
                f"{hint} (its sensors: {', '.join(names) or 'none'})"
            )
        spec = next(s for s in sim.robots[i].sensors if s.name == rc.slam.sensor)
        if spec.num_beams < 20:
            raise ValueError(
                f"robots[{i}].slam.sensor: {rc.slam.sensor!r} has {spec.num_beams} beams; SLAM "
                "needs a lidar (20 beams or more)"
            )
        out.append(OnlineSlam(sim, i, rc.slam))
    return out
