"""Every camera of a simulation as one table of C slots, rendering the ones that are due.

A :class:`~agvsim.sim.engine.Simulation` makes a ``CameraRig`` only when some robot has a
camera, so runs without cameras pay nothing. Each step the rig renders the cameras whose time
has come (``rate_hz``) and hands the frames to the engine, which stores, per slot, in the
simulation state:

* ``state.images[c]`` ``(H, W, 3)`` uint8 and ``state.depths[c]`` ``(H, W)`` float32 (read-only
  arrays, replaced by new ones at each frame, so a reference kept by a controller or a recorder
  never changes under it);
* ``state.image_stamp[c]`` the simulation time of the frame, ``state.image_seq[c]`` a frame
  counter (0 before the first frame) and ``state.image_pose[c]`` the robot's true pose then.

:meth:`CameraRig.frames` lists the latest frame of every camera with its robot and name.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from agvsim.geometry import box_tables
from agvsim.sensors.camera import (
    CameraSpec,
    MarkerView,
    add_pixel_noise,
    marker_views,
    pixel_rays,
    render_view,
)
from agvsim.sensors.grid_dda import mark_empty_space, pad_grid
from agvsim.sim.spec import BOX_HEIGHT_M, WALL_HEIGHT_M, RobotSpec, World
from agvsim.world.grid import OccupancyGrid


@dataclass(frozen=True)
class CameraFrame:
    """The latest frame of one camera."""

    robot: int  # robot index
    robot_name: str
    camera: str  # the camera's name
    slot: int
    seq: int  # frames taken so far (0: none yet)
    stamp_s: float  # simulation time of the frame
    rgb: np.ndarray  # (H, W, 3) uint8
    depth: np.ndarray  # (H, W) float32 z-depth m, inf = nothing within range


def rgb_of(color: str) -> tuple[int, int, int]:
    """A robot's colour ("#rrggbb", "#rgb", or a matplotlib colour name) as 0..255 RGB."""
    c = color.strip()
    h = c.lstrip("#")
    if c.startswith("#") and len(h) in (3, 6):
        try:
            if len(h) == 3:
                h = "".join(ch * 2 for ch in h)
            return (int(h[0:2], 16), int(h[2:4], 16), int(h[4:6], 16))
        except ValueError:
            pass
    try:  # named colours: matplotlib is a dependency, but only needed for names
        from matplotlib.colors import to_rgb

        r, g, b = to_rgb(c)
        return (round(r * 255), round(g * 255), round(b * 255))
    except (ImportError, ValueError):
        return (214, 39, 40)


class CameraRig:
    """The cameras of ``robots`` in ``world``: specs, owners and the scene tables."""

    def __init__(self, robots: Sequence[RobotSpec], world: World) -> None:
        self.specs: list[CameraSpec] = []
        owner: list[int] = []
        self.slots_of: list[list[int]] = []
        self.robot_names = [r.name for r in robots]
        for i, r in enumerate(robots):
            names = [s.name for s in r.sensors] + [c.name for c in r.cameras]
            if len(set(names)) != len(names):
                raise ValueError(f"robot {r.name!r}: sensor names must be unique, got {names}")
            for cam in r.cameras:
                if not cam.mount_z_m < WALL_HEIGHT_M:
                    raise ValueError(
                        f"robot {r.name!r}, camera {cam.name!r}: mount_z_m must be below the "
                        f"wall height {WALL_HEIGHT_M:g} m, got {cam.mount_z_m:g}"
                    )
            self.slots_of.append(list(range(len(self.specs), len(self.specs) + len(r.cameras))))
            self.specs.extend(r.cameras)
            owner.extend([i] * len(r.cameras))
        self.owner = np.array(owner, dtype=np.int64)
        self.period_s = np.array([c.period_s for c in self.specs], dtype=np.float64)
        self._rays = [pixel_rays(c) for c in self.specs]
        self._robot_h = np.array([r.height_m for r in robots], dtype=np.float64)
        self._robot_rgb = np.array([rgb_of(r.color) for r in robots], dtype=np.uint8)
        self.set_world(world)

    @property
    def count(self) -> int:
        return len(self.specs)

    def slot(self, robot: int, name: str) -> int:
        for s in self.slots_of[robot]:
            if self.specs[s].name == name:
                return s
        have = [self.specs[s].name for s in self.slots_of[robot]]
        raise KeyError(f"robot {self.robot_names[robot]!r} has no camera {name!r} (has {have})")

    # ------------------------------------------------------------------ scene
    def set_world(self, world: World) -> None:
        """Use a new world (walls, boxes, colours, markers): rebuilds the tables."""
        self.world = world
        grid: OccupancyGrid = world.grid
        ny, nx = grid.cells_bu.shape
        cells = pad_grid(np.ascontiguousarray(grid.cells_bu, dtype=np.uint8))
        mark_empty_space(cells, nx, ny)
        ox, oy = (float(v) for v in grid.origin_xy_m)
        self._table = (cells, int(nx), int(ny), float(grid.resolution_m), ox, oy)
        look = world.appearance
        self._scene = (
            look.cell_colors(grid),
            look.face_shades(),
            np.array(look.floor_rgb, dtype=np.float64),
            np.array(look.sky_rgb, dtype=np.float64),
            float(WALL_HEIGHT_M),
            bool(look.floor_checker),
        )
        self._marks = look.marker_tables()
        k = len(world.boxes)
        self._static_h = np.full(k, BOX_HEIGHT_M)
        self._static_rgb = np.tile(np.array(look.box_rgb, dtype=np.uint8), (k, 1))
        self._box_h = np.concatenate([self._robot_h, self._static_h])
        self._box_rgb = np.ascontiguousarray(np.concatenate([self._robot_rgb, self._static_rgb]))

    # ------------------------------------------------------------------ rendering
    def render(
        self, slot: int, robot_pose: np.ndarray, footprints: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """One frame of camera ``slot`` with its robot at ``robot_pose`` and every robot's
        footprint ``(N, 5)`` (the static boxes are added here): ``(rgb, depth)``, without pixel
        noise (``render_due`` adds it)."""
        spec = self.specs[slot]
        boxes = footprints
        if len(self.world.boxes):
            boxes = np.concatenate([footprints, self.world.boxes])
        boxes = np.ascontiguousarray(boxes, dtype=np.float64)
        return self._render(slot, robot_pose, boxes, box_tables(boxes), spec)

    def _render(self, slot, robot_pose, boxes, btab, spec):
        x, y, z, yaw = spec.pose_world(robot_pose)
        r = self._rays[slot]
        h, w = spec.height_px, spec.width_px
        rgb = np.empty((h * w, 3), dtype=np.uint8)
        depth = np.empty(h * w, dtype=np.float32)
        render_view(
            self._table,
            (r.bin_rel_az, r.bin_start, r.order, r.slope, r.inv_h),
            (x, y, z, yaw, float(spec.range_max_m)),
            self._scene,
            self._marks,
            (boxes, btab, self._box_h, self._box_rgb, int(self.owner[slot])),
            rgb,
            depth,
        )
        return rgb.reshape(h, w, 3), depth.reshape(h, w)

    # ------------------------------------------------------------------ in a simulation
    def blank_frames(self) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """One blank frame per camera (sky, inf depth), read-only: the state before the first
        render."""
        images: list[np.ndarray] = []
        depths: list[np.ndarray] = []
        for spec in self.specs:
            img = np.empty((spec.height_px, spec.width_px, 3), dtype=np.uint8)
            img[:] = self.world.appearance.sky_rgb
            dep = np.full((spec.height_px, spec.width_px), np.inf, dtype=np.float32)
            img.setflags(write=False)
            dep.setflags(write=False)
            images.append(img)
            depths.append(dep)
        return images, depths

    def render_due(
        self,
        state,
        footprints: np.ndarray,
        force: bool = False,
        rng: np.random.Generator | None = None,
    ) -> list[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
        """Render every camera due at ``state.t_s`` (all when ``force``); returns the new
        frames as ``(slot, rgb, depth, robot pose)``, read-only, for the engine to store (the
        state is only read here). Cameras with ``noise_std`` > 0 draw their pixel
        noise from ``rng`` (the simulation's generator; slot order, so runs repeat)."""
        due = np.ones(self.count, bool) if force else state.t_s >= state.next_image_s - 1e-9
        if not due.any():
            return []
        boxes = footprints
        if len(self.world.boxes):
            boxes = np.concatenate([footprints, self.world.boxes])
        boxes = np.ascontiguousarray(boxes, dtype=np.float64)
        btab = box_tables(boxes)
        done = []
        for slot in np.flatnonzero(due):
            pose = state.poses[self.owner[slot]]
            spec = self.specs[slot]
            rgb, depth = self._render(slot, pose, boxes, btab, spec)
            if spec.noise_std > 0.0:
                if rng is None:
                    raise ValueError(
                        f"camera {spec.name!r} has noise_std > 0: render_due needs the "
                        "simulation's generator (rng)"
                    )
                rgb = add_pixel_noise(rgb, spec.noise_std, rng)
            rgb.setflags(write=False)
            depth.setflags(write=False)
            done.append((int(slot), rgb, depth, pose))
        return done

    def marker_views(self, state, slot: int) -> list[MarkerView]:
        """Ground truth of camera ``slot``'s latest frame: the markers in view, their corner
        pixels and how much of each is unoccluded (:func:`agvsim.sensors.camera.marker_views`)."""
        return marker_views(
            self.specs[slot],
            state.image_pose[slot],
            self.world.appearance.markers,
            state.depths[slot],
        )

    def frames(self, state) -> list[CameraFrame]:
        """The latest frame of every camera (for recorders and viewers)."""
        return [
            CameraFrame(
                robot=int(self.owner[c]),
                robot_name=self.robot_names[int(self.owner[c])],
                camera=self.specs[c].name,
                slot=c,
                seq=int(state.image_seq[c]),
                stamp_s=float(state.image_stamp[c]),
                rgb=state.images[c],
                depth=state.depths[c],
            )
            for c in range(self.count)
        ]
