"""The base of synthetic scenes: camera, smooth motion, textured boxes, rendering of a frame."""

from __future__ import annotations

from abc import ABC, abstractmethod
from functools import cached_property, lru_cache
from typing import Any, ClassVar

import numpy as np

from sal_adapters.camera import Camera
from sal_adapters.synthetic.atlas import Atlas, build_atlas
from sal_adapters.synthetic.render import Renderer, Stage
from sal_adapters.trajectory import Trajectory

__all__ = ["World", "rotation", "shared_world", "wave"]


def rotation(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """Camera-to-scene rotation ``Ry(yaw) @ Rx(pitch) @ Rz(roll)`` (rad) in the camera
    convention (y down): positive yaw turns right, positive pitch looks down."""
    cy, sy, cp, sp, cr, sr = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch), np.cos(roll), np.sin(roll)
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rx = np.array([[1, 0, 0], [0, cp, sp], [0, -sp, cp]])
    Rz = np.array([[cr, -sr, 0], [sr, cr, 0], [0, 0, 1]])
    return Ry @ Rx @ Rz


def wave(t: float, terms: np.ndarray) -> float:
    """``sum(amplitude * sin(2 pi t / period + phase))`` over rows ``(amplitude, period_s, phase_rad)``."""
    return float(np.sum(terms[:, 0] * np.sin(2 * np.pi * t / terms[:, 1] + terms[:, 2])))


class World(ABC):
    """A deterministic scene: everything follows from the class and the ``seed``.

    Subclasses set the class attributes, list their tiles in ``TILE_NAMES``, paint them in
    ``paint_tiles``, and define the camera motion (``pose``) and what is around (``stage``).
    """

    name: ClassVar[str]
    #: Frame rate (Hz).
    fps: ClassVar[float]
    #: ``(fx, fy, cx, cy, width, height)`` in pixels.
    intrinsics: ClassVar[tuple[float, float, float, float, int, int]]
    #: Stereo baseline (m): the right camera sits at +baseline along the left camera's x.
    baseline: ClassVar[float]
    #: Depth units per metre recorded in the camera (TUM convention), or ``None``.
    depth_scale: ClassVar[float | None] = None
    default_sensor: ClassVar[str]
    #: Standard deviation (px) of the lens's Gaussian point spread function; 0 for none.
    psf_sigma_px: ClassVar[float] = 0.0
    TILE_NAMES: ClassVar[tuple[str, ...]]

    def __init__(self, seed: int):
        self.seed = int(seed)
        self.tiles = {name: number for number, name in enumerate(self.TILE_NAMES)}

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickled as its class and seed (a world follows from them), so a sequence of it can
        travel to another process (a Ray worker), which builds the world once and shares it."""
        return shared_world, (type(self), self.seed)

    @abstractmethod
    def pose(self, t: float) -> np.ndarray:
        """Camera-to-scene pose (4x4) of the left camera at time ``t`` (s)."""

    @abstractmethod
    def stage(self, eye: np.ndarray) -> Stage:
        """What can be seen from the point ``eye`` (scene coordinates, m)."""

    @abstractmethod
    def paint_tiles(self, rng: np.random.Generator) -> dict[str, np.ndarray]:
        """Every tile of ``TILE_NAMES``, painted with ``rng``."""

    @cached_property
    def atlas(self) -> Atlas:
        """The scene's texture atlas (painted on first use)."""
        painted = self.paint_tiles(np.random.default_rng([self.seed, 0x7E7]))
        return build_atlas([(name, painted[name]) for name in self.TILE_NAMES])

    @cached_property
    def renderer(self) -> Renderer:
        """Renderer of the (left and right, same intrinsics) camera."""
        return Renderer(self.camera("mono"), self.atlas, psf_sigma_px=self.psf_sigma_px)

    def camera(self, sensor: str) -> Camera:
        """Intrinsics of the left camera; ``stereo`` adds the right camera at +baseline (x)."""
        fx, fy, cx, cy, width, height = self.intrinsics
        camera = Camera(fx, fy, cx, cy, width, height, depth_scale=self.depth_scale)
        if sensor == "stereo":
            camera = camera.with_stereo(self.T_left_right)
        return camera

    @property
    def T_left_right(self) -> np.ndarray:
        """Pose of the right camera in the left camera frame (4x4)."""
        T = np.eye(4)
        T[0, 3] = self.baseline
        return T

    def render(self, index: int, right: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """RGB and z-depth (float32 m, 0 = sky) of frame ``index`` seen by the left (or right) camera."""
        pose = self.pose(index / self.fps)
        if right:
            pose = pose @ self.T_left_right
        return self.renderer.render(self.stage(pose[:3, 3]), pose)

    def groundtruth(self, indices: np.ndarray) -> Trajectory:
        """Left-camera poses at frames ``indices``, in the frame of the camera at t = 0."""
        times = np.asarray(indices, np.float64) / self.fps
        origin = np.linalg.inv(self.pose(0.0))
        poses = np.stack([origin @ self.pose(t) for t in times]) if len(times) else np.zeros((0, 4, 4))
        return Trajectory.from_matrices(times, poses)


@lru_cache(maxsize=4)
def shared_world(world_class: type[World], seed: int) -> World:
    """The world of ``world_class`` and ``seed``, built once per process (its texture atlas is
    painted once)."""
    return world_class(seed)
