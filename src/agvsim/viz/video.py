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
        self._cams: dict[int, str] = {}
        if cameras and hasattr(sim, "camera_frames"):
            for f in sim.camera_frames():
                key = f"{_safe(f.robot_name)}_{_safe(f.camera)}"
                h, w = f.rgb.shape[:2]
                self.streams[key] = _Stream(self.out / f"{key}.mp4", w, h, fps)
                self._cams[f.slot] = key
        self._trail = np.zeros((sim.n, 1024, 2))  # (N, capacity, 2) grows by doubling
        self._k = 0  # frames written
        self._closed = False
        self._t0 = sim.state.t_s
        self.record()

    @property
    def paths(self) -> list[Path]:
        return [s.path for s in self.streams.values()]

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
            k = self._k
            if k >= self._trail.shape[1]:
                self._trail = np.concatenate([self._trail, np.zeros_like(self._trail)], axis=1)
            self._trail[:, k] = sim.state.poses[:, :2]
            trails = [self._trail[i, : k + 1] for i in range(sim.n)]
        self.streams["top"].write(self.view.render(sim, beams=self.beams, trails=trails))
        if self._cams:
            for f in sim.camera_frames():
                key = self._cams.get(f.slot)
                if key is not None:
                    self.streams[key].write(f.rgb)

    def close(self) -> None:
        """Write the frames still due (a step not yet seen) and finish the files."""
        if not self._closed:
            self._closed = True
            self.record()
            for s in self.streams.values():
                s.close()
