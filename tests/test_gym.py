"""The Gymnasium maze-goal environments (agvsim.gym): the API contract for every registered id,
seeding, hand-worked motion, goal reward and termination, and the vector env against single
envs run by Gymnasium's own SyncVectorEnv.

Geometry used below (the default maze: 3 x 3 rooms of 3 cells, walls 1 cell, 0.5 m cells): the
maze is 13 cells = 6.5 m square, centred, so x, y in [-3.25, 3.25]. Room (i, j) (row i from the
north) has its centre at x = -3.25 + (1 + 4 j + 1.5) 0.5, y = 3.25 - (1 + 4 i + 1.5) 0.5: room 4
(1, 1) at (0, 0), room 5 (1, 2) at (2, 0). The eastern border wall's inner face is x = 2.75.
"""

from __future__ import annotations

import importlib.util
import math
import re
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import agvsim.gym
from agvsim.gym import MazeGoalEnv, MazeGoalVectorEnv
from agvsim.gym.actions import twist_limits
from agvsim.kinematics import MODELS

B = 32  # default lidar beams; beam 16 looks straight ahead (-180 deg + 16 x 11.25 deg)
IDS = sorted(i for i in gym.registry if i.startswith("agvsim/"))


def test_every_model_has_an_id_and_the_ids_are_registered():
    assert set(IDS) == set(agvsim.gym.ENV_IDS)
    fixed = {kw.get("model") for kw in agvsim.gym.ENV_IDS.values()}
    assert set(MODELS) <= fixed


@pytest.mark.parametrize("mode", ["inverse", "forward"])
@pytest.mark.parametrize("env_id", IDS)
def test_check_env_passes_for_every_registered_id(env_id, mode):
    env = gym.make(env_id, mode=mode, lidar={"beams": 8}, maze={"rows": 2, "cols": 2})
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any checker warning fails the test
        check_env(env.unwrapped)
    env.close()


@pytest.mark.parametrize("env_id", IDS)
def test_make_vec_gives_the_batched_env(env_id):
    envs = gym.make_vec(env_id, num_envs=3, lidar={"beams": 8})
    assert isinstance(envs, MazeGoalVectorEnv)
    obs, info = envs.reset(seed=1)
    assert obs.shape == (3, 8 + 7) and obs.dtype == np.float32
    assert envs.observation_space.contains(obs)
    obs, rew, term, trunc, info = envs.step(envs.action_space.sample())
    assert obs.shape == (3, 15) and rew.shape == term.shape == trunc.shape == (3,)
    assert all(envs.single_observation_space.contains(o) for o in obs)
    assert set(info) >= {"distance_m", "_distance_m", "is_success", "collided", "maze_seed"}
    envs.close()


def test_twist_limits_hand_worked():
    m = MODELS
    np.testing.assert_allclose(twist_limits(m["differential"]()), [2.0, 0.0, 8.0])  # r w / l
    np.testing.assert_allclose(twist_limits(m["mecanum"]()), [1.5, 1.5, 3.75])  # k = 0.4
    # omni3: vx needs sin(120 deg) of a wheel, vy cos(0) = 1, omega r w / R
    np.testing.assert_allclose(
        twist_limits(m["omni3"]()), [1.5 / math.sin(2 * math.pi / 3), 1.5, 7.5]
    )
    # tricycle: omega r w sin(90 deg) / L; ackermann: vx tan(35 deg) / L
    np.testing.assert_allclose(twist_limits(m["tricycle"]()), [2.0, 0.0, 4.0])
    np.testing.assert_allclose(
        twist_limits(m["ackermann"]()), [2.0, 0.0, 2.0 * math.tan(math.radians(35)) / 0.5]
    )


def _rollout(env: MazeGoalEnv, seed: int, steps: int) -> list:
    out = [env.reset(seed=seed)]
    env.action_space.seed(seed)
    for _ in range(steps):
        out.append(env.step(env.action_space.sample()))
    return out


def test_same_seed_same_bits_other_seed_other_maze():
    a = _rollout(MazeGoalEnv(model="ackermann", mode="forward"), 7, 40)
    b = _rollout(MazeGoalEnv(model="ackermann", mode="forward"), 7, 40)
    for ra, rb in zip(a, b, strict=True):
        assert ra[0].tobytes() == rb[0].tobytes()
        assert ra[1:] == rb[1:]
    env = MazeGoalEnv()
    seeds = {env.reset(seed=s)[1]["maze_seed"] for s in range(5)}
    assert len(seeds) == 5
    # a reset without a seed goes on with the env's generator: a new episode
    env.reset(seed=3)
    assert env.reset()[1]["maze_seed"] != env.reset(seed=3)[1]["maze_seed"]


def test_room_centres_hand_worked():
    task = MazeGoalEnv().task
    assert task.room_centre(0, 4) == (0.0, 0.0)
    assert task.room_centre(0, 5) == (2.0, 0.0)
    assert task.room_centre(0, 0) == (-2.0, 2.0)
    assert task.sim.world.grid.extent_m == (-3.25, 3.25, -3.25, 3.25)


# model, mode, action, displacement in the robot frame after one env step (0.1 s):
# differential / tricycle / ackermann top speed r w = 0.1 x 20 = 2 m/s -> 0.2 m;
# mecanum 0.05 x 30 = 1.5 m/s -> 0.15 m (forward, or sideways with vy);
# omni3 vx 1.5 / sin(120 deg) = 1.7320508 m/s -> 0.17320508 m
FORWARD = [
    ("differential", "inverse", [1.0, 0.0], (0.2, 0.0)),
    ("differential", "forward", [1.0, 1.0], (0.2, 0.0)),
    ("tricycle", "inverse", [1.0, 0.0], (0.2, 0.0)),
    ("tricycle", "forward", [1.0, 0.0], (0.2, 0.0)),
    ("ackermann", "inverse", [1.0, 0.0], (0.2, 0.0)),
    ("ackermann", "forward", [1.0, 1.0, 0.0], (0.2, 0.0)),
    ("mecanum", "forward", [1.0, 1.0, 1.0, 1.0], (0.15, 0.0)),
    ("mecanum", "inverse", [0.0, 1.0, 0.0], (0.0, 0.15)),
    ("omni3", "inverse", [1.0, 0.0, 0.0], (0.1 * math.sqrt(3.0), 0.0)),
]


@pytest.mark.parametrize("model,mode,action,moved", FORWARD)
def test_forward_action_moves_the_hand_worked_distance(model, mode, action, moved):
    env = MazeGoalEnv(model=model, mode=mode)
    offset = env.sim.robots[0].body_offset_x_m  # car-like: body centre 0.25 m ahead of P
    # room 5, facing the eastern border wall (inner face x = 2.75), body centre at 2.0
    start = (2.0 - offset, 0.0, 0.0)
    obs0, _ = env.reset(seed=0, options={"start_pose": start, "goal_xy": (-2.0, 2.0)})
    obs1, _, term, trunc, info = env.step(np.array(action, dtype=np.float32))
    pose = env.sim.state.poses[0]
    np.testing.assert_allclose(pose, [start[0] + moved[0], moved[1], 0.0], atol=1e-12)
    assert not (term or trunc or info["collided"])
    # the lidar sits at the body centre; its front beam reads 0.75 m, then 0.75 - dx (of 4 m)
    assert obs0[B // 2] == pytest.approx(0.75 / 4.0, abs=1e-7)
    assert obs1[B // 2] == pytest.approx((0.75 - moved[0]) / 4.0, abs=1e-7)
    # the twist part of the observation: the executed twist over the model's limits
    lim = twist_limits(env.task.model)
    expect = [moved[0] / 0.1 / lim[0], moved[1] / 0.1 / lim[1] if lim[1] else 0.0, 0.0]
    np.testing.assert_allclose(obs1[B + 3 : B + 6], expect, atol=1e-6)


def test_forward_at_any_heading_moves_along_the_heading():
    env = MazeGoalEnv()
    for th in (0.7, -2.0, math.pi / 2):
        env.reset(seed=0, options={"start_pose": (0.0, 0.0, th)})
        env.step(np.array([0.5, 0.0], dtype=np.float32))  # 1 m/s for 0.1 s
        np.testing.assert_allclose(
            env.sim.state.poses[0], [0.1 * math.cos(th), 0.1 * math.sin(th), th], atol=1e-12
        )


def test_reaching_a_goal_right_in_front_rewards_and_terminates():
    env = MazeGoalEnv()  # goal radius 0.3 m; rewards 1/m progress, 10 success, 0.01 per step
    obs, info = env.reset(seed=0, options={"start_pose": (0.0, 0.0, 0.0), "goal_xy": (0.6, 0.0)})
    assert info["distance_m"] == pytest.approx(0.6)
    # the goal straight ahead: distance 0.6 / diagonal 6.5 sqrt 2, bearing sin 0, cos 1
    np.testing.assert_allclose(obs[B : B + 3], [0.6 / (6.5 * math.sqrt(2)), 0.0, 1.0], atol=1e-7)
    obs, r, term, trunc, info = env.step(np.array([1.0, 0.0], dtype=np.float32))
    assert r == pytest.approx(0.2 - 0.01, abs=1e-12) and not term and not info["is_success"]
    assert info["distance_m"] == pytest.approx(0.4, abs=1e-12)
    obs, r, term, trunc, info = env.step(np.array([1.0, 0.0], dtype=np.float32))
    assert r == pytest.approx(0.2 + 10.0 - 0.01, abs=1e-12)
    assert term and not trunc and info["is_success"]


def test_bumping_a_wall_is_penalised():
    env = MazeGoalEnv()
    _, info = env.reset(seed=0, options={"start_pose": (2.0, 0.0, 0.0), "goal_xy": (0.0, 0.0)})
    d, bumps = info["distance_m"], []
    for _ in range(3):  # body front 2.3 -> 2.5 -> 2.7 -> would cross the wall at 2.75
        _, r, term, _, info = env.step(np.array([1.0, 0.0], dtype=np.float32))
        bumps.append(info["collided"])
        assert r == pytest.approx((d - info["distance_m"]) - 0.1 * info["collided"] - 0.01)
        d = info["distance_m"]
    assert bumps == [False, False, True]
    # a kinematics step (0.05 s, 0.1 m) would put the front at 2.8: the body stays where it was
    assert env.sim.state.poses[0, 0] == pytest.approx(2.4, abs=1e-12)


def test_truncated_after_max_steps():
    env = MazeGoalEnv(max_steps=3)
    env.reset(seed=2)
    flags = [env.step(np.zeros(2, np.float32))[3] for _ in range(3)]
    assert flags == [False, False, True]


def test_rgb_array_shows_the_maze_and_the_goal():
    env = MazeGoalEnv(render_mode="rgb_array", render_width_px=130)  # 20 px per metre
    env.reset(seed=0, options={"start_pose": (0.0, 0.0, 0.0), "goal_xy": (2.0, 2.0)})
    img = env.render()
    assert img.shape == (130, 130, 3) and img.dtype == np.uint8
    # the goal (2, 2) is pixel col (2 + 3.25) 20 = 105, row (3.25 - 2) 20 = 25: green
    assert tuple(img[25, 105]) == agvsim.gym.render.GOAL_RGB
    assert tuple(img[0, 0]) != agvsim.gym.render.GOAL_RGB  # the border wall
    assert MazeGoalEnv().render() is None


@pytest.mark.parametrize(
    "kwargs,words",
    [
        ({"model": "diferential"}, ["model", "did you mean 'differential'"]),
        ({"mode": "sideways"}, ["mode", "sideways"]),
        ({"lidar": {"beams": 0}}, ["lidar.beams", "greater than or equal to 1"]),
        ({"lidar": {"rate_hz": 5}}, ["lidar.rate_hz", "once per env step"]),
        ({"params": {"wheel_radius": 0.1}}, ["params", "'wheel_radius'", "wheel_radius_m"]),
        ({"maze": {"rows": 1, "cols": 1}}, ["maze", "at least 2 rooms"]),
        ({"maze": {"seed": 3}}, ["maze.seed"]),
        ({"body": {"length_m": 2.0}}, ["body", "cannot turn", "corridor_cells"]),
        ({"action_repeat": 0}, ["action_repeat", ">= 1"]),
        ({"goal_radius_m": -1}, ["goal_radius_m"]),
        ({"rewards": {"succes": 1.0}}, ["rewards", "'succes'", "success"]),
        ({"render_mode": "human"}, ["render_mode", "'human'", "rgb_array"]),
    ],
)
def test_bad_arguments_get_a_clear_error(kwargs, words):
    with pytest.raises(ValueError) as err:
        MazeGoalEnv(**kwargs)
    for w in words:
        assert w in str(err.value), str(err.value)


def test_bad_actions_and_options_get_a_clear_error():
    env = MazeGoalEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(2,\), got shape \(3,\)"):
        env.step(np.zeros(3))
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([np.nan, 0.0]))
    with pytest.raises(ValueError, match="start_pose .* wall"):
        env.reset(options={"start_pose": (2.6, 0.0, 0.0)})
    with pytest.raises(ValueError, match="goal_xy .* wall"):
        env.reset(options={"goal_xy": (3.0, 0.0)})
    with pytest.raises(ValueError, match="unknown key"):
        env.reset(options={"goal": (0.0, 0.0)})
    venv = MazeGoalVectorEnv(2)
    venv.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(2, 2\)"):
        venv.step(np.zeros(2))


# actions that never move a body out of place: turning on the spot (the body fits its room at
# any heading) or, for the car-like ackermann, only steering
STILL_BODY = [
    ("differential", "inverse", [0.0, 1.0]),  # omega
    ("mecanum", "forward", [-1.0, 1.0, -1.0, 1.0]),  # wheels of a pure rotation
    ("ackermann", "forward", [0.0, 0.0, 1.0]),  # steering angle only
]


@pytest.mark.parametrize("model,mode,pattern", STILL_BODY)
def test_vector_env_equals_single_envs_with_autoreset(model, mode, pattern):
    """World k of the vector env runs as a MazeGoalEnv seeded seed + k under Gymnasium's own
    SyncVectorEnv (next-step autoreset). A goal radius of 2.1 m ends episodes whose goal room
    neighbours the start room at once (room centres 2 m apart); the others are truncated."""
    n, kw = 5, {"model": model, "mode": mode, "max_steps": 6, "goal_radius_m": 2.1}
    vec = MazeGoalVectorEnv(n, **kw)
    ref = gym.vector.SyncVectorEnv([lambda: MazeGoalEnv(**kw) for _ in range(n)])
    assert ref.metadata["autoreset_mode"] == vec.metadata["autoreset_mode"]
    (o1, i1), (o2, i2) = vec.reset(seed=11), ref.reset(seed=11)
    np.testing.assert_array_equal(i1["maze_seed"], i2["maze_seed"])
    np.testing.assert_allclose(o1, o2, atol=1e-6)
    ends = np.zeros(2, int)
    for t in range(30):
        a = (np.sin(0.3 * t + np.arange(n))[:, None] * np.array(pattern)).astype(np.float32)
        o1, r1, te1, tr1, i1 = vec.step(a)
        o2, r2, te2, tr2, i2 = ref.step(a)
        assert not i1["collided"].any()  # the precondition of equality (see docs/gym.md)
        np.testing.assert_allclose(o1, o2, atol=1e-6, err_msg=f"step {t}")
        np.testing.assert_allclose(r1, r2, atol=1e-9)
        np.testing.assert_array_equal(te1, te2)
        np.testing.assert_array_equal(tr1, tr2)
        np.testing.assert_array_equal(i1["maze_seed"], i2["maze_seed"])
        ends += [te1.sum(), tr1.sum()]
    assert ends.min() > 0, f"the run must see both endings, got {ends}"
    assert np.abs(o1[:, B + 3 :]).max() > 0.1  # the twist or steering part did change


def test_vector_worlds_are_walled_apart():
    """Each world's maze sits in its own tile, with its own border: no free cell of one tile
    touches another's."""
    vec = MazeGoalVectorEnv(5)
    vec.reset(seed=0)
    occ = vec.sim.world.grid.occupied
    t = vec.task
    assert occ.shape == (2 * 13, 3 * 13)  # 5 worlds on a 3 x 2 lattice, the 6th tile solid
    assert occ[13:, 26:].all()
    for k in range(5):
        r0, c0 = (k // 3) * 13, (k % 3) * 13
        tile = occ[r0 : r0 + 13, c0 : c0 + 13]
        assert tile[0].all() and tile[-1].all() and tile[:, 0].all() and tile[:, -1].all()
        x0, x1, y0, y1 = t.tile_extent(k)
        gx, gy = t.goals[k]
        assert x0 < gx < x1 and y0 < gy < y1
        px, py, _ = vec.sim.state.poses[k]
        assert x0 < px < x1 and y0 < py < y1


def test_vector_reset_seeds_worlds_like_single_envs():
    vec = MazeGoalVectorEnv(3)
    _, info = vec.reset(seed=[4, None, 9])
    assert info["maze_seed"][0] == MazeGoalEnv().reset(seed=4)[1]["maze_seed"]
    assert info["maze_seed"][2] == MazeGoalEnv().reset(seed=9)[1]["maze_seed"]
    with pytest.raises(ValueError, match="2 seeds for 3 worlds"):
        vec.reset(seed=[1, 2])


ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("k", [0, 1])
def test_docs_gym_examples_run(k, monkeypatch):
    text = (ROOT / "docs" / "gym.md").read_text(encoding="utf-8")
    blocks = re.findall(r"^```python\n(.*?)^```", text, re.S | re.M)
    assert len(blocks) == 2
    monkeypatch.chdir(ROOT)
    exec(compile(blocks[k], f"docs/gym.md block {k}", "exec"), {"__name__": "__doc__"})


def test_example_script_runs(tmp_path, capsys):
    spec = importlib.util.spec_from_file_location("gym_random", ROOT / "examples" / "gym_random.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.main("omni3", "forward", steps=30, frame=str(tmp_path / "f.png"))
    out = capsys.readouterr().out
    assert "omni3 (forward): observation (39,), action (3,)" in out
    assert "observations (16, 39)" in out
    assert (tmp_path / "f.png").stat().st_size > 0


def test_vector_render_gives_one_frame_per_world():
    vec = MazeGoalVectorEnv(3, render_mode="rgb_array", render_width_px=130)  # 20 px per m
    vec.reset(seed=0)
    frames = vec.render()
    assert isinstance(frames, tuple) and len(frames) == 3
    whole = vec.render_all()
    assert whole.shape == (2 * 130, 2 * 130, 3)  # 3 worlds on a 2 x 2 lattice
    t = vec.task
    for k, f in enumerate(frames):
        assert f.shape == (130, 130, 3) and f.dtype == np.uint8
        x0, _, _, y1 = t.tile_extent(k)
        gx, gy = t.goals[k]
        col, row = int((gx - x0) * 20), int((y1 - gy) * 20)
        assert tuple(f[row, col]) == agvsim.gym.render.GOAL_RGB
