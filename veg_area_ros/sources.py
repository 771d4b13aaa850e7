"""Frame sources for the camera node and the graph: a synthetic underwater endoscope (the built-in default),
a V4L2/USB device, a video file, an image folder or glob. No ROS here.

`read()` returns the next frame, None at the end of a file source, and raises SourceError for a frame that
could not be had (unreadable file, device not delivering): the caller logs it and carries on or retries.
"""

from __future__ import annotations

import glob
from pathlib import Path

import cv2
import numpy as np

from .board import BoardSpec
from .frames import IMAGE_SUFFIXES, read_image
from .sim.synthetic import (
    BOARD,
    DISTANCE_M,
    ENDOSCOPE,
    VIEWS,
    FlatPort,
    board_views,
    bush_scene,
    cube_scene,
    degrade,
    render_board_views,
    render_scene,
    scene_targets,
)
from .targets import TargetsSpec

SYNTHETIC_SCENES = ("cube", "bush", "board", "board_then_cube")
DEFAULT_BOARD = BOARD  # the board the built-in synthetic camera shows: the calibration node's default


def default_targets() -> TargetsSpec:
    """The targets the built-in synthetic camera shows: the area node's default."""
    return scene_targets()


class SourceError(RuntimeError):
    """A frame that could not be had; the message says why."""


class SyntheticSource:
    """The underwater endoscope of `synthetic.ENDOSCOPE` behind a flat port (or in air): a cube or bush
    between four ArUco markers at 0.7 m, and/or calibration board views. Frames are rendered once, lazily,
    and replayed with fresh sensor noise, so the source keeps up with any rate after the first pass."""

    def __init__(self, scene: str = "board_then_cube", medium: str = "water", board_passes: int = 2, seed: int = 0):
        if scene not in SYNTHETIC_SCENES:
            raise SourceError(f"synthetic scene must be one of {', '.join(SYNTHETIC_SCENES)}, got {scene!r}")
        if medium not in ("air", "water"):
            raise SourceError(f"synthetic medium must be air or water, got {medium!r}")
        self.camera = ENDOSCOPE
        self.port = FlatPort() if medium == "water" else None
        self.scene_name = "cube" if scene == "board_then_cube" else scene
        self.scene = None
        if self.scene_name in ("cube", "bush"):
            self.scene = cube_scene() if self.scene_name == "cube" else bush_scene()
        self.board_frames = VIEWS * board_passes if scene in ("board", "board_then_cube") else 0
        self.loop_board = scene == "board"
        self._rng = np.random.default_rng(seed)
        self._poses = None
        self._board_cache: dict[int, np.ndarray] = {}
        self._clean_scene: np.ndarray | None = None
        self.index = 0

    @property
    def true_area_m2(self) -> float | None:
        return None if self.scene is None else self.scene.true_area_m2

    def _board_view(self, k: int) -> np.ndarray:
        if k not in self._board_cache:
            board = BoardSpec.parse(BOARD)
            if self._poses is None:
                self._poses = board_views(self.camera, board, VIEWS, DISTANCE_M,
                                          np.random.default_rng(3), port=self.port)
            image = render_board_views(self.camera, board, [self._poses[k]], port=self.port, noise_sigma=0.0)[0]
            self._board_cache[k] = image
        return self._board_cache[k]

    def _noisy(self, clean: np.ndarray) -> np.ndarray:
        return degrade(clean, self._rng, noise_sigma=1.0)

    def read(self) -> np.ndarray | None:
        k = self.index
        self.index += 1
        if self.board_frames and (self.loop_board or k < self.board_frames):
            grey = self._noisy(self._board_view(k % VIEWS))
            return cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)
        if self._clean_scene is None:
            self._clean_scene = render_scene(self.camera, self.scene, DISTANCE_M, self.port, noise_sigma=0.0)
        return self._noisy(self._clean_scene)

    def release(self) -> None:
        pass


class VideoSource:
    def __init__(self, path: str, loop: bool = False):
        self.path = path
        self.loop = loop
        self._capture = cv2.VideoCapture(path)
        if not self._capture.isOpened():
            raise SourceError(f"{path}: not a video OpenCV can open")

    def read(self) -> np.ndarray | None:
        ok, image = self._capture.read()
        if ok:
            return image
        if not self.loop:
            return None
        self._capture.release()
        self._capture = cv2.VideoCapture(self.path)
        ok, image = self._capture.read()
        if not ok:
            raise SourceError(f"{self.path}: no frame after rewinding")
        return image

    def release(self) -> None:
        self._capture.release()


LOOP_CACHE_FRAMES = 16  # a looped folder of at most this many images is decoded once (test patterns at any rate)


class FolderSource:
    def __init__(self, files: list[Path], loop: bool = False):
        if not files:
            raise SourceError("no image files found")
        self.files = files
        self.loop = loop
        self.index = 0
        self._cache: dict[int, np.ndarray] | None = {} if loop and len(files) <= LOOP_CACHE_FRAMES else None

    def read(self) -> np.ndarray | None:
        if self.index >= len(self.files):
            if not self.loop:
                return None
            self.index = 0
        index = self.index
        self.index += 1
        if self._cache is not None and index in self._cache:
            return self._cache[index]
        path = self.files[index]
        image, problem = read_image(path)
        if image is None:
            raise SourceError(f"{path.name} {problem}")
        if self._cache is not None:
            self._cache[index] = image
        return image

    def release(self) -> None:
        pass


class DeviceSource:
    """A V4L2 / USB camera (index or /dev/videoN). A device that stops delivering raises SourceError; the
    caller calls reopen() to retry (an unplugged endoscope that comes back is picked up again)."""

    def __init__(self, device: int | str, width: int = 0, height: int = 0):
        self.device, self.width, self.height = device, width, height
        self._capture = None
        self.reopen()

    def reopen(self) -> None:
        if self._capture is not None:
            self._capture.release()
        self._capture = cv2.VideoCapture(self.device, cv2.CAP_V4L2)
        if not self._capture.isOpened():
            raise SourceError(f"device {self.device} cannot be opened")
        if self.width and self.height:
            self._capture.set(cv2.CAP_PROP_FRAME_WIDTH, self.width)
            self._capture.set(cv2.CAP_PROP_FRAME_HEIGHT, self.height)

    def read(self) -> np.ndarray | None:
        ok, image = self._capture.read()
        if not ok:
            raise SourceError(f"device {self.device} delivered no frame (unplugged?)")
        return image

    def release(self) -> None:
        self._capture.release()


def open_source(source: str, loop: bool = False, width: int = 0, height: int = 0,
                synthetic_scene: str = "board_then_cube", synthetic_medium: str = "water"):
    """`synthetic`, a device (index or /dev/video*), a video file, an image folder or a glob pattern."""
    if source == "synthetic":
        return SyntheticSource(synthetic_scene, synthetic_medium)
    if source.isdigit() or source.startswith("/dev/video"):
        return DeviceSource(int(source) if source.isdigit() else source, width, height)
    path = Path(source)
    if path.is_dir():
        return FolderSource(sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES), loop)
    if path.is_file():
        if path.suffix.lower() in IMAGE_SUFFIXES:
            return FolderSource([path], loop)
        return VideoSource(str(path), loop)  # a video, or a file OpenCV may still open as one
    matches = sorted(Path(p) for p in glob.glob(source) if Path(p).suffix.lower() in IMAGE_SUFFIXES)
    if matches:
        return FolderSource(matches, loop)
    raise SourceError(f"source {source!r} is not 'synthetic', a device, a video, an image folder or a glob "
                      "that matches images")
