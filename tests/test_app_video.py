"""The browser app's "Record video": MP4s of the live session (top view and each onboard
camera) at 25 frames per simulated second, through the Session API and the panel, without a
browser; edits and resets while recording; a server stopped (SIGTERM) leaves finished files."""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")

from agvsim.app.session import EditError, Session  # noqa: E402
from agvsim.scenario import parse_scenario  # noqa: E402

pytestmark = pytest.mark.slow  # video encoding

ROOM = "\n".join(["#########"] + ["#.......#"] * 7 + ["#########"])  # 9 m x 9 m


def scenario() -> dict:
    return {
        "name": "room",
        "world": {"picture": ROOM},
        "robots": [
            {
                "name": "agv",
                "model": "differential",
                "pose": {"x_m": -2.0, "y_m": 0.0, "theta_deg": 0.0},
                "sensors": [
                    {"type": "lidar", "beams": 8, "range_max_m": 10.0},
                    {"type": "camera", "name": "front", "width_px": 64, "height_px": 48},
                ],
                "controller": {
                    "type": "script",
                    "steps": [{"duration_s": 100, "twist": [0.5, 0.3]}],
                },
            }
        ],
    }


def read_mp4(path: Path) -> tuple[tuple[int, int], list[np.ndarray]]:
    gen = imageio_ffmpeg.read_frames(str(path))
    meta = next(gen)
    w, h = meta["size"]
    return (w, h), [np.frombuffer(f, np.uint8).reshape(h, w, 3) for f in gen]


def test_record_step_stop_writes_the_top_view_and_the_camera(tmp_path):
    s = Session(parse_scenario(scenario()), "test", out_dir=tmp_path)
    assert s.video_status() is None
    folder = s.start_video()
    assert folder == tmp_path / "video_1"
    with pytest.raises(EditError, match="already recording"):
        s.start_video()
    s.step(50)  # 1 s at dt 0.02: frames at t = 0, 0.04, ..., 1.0
    assert s.video_status() == (folder, 26, pytest.approx(26 / 25))
    paths = s.stop_video()
    assert s.video_status() is None and s.stop_video() == []
    assert sorted(p.name for p in paths) == ["agv_front.mp4", "top.mp4"]
    # top: 720 px wide, the square map 720 px high (a multiple of 16)
    size, frames = read_mp4(folder / "top.mp4")
    assert size == (720, 720) and len(frames) == 26
    size, frames = read_mp4(folder / "agv_front.mp4")
    assert size == (64, 48) and len(frames) == 26
    rgb = s.sim.camera_frames()[0].rgb  # the camera's frame at t = 1.0 (10 Hz)
    assert np.abs(frames[-1].astype(int) - rgb.astype(int)).mean() < 8.0
    # the next recording goes to a new folder
    assert s.start_video() == tmp_path / "video_2"
    s.stop_video()
    _, frames = read_mp4(tmp_path / "video_2" / "top.mp4")
    assert len(frames) == 1  # t = 1.0 only


def test_recording_carries_on_across_edits_and_resets(tmp_path):
    s = Session(parse_scenario(scenario()), "test", out_dir=tmp_path)
    folder = s.start_video()
    s.step(25)  # t = 0.5: 13 frames
    assert s.video_status()[1] == 13
    robot = s.robot_config("agv")
    robot["body"] = {"length_m": 0.5, "width_m": 0.4}
    s.apply_robot("agv", robot)  # a new simulation, same clock: the video goes on
    s.step(25)  # t = 1.0
    assert s.video_status()[1] == 26
    s.reset()  # back to t = 0: the video goes on with the next step's frame
    s.step(10)  # t = 0.2: frames at 0.02, 0.06, ..., 0.18
    assert s.video_status()[1] == 31
    s.stop_video()
    assert len(read_mp4(folder / "top.mp4")[1]) == 31
    assert len(read_mp4(folder / "agv_front.mp4")[1]) == 31


def test_the_panel_shows_progress_and_where_the_files_went(tmp_path):
    pytest.importorskip("viser")
    from agvsim.app.server import App
    from agvsim.net import free_port

    said: list[str] = []
    session = Session(parse_scenario(scenario()), "test", out_dir=tmp_path)
    app = App(session, port=free_port(), notify=said.append)  # loops not started
    try:
        panel = app.panel
        assert not panel.record_video.disabled and panel.save_video.disabled
        panel.start_video()
        assert panel.record_video.disabled and not panel.save_video.disabled
        assert said == [f"recording video into {tmp_path / 'video_1'}"]
        session.step(25)
        panel.refresh()
        assert "recording **0.5 s** (13 frames)" in panel.video_msg.content
        assert str(tmp_path / "video_1") in panel.video_msg.content
        panel.stop_video()
        assert "saved 0.5 s (13 frames)" in panel.video_msg.content
        assert said[-1].startswith("video saved (0.5 s): ") and "top.mp4" in said[-1]
        assert not panel.record_video.disabled and panel.save_video.disabled
        # stopping the app finishes a video still being recorded
        panel.start_video()
        session.step(10)
    finally:
        app.stop()
    assert session.video_status() is None
    assert "video_2" in said[-1] and "agv_front.mp4" in said[-1]
    assert len(read_mp4(tmp_path / "video_2" / "top.mp4")[1]) == 6


def test_sigterm_to_the_server_finishes_the_video(tmp_path):
    from agvsim.net import free_port

    scen = tmp_path / "room.yaml"
    scen.write_text(yaml.safe_dump(scenario()))
    code = textwrap.dedent(
        f"""
        from agvsim.app.server import serve

        def ready(app):
            app.session.start_video()
            app.session.play()
            print("READY", flush=True)

        serve({str(scen)!r}, port={free_port()}, play=False, on_ready=ready,
              out_dir={str(tmp_path / "out")!r})
        """
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    try:
        lines = []
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            lines.append(line)
            if not line or line.startswith("READY"):
                break
        assert lines[-1].startswith("READY"), "".join(lines)
        time.sleep(2.0)  # about 2 s of video at real time
        proc.send_signal(signal.SIGTERM)
        rest, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, rest
    assert "video saved" in rest, rest
    n, secs = imageio_ffmpeg.count_frames_and_secs(tmp_path / "out" / "video_1" / "top.mp4")
    assert n >= 10 and secs == pytest.approx(n / 25, abs=0.05)
