"""Live frame sources for the camera node and the graph, one protocol: a synthetic underwater endoscope (the
built-in default), a V4L2/USB device, and files (images, folders, globs, videos, bags) read as the command line
reads them (`frames`). No ROS here.

`read()` returns the next frame, None at the end of a file source, and raises SourceError for a frame that
could not be had (unreadable file, device not delivering): the caller logs it and carries on or retries.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from .board import BoardSpec
from .files import glob_matches
from .frames import IMAGE_SUFFIXES, InputError, expand_inputs, iter_frames
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
    scene_targets_content,
)
from .targets import TargetsSpec

SYNTHETIC_SCENES = ("cube", "bush", "board", "board_then_cube")
DEFAULT_BOARD = BOARD  # the board the built-in synthetic camera shows: the calibration node's default


def default_targets() -> TargetsSpec:
    """The targets the built-in synthetic camera shows: the area node's default."""
    return scene_targets()


def default_targets_content() -> dict:
    """The same targets as a targets file's content (YAML-ready), for a user to measure a saved frame."""
    return scene_targets_content()


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
        return self.scene_frame()

    def scene_frame(self) -> np.ndarray | None:
        """One frame of the measured scene (with the sensor's noise), whatever the source is showing now; None
        for a board-only source."""
        if self.scene is None:
            return None
        if self._clean_scene is None:
            self._clean_scene = render_scene(self.camera, self.scene, DISTANCE_M, self.port, noise_sigma=0.0)
        return self._noisy(self._clean_scene)

    def release(self) -> None:
        pass


LOOP_CACHE_FRAMES = 16  # a looped input of at most this many frames is decoded once (test patterns at any rate)


class FileSource:
    """Image files, folders, videos or rosbag2 bags, read by `frames.iter_frames` as the command line reads
    them. The end returns None, or starts over with `loop`; a looped input of at most LOOP_CACHE_FRAMES frames
    is decoded once. An unreadable frame raises SourceError naming it."""

    def __init__(self, paths: list[Path], loop: bool = False):
        self.notes: list[str] = []  # what reading assumed or passed over, each kind once, for the node to say
        try:
            self.files = expand_inputs(paths, self.notes, archives=True)  # and photos passed over (raw, HEIC)
        except InputError as exc:
            raise SourceError(str(exc)) from exc
        self.loop = loop
        self._frames = iter_frames(self.files)
        self._first_pass: list[np.ndarray | str] | None = [] if loop else None  # while it may be replayed
        self._replay: list[np.ndarray | str] | None = None
        self._next = 0
        self._note_kinds: set[str] = set()

    def read(self) -> np.ndarray | None:
        if self._replay is not None:
            item = self._replay[self._next % len(self._replay)]
            self._next += 1
        else:
            item = self._read_file()
            if item is None:
                return None
        if isinstance(item, str):
            raise SourceError(item)
        return item

    def _read_file(self) -> np.ndarray | str | None:
        """The next frame decoded (or why it could not be), None at the end of an input not looped."""
        frame = next(self._frames, None)
        if frame is None:
            if not self.loop:
                return None
            if self._first_pass:  # short: replayed from memory from now on
                self._replay, self._next = self._first_pass, 1
                return self._replay[0]
            self._frames = iter_frames(self.files)
            frame = next(self._frames, None)
            if frame is None:
                raise SourceError(f"{self.files[0]}: no frame after starting over")
        item = frame.image if frame.image is not None else f"{frame.name} {frame.problem}"
        for note in frame.notes:
            kind = note.split(":", 1)[0]
            if kind not in self._note_kinds:
                self._note_kinds.add(kind)
                # a depth note is about what is published; files passed over and an EXIF turn are not
                published = " (the published frames are 8-bit)" if note.startswith("16-bit image read as") else ""
                self.notes.append(f"{frame.name}: {note}{published}")
        if self._first_pass is not None:
            self._first_pass.append(item)
            if len(self._first_pass) > LOOP_CACHE_FRAMES:
                self._first_pass = None
        return item

    def release(self) -> None:
        self._frames.close()  # a video's capture is released by its generator


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


SOURCE_KINDS = {"device": "a device", "file": "files (videos, folders, bags)", "synthetic": "the synthetic camera"}
SOURCE_SETTINGS = (("image_width/image_height", "device"), ("loop", "file"), ("synthetic_scene", "synthetic"),
                   ("synthetic_medium", "synthetic"))  # each setting and the kind of source that uses it


def open_source(source: str, loop: bool = False, width: int = 0, height: int = 0,
                synthetic_scene: str = "board_then_cube", synthetic_medium: str = "water"
                ) -> SyntheticSource | DeviceSource | FileSource:
    """`synthetic`, a device (index or /dev/video*), a video file, an image folder, a rosbag2 bag or a glob.
    A setting the source has no use for (a device's size for a file, the synthetic scene for a device, looping a
    device) is refused with the reason (SourceError): it was ignored without a word."""
    kind = ("synthetic" if source == "synthetic" else "device" if source.isdigit() or source.startswith("/dev/video")
            else "file")
    given = {"image_width/image_height": bool(width or height), "loop": loop,
             "synthetic_scene": synthetic_scene != "board_then_cube", "synthetic_medium": synthetic_medium != "water"}
    unused = [(name, used_by) for name, used_by in SOURCE_SETTINGS if given[name] and used_by != kind]
    if unused:
        said = "; ".join(f"{name} applies only to {SOURCE_KINDS[used_by]}" for name, used_by in unused)
        raise SourceError(f"source {source!r} is {SOURCE_KINDS[kind]}: {said} (leave it at its default)")
    if kind == "synthetic":
        return SyntheticSource(synthetic_scene, synthetic_medium)
    if kind == "device":
        return DeviceSource(int(source) if source.isdigit() else source, width, height)
    path = Path(source)
    if path.exists():  # a folder, an image, a video (or a file OpenCV may still open as one), a bag
        return FileSource([path], loop)
    matches = [p for p in glob_matches(source) or [] if p.suffix.lower() in IMAGE_SUFFIXES]
    if matches:
        return FileSource(matches, loop)
    raise SourceError(f"source {source!r} is not 'synthetic', a device, a video, an image folder, a bag or a "
                      "glob that matches images")
