"""The PettingZoo pursuit env (agvsim.gym.pursuit_v0): PettingZoo's parallel API test, seeding,
a hand-worked capture and the thesis behaviours driving the robots that do not learn."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

from agvsim.gym import pursuit_v0

B = 32  # default lidar beams


@pytest.mark.parametrize("learners", [("red", "blue"), ("red",), ("blue",)])
def test_parallel_api_test_passes(learners):
    env = pursuit_v0.parallel_env(learners=learners)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # "live agent was not given ..." and the like fail
        parallel_api_test(env, num_cycles=200)
    assert env.possible_agents == list(learners)


def test_same_seed_same_bits():
    def run(seed):
        env = pursuit_v0.parallel_env()
        obs, _ = env.reset(seed=seed)
        out = [obs]
        rng = np.random.default_rng(seed)
        for _ in range(30):
            obs, rew, *_ = env.step({a: rng.uniform(-1, 1, 2) for a in env.agents})
            out.append((obs, rew))
        return out

    a, b = run(3), run(3)
    for x, y in zip(a[1:], b[1:], strict=True):
        for agent in ("red", "blue"):
            assert x[0][agent].tobytes() == y[0][agent].tobytes()
            assert x[1][agent] == y[1][agent]
    assert a[0]["red"].tobytes() != run(4)[0]["red"].tobytes()


def test_capture_hand_worked():
    """Red at the origin drives east at its top speed of 1 m/s (0.05 m per 0.05 s kinematics
    step) at blue, 1.52 m ahead and standing still; the capture radius is 0.8 m between body
    centres, so it comes after 15 kinematics steps (0.75 m, gap 0.77 m; after 14 the gap is
    0.82 m): during env step 8, at t = 0.75 s."""
    env = pursuit_v0.parallel_env()
    poses = {"red": (0.0, 0.0, 0.0), "blue": (1.52, 0.0, 0.0)}
    obs, info = env.reset(seed=0, options={"poses": poses})
    # red sees blue straight ahead: distance 1.52 / (18 sqrt 2), bearing 0, same heading
    np.testing.assert_allclose(
        obs["red"][B : B + 5], [1.52 / (18 * math.sqrt(2)), 0.0, 1.0, 0.0, 1.0], atol=1e-7
    )
    go = {"red": np.array([1.0, 0.0]), "blue": np.zeros(2)}
    for k in range(1, 9):
        obs, rew, term, trunc, info = env.step(go)
        if k < 8:
            assert not term["red"] and env.agents == ["red", "blue"]
            assert rew["red"] == pytest.approx(0.1, abs=1e-9)  # the gap closed by 0.1 m
            assert rew["blue"] == pytest.approx(-0.1, abs=1e-9)
    assert term == {"red": True, "blue": True} and trunc == {"red": False, "blue": False}
    assert info["red"]["captured"] and info["red"]["t_s"] == pytest.approx(0.75)
    assert info["red"]["distance_m"] == pytest.approx(0.77, abs=1e-9)
    assert rew["red"] == pytest.approx(0.05 + 10.0, abs=1e-9)  # 1 kinematics step, + capture
    assert rew["blue"] == pytest.approx(-(0.05 + 10.0), abs=1e-9)
    assert env.agents == []
    with pytest.raises(RuntimeError, match="reset"):
        env.step(go)


def test_truncated_after_max_cycles():
    env = pursuit_v0.parallel_env(max_cycles=3)
    env.reset(seed=1)
    still = {"red": np.zeros(2), "blue": np.zeros(2)}
    flags = [env.step(still)[3]["red"] for _ in range(3)]
    assert flags == [False, False, True] and env.agents == []


def test_the_thesis_evader_drives_blue_when_only_red_learns():
    env = pursuit_v0.parallel_env(learners=["red"])
    obs, _ = env.reset(seed=0, options={"thesis_start": True})
    assert set(obs) == {"red"}
    start = env.sim.state.poses.copy()
    np.testing.assert_allclose(start[1], [5.0, 4.0, math.pi])  # the thesis's start of blue
    for _ in range(20):
        env.step({"red": np.zeros(2)})
    moved = env.sim.state.poses - start
    assert np.hypot(*moved[0, :2]) == 0.0  # red was told to stand still
    assert np.hypot(*moved[1, :2]) > 0.5  # blue wandered off on its own (0.4 m/s for 2 s)


def test_bad_arguments_get_a_clear_error():
    with pytest.raises(ValueError, match="learners"):
        pursuit_v0.parallel_env(learners=["green"])
    with pytest.raises(ValueError, match="beams"):
        pursuit_v0.parallel_env(beams=0)
    with pytest.raises(ValueError, match="min_start_distance_m"):
        pursuit_v0.parallel_env(min_start_distance_m=30.0)
    env = pursuit_v0.parallel_env()
    with pytest.raises(ValueError, match="poses .* wall"):
        env.reset(options={"poses": {"red": (9.0, 0.0, 0.0), "blue": (0.0, 0.0, 0.0)}})
    with pytest.raises(ValueError, match="'red' and 'blue'"):
        env.reset(options={"poses": {"red": (0.0, 0.0, 0.0)}})
    env.reset(seed=0)
    with pytest.raises(ValueError, match="no action for live agent"):
        env.step({"red": np.zeros(2)})
    with pytest.raises(ValueError, match=r"shape \(2,\)"):
        env.step({"red": np.zeros(3), "blue": np.zeros(2)})


def test_rgb_array_frame():
    env = pursuit_v0.parallel_env(render_mode="rgb_array", render_width_px=200)
    env.reset(seed=0)
    img = env.render()
    assert img.shape == (200, 200, 3) and img.dtype == np.uint8
