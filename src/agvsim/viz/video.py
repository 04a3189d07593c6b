"""MP4 videos of a run: the top view (``top.mp4``) and each onboard camera
(``<robot>_<camera>.mp4``), encoded while the simulation runs.

Frames are taken at ``fps`` frames per *simulated* second (25 by default), so the video plays
in real time whatever the speed of the simulation. Encoding uses the ffmpeg binary that the
``imageio-ffmpeg`` package ships (no system ffmpeg needed), H.264 in yuv420p, which every
browser and player opens.

    video = VideoRecorder(sim, "runs/x")     # writes the frame at t
    for _ in range(n):
        sim.step()
        video.record()                       # a frame whenever 1 / fps s have passed
    video.close()

The browser app records the same way from its step loop; when it rebuilds its simulation (an
edit in the mask, a reset) ``follow(new_sim)`` carries the videos on from the new one.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from agvsim.viz.topview import TopView


def _even(n: int, block: int = 16) -> int:
    """``n`` rounded up to a multiple of ``block`` (H.264 in yuv420p wants even sizes; 16 avoids
    ffmpeg's rescaling)."""
    return max(block, -(-int(n) // block) * block)


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]", "_", name)


def _camera_frames(sim) -> list:
    return sim.camera_frames() if hasattr(sim, "camera_frames") else []


def _camera_key(frame) -> str:
    """``<robot>_<camera>``: the name of a camera's video (without ``.mp4``)."""
    return f"{_safe(frame.robot_name)}_{_safe(frame.camera)}"


class _Stream:
    """One MP4 file fed with (H, W, 3) uint8 frames of a fixed size (padded with black)."""

    def __init__(self, path: Path, width: int, height: int, fps: float):
        import imageio_ffmpeg

        self.path, self.fps = path, fps
        self.width, self.height = _even(width), _even(height)
        self.frames = 0
        self._gen = imageio_ffmpeg.write_frames(
            str(path),
            (self.width, self.height),
            fps=fps,
            codec="libx264",
            macro_block_size=16,
            output_params=["-preset", "veryfast", "-threads", "2"],
        )
        self._gen.send(None)
        self._buf = np.zeros((self.height, self.width, 3), np.uint8)

    def write(self, rgb: np.ndarray) -> None:
        h, w = rgb.shape[:2]
        if (h, w) == (self.height, self.width):
            frame = np.ascontiguousarray(rgb, dtype=np.uint8)
        else:
            frame = self._buf
            frame[:h, :w] = rgb[: self.height, : self.width]
        self._gen.send(frame)
        self.frames += 1

    def close(self) -> None:
        self._gen.close()


class VideoRecorder:
    """Writes ``top.mp4`` (and one MP4 per camera, ``cameras=True``) into ``out_dir``.

    ``width_px`` is the top view's width (its height follows the map, rounded up to 16);
    ``trails`` draws where each robot has been, ``beams`` the sensor beams."""

    def __init__(
        self,
        sim,
        out_dir: str | Path,
        fps: float = 25.0,
        width_px: int = 720,
        *,
        cameras: bool = True,
        beams: bool = True,
        trails: bool = True,
    ):
        if not (fps > 0 and np.isfinite(fps)):
            raise ValueError(f"video fps must be a positive number, got {fps}")
        if int(width_px) < 16:
            raise ValueError(f"video width_px must be >= 16, got {width_px}")
        self.sim, self.fps = sim, float(fps)
        self.out = Path(out_dir)
        self.out.mkdir(parents=True, exist_ok=True)
        self.beams, self.trails = beams, trails
        xmin, xmax, ymin, ymax = sim.world.grid.extent_m
        width = _even(width_px)
        height = _even(width * (ymax - ymin) / (xmax - xmin))
        self.view = TopView(width, height)
        self.streams: dict[str, _Stream] = {
            "top": _Stream(self.out / "top.mp4", width, height, fps)
        }
        self._cams: set[str] = set()
        if cameras:
            for f in _camera_frames(sim):
                key = _camera_key(f)
                h, w = f.rgb.shape[:2]
                self.streams[key] = _Stream(self.out / f"{key}.mp4", w, h, fps)
                self._cams.add(key)
        self._trail = np.zeros((sim.n, 1024, 2))  # (N, capacity, 2) grows by doubling
        self._trail_k0 = 0  # the frame the trails start at
        self._k = 0  # frames written
        self._closed = False
        self._t0 = sim.state.t_s
        self.record()

    @property
    def paths(self) -> list[Path]:
        return [s.path for s in self.streams.values()]

    @property
    def frames(self) -> int:
        """Frames written to the top view so far."""
        return self._k

    @property
    def seconds(self) -> float:
        """Seconds of video written so far (frames / fps)."""
        return self._k / self.fps

    @property
    def closed(self) -> bool:
        return self._closed

    def follow(self, sim) -> None:
        """Go on recording from ``sim`` (a rebuilt simulation: same scenario edited, reset).
        The next frame is due at once when its clock went back; the trails start afresh
        unless the same robots go on at the same time. Cameras are matched by robot and camera
        name; one that is new gets no video, one that is gone gets no more frames."""
        if sim is self.sim:
            return
        old, self.sim = self.sim, sim
        t = sim.state.t_s
        due = self._t0 + self._k / self.fps
        same_robots = [r.name for r in sim.robots] == [r.name for r in old.robots]
        if t < due - 1.0 / self.fps - 1e-9 or t > due + 1.0:  # the clock jumped: rebase it
            self._t0 = t - self._k / self.fps
            same_robots = False
        if not same_robots:
            self._trail = np.zeros((sim.n, 1024, 2))
            self._trail_k0 = self._k

    def record(self) -> None:
        """Write the frames due by the simulation's current time (none, one, or several when a
        step is longer than a frame)."""
        t = self.sim.state.t_s
        while t >= self._t0 + self._k / self.fps - 1e-9:
            self._frame()
            self._k += 1

    def _frame(self) -> None:
        sim = self.sim
        trails = None
        if self.trails:
            k = self._k - self._trail_k0
            if k >= self._trail.shape[1]:
                self._trail = np.concatenate([self._trail, np.zeros_like(self._trail)], axis=1)
            self._trail[:, k] = sim.state.poses[:, :2]
            trails = [self._trail[i, : k + 1] for i in range(sim.n)]
        self.streams["top"].write(self.view.render(sim, beams=self.beams, trails=trails))
        if self._cams:
            for f in _camera_frames(sim):
                key = _camera_key(f)
                if key in self._cams:
                    self.streams[key].write(f.rgb)

    def close(self) -> None:
        """Write the frames still due (a step not yet seen) and finish the files."""
        if not self._closed:
            self._closed = True
            try:
                self.record()
            finally:  # every file is finished, even when the last frame fails
                errors = []
                for s in self.streams.values():
                    try:
                        s.close()
                    except (OSError, RuntimeError) as err:
                        errors.append(err)
                if errors:
                    raise errors[0]
