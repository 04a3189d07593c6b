"""MP4 export: frames at the video rate of simulated time, the top view's pixels, camera
videos, and the runner's ``video=True``."""

from __future__ import annotations

import numpy as np
import pytest

imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")

from agvsim.runner import run_scenario  # noqa: E402
from agvsim.scenario import build, parse_scenario  # noqa: E402
from agvsim.viz.video import VideoRecorder  # noqa: E402

pytestmark = pytest.mark.slow  # video encoding

ROOM = {
    "name": "video room",
    "duration_s": 1.0,
    "world": {"picture": "########\n#......#\n#......#\n#......#\n########"},
    "robots": [
        {
            "name": "cam bot",
            "model": "differential",
            "pose": {"x_m": -2.0, "y_m": 0.0},
            "sensors": [
                {"type": "lidar", "beams": 30},
                {"type": "camera", "name": "front", "width_px": 64, "height_px": 48},
            ],
            "controller": {"type": "script", "steps": [{"duration_s": 5, "twist": [0.5, 0.5]}]},
        }
    ],
}


def _frames(path):
    gen = imageio_ffmpeg.read_frames(str(path))
    meta = next(gen)
    w, h = meta["size"]
    frames = [np.frombuffer(f, np.uint8).reshape(h, w, 3) for f in gen]
    return meta, frames


def test_top_video_has_one_frame_per_25th_of_a_simulated_second(tmp_path):
    from agvsim.viz.topview import TopView

    sim = build(parse_scenario(ROOM, "room"))
    # 160 px wide; the 8 x 5 m map is 100 px high, rounded up to 112 (H.264 blocks of 16)
    first = TopView(160, 112).render(sim)
    video = VideoRecorder(sim, tmp_path, fps=25, width_px=160, cameras=False, trails=False)
    for _ in range(50):  # 1 s at dt = 0.02
        sim.step()
        video.record()
    video.close()
    assert video.streams["top"].frames == 26  # t = 0, 0.04, ..., 1.0
    meta, frames = _frames(tmp_path / "top.mp4")
    assert meta["size"] == (160, 112) and len(frames) == 26
    # the first frame is the top view at t = 0 (H.264 is lossy: close, not equal)
    assert np.abs(frames[0].astype(int) - first.astype(int)).mean() < 6.0
    assert np.abs(frames[-1].astype(int) - first.astype(int)).mean() > 0.2  # it moved


def test_long_steps_repeat_frames_to_keep_time(tmp_path):
    data = dict(ROOM, dt_s=0.1)
    sim = build(parse_scenario(data, "room"))
    video = VideoRecorder(sim, tmp_path, fps=25, width_px=64, cameras=False)
    for _ in range(10):
        sim.step()
        video.record()
    video.close()
    assert video.streams["top"].frames == 26
    n, secs = imageio_ffmpeg.count_frames_and_secs(tmp_path / "top.mp4")
    assert n == 26 and secs == pytest.approx(26 / 25, abs=0.05)


def test_camera_video_holds_the_camera_frames(tmp_path):
    sim = build(parse_scenario(ROOM, "room"))
    video = VideoRecorder(sim, tmp_path, fps=10, width_px=64)
    for _ in range(25):
        sim.step()
        video.record()
    video.close()
    assert set(video.streams) == {"top", "cam_bot_front"}
    meta, frames = _frames(tmp_path / "cam_bot_front.mp4")
    assert meta["size"] == (64, 48) and len(frames) == 6  # 0.5 s at 10 fps, t = 0 included
    rgb = sim.camera_frames()[0].rgb
    assert np.abs(frames[-1].astype(int) - rgb.astype(int)).mean() < 8.0


def test_runner_writes_top_mp4_and_refuses_bad_settings(tmp_path):
    run_scenario(parse_scenario(ROOM, "room"), tmp_path, plot=False, video=True)
    assert (tmp_path / "top.mp4").stat().st_size > 1000
    assert (tmp_path / "cam_bot_front.mp4").exists()
    sim = build(parse_scenario(ROOM, "room"))
    with pytest.raises(ValueError, match="fps must be a positive number"):
        VideoRecorder(sim, tmp_path / "x", fps=0)
