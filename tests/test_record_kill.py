"""A run killed with SIGKILL leaves a readable run.mcap holding everything up to within a
second (simulated) of the kill; Ctrl-C (SIGINT) closes it properly."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import yaml

pytest.importorskip("rosbags")
from rosbags.highlevel import AnyReader  # noqa: E402

from agvsim.record.mcap_file import scan_records  # noqa: E402
from agvsim.record.mcap_reader import Recording  # noqa: E402
from agvsim.scenario import build, load_scenario  # noqa: E402

pytestmark = pytest.mark.slow  # killed subprocess runs

ROOM = {
    "name": "kill room",
    "world": {"picture": "########\n#......#\n#......#\n#......#\n########"},
    "robots": [
        {
            "name": "a",
            "model": "differential",
            "pose": {"x_m": -1.0, "y_m": 0.0},
            "sensors": [{"type": "rangers"}, {"type": "lidar", "beams": 90, "rate_hz": 10}],
            "odometry": {"wheel_noise_rel": 0.02},
            "controller": {"type": "avoid", "trigger_m": 0.8, "speed_m_s": 0.5},
        }
    ],
}

CHILD = textwrap.dedent(
    """
    import sys
    from agvsim.runner import run_scenario

    def tick(t, total):
        print(f"{t:.6f}", flush=True)

    run_scenario(sys.argv[1], sys.argv[2], plot=False, progress=tick)
    """
)


def _start(tmp_path):
    data = json.loads(json.dumps(ROOM))
    data["duration_s"] = 100000.0  # runs until stopped
    scen = tmp_path / "room.yaml"
    scen.write_text(yaml.safe_dump(data))
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(scen), str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    return proc, scen, out


def _run_until(proc, t_min: float) -> float:
    """Read the child's progress lines until its simulated time passes ``t_min``."""
    assert proc.stdout is not None
    other = []
    for line in proc.stdout:
        try:
            t = float(line)
        except ValueError:
            other.append(line)
            continue
        if t >= t_min:
            return t
    err = "".join(other)[-2000:]
    raise AssertionError(f"the child stopped early (exit {proc.wait()}):\n{err}")


def _signal_at(proc, t_min: float, sig: signal.Signals, timeout_s: float) -> float:
    """Let the child run past simulated time ``t_min``, send it ``sig`` and wait for it to
    end (killing it if it does not); returns the time it had reached."""
    try:
        t_seen = _run_until(proc, t_min)
        proc.send_signal(sig)
        proc.wait(timeout=timeout_s)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stdout.close()
    return t_seen


def test_killed_run_leaves_a_readable_recording(tmp_path):
    proc, scen, out = _start(tmp_path)
    t_seen = _signal_at(proc, 4.0, signal.SIGKILL, timeout_s=30)
    path = out / "run.mcap"
    assert not (out / "summary.json").exists()  # it really died before writing the end
    # the file ends in a (provisional) footer: rosbags reads it as it is, no repair needed
    assert scan_records(path)[2]
    with AnyReader([path]) as r:
        assert "/a/ground_truth" in {c.topic for c in r.connections}
    rec = Recording(path)
    assert not rec.repaired
    t, poses, _ = rec.odometry("/a/ground_truth")
    # everything up to within a second of the time the child had reached when it was killed
    assert t[-1] >= t_seen - 1.0 - 1e-9
    np.testing.assert_allclose(np.diff(t), 0.02, atol=1e-9)  # no gap
    # and it is the run itself: a fresh simulation of the same scenario gives the same poses
    sim = build(load_scenario(scen))
    for k in range(len(t)):
        if k:
            sim.step()
        if k % 50 == 0:
            np.testing.assert_allclose(poses[k], sim.state.poses[0], atol=1e-12)
    assert len(rec.laser_scans("/a/lidar").stamp_s) >= int(t[-1] * 10)


def test_interrupted_run_closes_the_recording(tmp_path):
    proc, _, out = _start(tmp_path)
    _signal_at(proc, 2.0, signal.SIGINT, timeout_s=60)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["run"]["status"] == "interrupted"
    path = out / "run.mcap"
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        stats = make_reader(f).get_summary().statistics  # the full summary was written
    t, _, _ = Recording(path).odometry("/a/ground_truth")
    assert t[-1] == pytest.approx(summary["run"]["simulated_time_s"])
    assert stats.message_count > 0
