"""``pursuit_v0``: the thesis's pursuit case study (section 7.1) as a PettingZoo ``ParallelEnv``.

Two differential drives in a 20 x 20 m walled square (free floor x, y in [-9, 9] m), as in
``scenarios/thesis_pursuit.yaml``: ``red`` pursues ``blue``. Red is faster (1 m/s) but turns
slower (1 rad/s); blue turns faster (2.5 rad/s) at 0.8 m/s. The episode ends (every agent
terminated) when their body centres come within ``capture_radius_m`` (0.8 m, the thesis's
capture metric, checked after every kinematics step), or is truncated after ``max_cycles``.

    from agvsim.gym import pursuit_v0
    env = pursuit_v0.parallel_env()                 # both robots learn
    env = pursuit_v0.parallel_env(learners=["red"])  # blue runs the thesis's evader

``learners`` lists the agents the env exposes; any other robot is driven by the thesis's own
behaviour (``agvsim.control.pursuit``: ``Pursuer`` for red, ``Evader`` for blue).

Observation of an agent (float32 Box, ``B = beams``): lidar ranges / ``range_max_m`` (B values in
[0, 1], no return reads 1); the other robot's distance / the square's diagonal, the sin and cos
of its bearing and of its heading relative to ours (5 values); our executed (vx, omega) divided by
our top speed and turn rate (2 values, clipped to [-1, 1]). Action: ``[-1, 1]^2`` = (vx, omega)
scaled by the agent's top speed and turn rate.

Reward: red gets ``progress_per_m`` x (metres the gap closed) + ``capture`` on capture; blue
gets the negative of that (zero-sum); each loses ``collision`` for a step in which it bumped.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from agvsim.behaviours import EvadeConfig, PursueConfig, build_evade, build_pursue
from agvsim.control.api import ControllerContext
from agvsim.gym.actions import check_actions
from agvsim.gym.render import check_render_mode
from agvsim.metrics.capture import Capture
from agvsim.scenario import ScenarioError, build_grid, parse_scenario, robot_spec
from agvsim.sim.engine import Binding, Simulation
from agvsim.sim.spec import World

AGENTS = ("red", "blue")
SIDE_CELLS = 20  # the square, walls included, 1 m cells
THESIS_START = {"red": (-6.0, -6.0, math.pi / 2), "blue": (5.0, 4.0, math.pi)}
SPEEDS = {"red": (1.0, 1.0), "blue": (0.8, 2.5)}  # top speed m/s, turn rate rad/s (thesis)


def parallel_env(**kwargs: Any) -> PursuitParallelEnv:
    """The pursuit env; keyword arguments as :class:`PursuitParallelEnv`."""
    return PursuitParallelEnv(**kwargs)


class _Pilot:
    """A batch controller handing the simulation the learners' pending twists."""

    def __init__(self, k: int):
        self.command = np.zeros((k, 3))

    def reset(self, k: int, rng: np.random.Generator) -> None:
        self.command[:] = 0.0

    def step(self, obs: object) -> np.ndarray:
        return self.command


class PursuitParallelEnv(ParallelEnv):
    """See the module docstring. Keyword arguments: ``learners`` (agents exposed, default
    both), ``beams`` (lidar beams, 32), ``range_max_m`` (10), ``capture_radius_m`` (0.8),
    ``max_cycles`` (env steps, 600 = 60 s), ``dt_s`` (0.05), ``action_repeat`` (2),
    ``min_start_distance_m`` (4: random starts at least this far apart), ``progress_per_m``
    (1), ``capture`` (10), ``collision`` (0.1), ``render_mode`` (None or ``"rgb_array"``),
    ``render_width_px``.

    ``reset(seed=s)`` draws both start poses from ``s`` (uniform on the floor, apart by at
    least ``min_start_distance_m``); ``options={"thesis_start": True}`` uses the thesis's
    poses instead, and ``options={"poses": {"red": (x, y, theta), "blue": (...)}}`` (m, m,
    rad) any poses on the floor. Other option keys are ignored (PettingZoo's API test passes
    made-up ones).
    """

    metadata = {
        "name": "agvsim_pursuit_v0",
        "render_modes": ["rgb_array"],
        "render_fps": 10,
        "is_parallelizable": True,
    }

    def __init__(
        self,
        learners: Sequence[str] = AGENTS,
        beams: int = 32,
        range_max_m: float = 10.0,
        capture_radius_m: float = 0.8,
        max_cycles: int = 600,
        dt_s: float = 0.05,
        action_repeat: int = 2,
        min_start_distance_m: float = 4.0,
        progress_per_m: float = 1.0,
        capture: float = 10.0,
        collision: float = 0.1,
        render_mode: str | None = None,
        render_width_px: int = 400,
    ):
        learners = [str(a) for a in learners]
        bad = [a for a in learners if a not in AGENTS]
        if bad or not learners or len(set(learners)) != len(learners):
            raise ValueError(
                f"learners: {learners!r} must name one or both of {list(AGENTS)}, once each"
            )
        self.possible_agents = [a for a in AGENTS if a in learners]
        self.agents: list[str] = []
        self.render_mode = check_render_mode(render_mode, ["rgb_array"])
        self.render_width_px = int(render_width_px)
        for name, v, low in (
            ("capture_radius_m", capture_radius_m, 0.0),
            ("min_start_distance_m", min_start_distance_m, 0.0),
        ):
            if not (isinstance(v, int | float) and math.isfinite(v) and v > low):
                raise ValueError(f"{name}: must be a number > {low:g}, got {v!r}")
        for name, v in (("max_cycles", max_cycles), ("action_repeat", action_repeat)):
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{name}: must be an integer >= 1, got {v!r}")
        if not capture_radius_m < min_start_distance_m <= 15.0 or min_start_distance_m < 1.0:
            raise ValueError(
                f"min_start_distance_m: {min_start_distance_m} m must be at least 1 m (bodies "
                f"apart), above capture_radius_m ({capture_radius_m} m) and at most 15 m (the "
                "16 m square the starts are drawn from)"
            )
        self.max_cycles, self.action_repeat = max_cycles, action_repeat
        self.capture_radius_m, self.min_start_m = float(capture_radius_m), min_start_distance_m
        self.weights = (float(progress_per_m), float(capture), float(collision))
        self.sim, self._beams, self._range_max = self._build(beams, range_max_m, dt_s)
        self._lidar_slot = {a: self.sim.sensors.slot(i, "lidar") for i, a in enumerate(AGENTS)}
        self._scale = {a: np.array([SPEEDS[a][0], SPEEDS[a][1]]) for a in AGENTS}
        self._diag = math.hypot(SIDE_CELLS - 2, SIDE_CELLS - 2)
        self._rng = np.random.default_rng()
        self._cycles, self._gap = 0, 0.0

    # ------------------------------------------------------------------ set-up
    def _build(self, beams: int, range_max_m: float, dt_s: float) -> tuple[Simulation, int, float]:
        """The world and robots through the scenario machinery (the thesis scenario's
        robots), the learners driven by one batch pilot, the others by the thesis behaviours."""
        picture = "\n".join(
            "#" * SIDE_CELLS if r in (0, SIDE_CELLS - 1) else "#" + "." * (SIDE_CELLS - 2) + "#"
            for r in range(SIDE_CELLS)
        )
        scan_hz = 1.0 / (dt_s * self.action_repeat) if dt_s > 0 else 1.0
        robot = {
            "model": "differential",
            "params": {"wheel_radius_m": 0.1, "half_track_m": 0.25},
            "body": {"length_m": 0.6, "width_m": 0.45},
            "sensors": [
                {"type": "rangers", "range_max_m": 2.0, "noise_std_m": 0.01},
                {"type": "lidar", "beams": beams, "range_max_m": range_max_m, "rate_hz": scan_hz},
            ],
            "odometry": {"wheel_noise_rel": 0.0},
        }
        data = {
            "dt_s": dt_s,
            "world": {"picture": picture, "cell_size_m": 1.0},
            "robots": [
                {
                    **robot,
                    "name": "red",
                    "color": "#d62728",
                    "knows": ["blue"],
                    "pose": {"x_m": -6.0, "y_m": -6.0, "theta_deg": 90.0},
                },
                {
                    **robot,
                    "name": "blue",
                    "color": "#1f77b4",
                    "knows": ["red"],
                    "pose": {"x_m": 5.0, "y_m": 4.0, "theta_deg": 180.0},
                },
            ],
        }
        try:
            sc = parse_scenario(data, "pursuit_v0")
            grid = build_grid(sc.world, sc._base_dir)
            specs = [robot_spec(rc, rc.name, sc.dt_s) for rc in sc.robots]
        except ScenarioError as err:
            problems = [
                p.replace("robots[0].sensors[1].lidar.", "").replace("robots[0].sensors[1].", "")
                for p in err.problems
            ]
            raise ValueError("pursuit_v0: " + "; ".join(problems)) from None
        learners = tuple(i for i, a in enumerate(AGENTS) if a in self.possible_agents)
        self._pilot = _Pilot(len(learners))
        bindings = [Binding(self._pilot, learners, batch=True)]
        for i, a in enumerate(AGENTS):
            if a in self.possible_agents:
                continue
            ctx = ControllerContext(i, specs[i], grid, AGENTS)
            ctrl: Any = (
                build_pursue(PursueConfig.model_validate({"type": "pursue", "target": "blue"}), ctx)
                if a == "red"
                else build_evade(
                    EvadeConfig.model_validate({"type": "evade", "pursuer": "red"}), ctx
                )
            )
            bindings.append(Binding(ctrl, (i,)))
        sim = Simulation(
            World(grid), specs, bindings, dt_s=sc.dt_s, knows={"red": ["blue"], "blue": ["red"]}
        )
        lidar = specs[0].sensors[1]
        return sim, lidar.num_beams, lidar.range_max_m

    @functools.cache  # noqa: B019 - one space object per agent, as asked
    def observation_space(self, agent: str) -> spaces.Box:
        b = self._beams
        low = np.concatenate([np.zeros(b + 1), -np.ones(6)]).astype(np.float32)
        return spaces.Box(low, np.ones(b + 7, np.float32), dtype=np.float32)

    @functools.cache  # noqa: B019
    def action_space(self, agent: str) -> spaces.Box:
        return spaces.Box(-np.ones(2, np.float32), np.ones(2, np.float32), dtype=np.float32)

    # ------------------------------------------------------------------ episodes
    def _starts(self, rng: np.random.Generator) -> dict[str, tuple[float, float, float]]:
        """Random start poses on the floor, ``min_start_distance_m`` apart, 1 m off walls."""
        lim = (SIDE_CELLS - 2) / 2.0 - 1.0
        while True:
            xy = rng.uniform(-lim, lim, size=(2, 2))
            th = rng.uniform(-math.pi, math.pi, size=2)
            if math.hypot(*(xy[0] - xy[1])) >= self.min_start_m:
                return {
                    a: (float(xy[i, 0]), float(xy[i, 1]), float(th[i]))
                    for i, a in enumerate(AGENTS)
                }

    @staticmethod
    def _given_poses(poses: object) -> dict[str, tuple[float, float, float]]:
        """``{"red": (x, y, theta), "blue": (...)}`` checked: m, m, rad, world frame."""
        out = {}
        for a in AGENTS:
            try:
                v = np.asarray(poses[a], dtype=np.float64)  # type: ignore[index]
            except (TypeError, KeyError, ValueError, IndexError):
                v = np.zeros(0)
            if v.shape != (3,) or not np.all(np.isfinite(v)):
                raise ValueError(
                    f"reset options: poses must map 'red' and 'blue' to (x m, y m, theta rad), "
                    f"got {poses!r}"
                )
            out[a] = (float(v[0]), float(v[1]), float(v[2]))
        return out

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict]]:
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        starts = self._starts(self._rng)
        opts = options or {}
        if opts.get("thesis_start"):
            starts = dict(THESIS_START)
        if "poses" in opts:
            starts = self._given_poses(opts["poses"])
        sim = self.sim
        for i, a in enumerate(AGENTS):
            sim.robots[i] = replace(sim.robots[i], initial_pose=starts[a])
        sim.reset(seed=int(self._rng.integers(2**31)))
        fp = sim.footprints(sim.state.poses)
        if sim.collider.hit_walls(fp).any() or len(sim.collider.overlapping_pairs(fp)):
            raise ValueError(
                f"reset options: poses {starts} put a body in a wall or the two bodies on "
                "each other; the floor spans x, y in [-9, 9] m"
            )
        self._capture = Capture(0, 1, self.capture_radius_m)
        self._capture.update(sim)
        self.agents = list(self.possible_agents)
        self._cycles = 0
        self._gap = self._distance()
        return self._observations(), {a: self._info(a, False) for a in self.agents}

    def step(self, actions: dict[str, Any]):
        if not self.agents:
            raise RuntimeError("pursuit_v0: step() after the episode ended; call reset()")
        missing = [a for a in self.agents if a not in actions]
        if missing:
            raise ValueError(f"pursuit_v0.step: no action for live agent(s) {missing}")
        for k, a in enumerate(self.possible_agents):
            act = check_actions(actions[a], (2,), f"pursuit_v0.step action of {a!r}")
            vx, omega = np.clip(act, -1.0, 1.0) * self._scale[a]
            self._pilot.command[k] = (vx, 0.0, omega)
        sim = self.sim
        bumped = np.zeros(sim.n, dtype=bool)
        captured = False
        for _ in range(self.action_repeat):
            sim.step()
            bumped |= sim.state.bump
            captured = self._capture.update(sim)
            if captured:
                break
        self._cycles += 1
        gap = self._distance()
        progress, bonus, penalty = self.weights
        red = progress * (self._gap - gap) + bonus * captured
        self._gap = gap
        rewards = {
            a: (red if a == "red" else -red) - penalty * bool(bumped[AGENTS.index(a)])
            for a in self.agents
        }
        truncated = self._cycles >= self.max_cycles and not captured
        obs = self._observations()
        terms = dict.fromkeys(self.agents, bool(captured))
        truncs = dict.fromkeys(self.agents, bool(truncated))
        infos = {a: self._info(a, bool(bumped[AGENTS.index(a)])) for a in self.agents}
        if captured or truncated:
            self.agents = []
        return obs, rewards, terms, truncs, infos

    # ------------------------------------------------------------------ observations
    def _distance(self) -> float:
        c = self.sim.footprints(self.sim.state.poses)[:, :2]
        return float(np.hypot(*(c[0] - c[1])))

    def _info(self, agent: str, bumped: bool) -> dict[str, Any]:
        return {
            "distance_m": self._gap,
            "captured": self._capture.captured,
            "collided": bumped,
            "t_s": float(self.sim.state.t_s),
        }

    def _observations(self) -> dict[str, np.ndarray]:
        st, b = self.sim.state, self._beams
        out = {}
        for a in self.agents:
            i = AGENTS.index(a)
            j = 1 - i
            x, y, th = st.poses[i]
            dx, dy = st.poses[j, 0] - x, st.poses[j, 1] - y
            d = math.hypot(dx, dy)
            bearing = math.atan2(dy, dx) - th
            rel = st.poses[j, 2] - th
            ranges = st.scans[self._lidar_slot[a], :b] / self._range_max
            o = np.empty(b + 7)
            o[:b] = np.clip(ranges, 0.0, 1.0)  # +inf (no return) -> 1
            o[b] = min(d / self._diag, 1.0)
            o[b + 1 : b + 5] = (math.sin(bearing), math.cos(bearing), math.sin(rel), math.cos(rel))
            o[b + 5 :] = np.clip(st.twists[i, [0, 2]] / self._scale[a], -1.0, 1.0)
            out[a] = o.astype(np.float32)
        return out

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        from agvsim.viz.topview import render_top

        return render_top(self.sim, self.render_width_px)

    def close(self) -> None:
        pass
