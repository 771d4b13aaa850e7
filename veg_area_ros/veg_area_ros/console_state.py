"""What the operator's console shows and accepts, without ROS or a web server: the newest image of each view
as a small JPEG made at a bounded rate, Af over time, the calibration's progress, the parameters a researcher
tunes (checked before they go to the area node), a ROI drawn on the shown image in the node's pixels, and the
rule for who may change anything (a token). The console node fills it; the console server reads it."""

from __future__ import annotations

import ipaddress
import itertools
import math
import os
import secrets
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import cv2
import numpy as np

from .classify import CHANNELS, OBJECTS
from .settings import AREA_MODE_CHOICES, THRESHOLD_MODES, TONE_CURVE_CHOICES

VIEWS = ("area", "calibration", "camera")  # the overlay, the calibration node's feedback, the raw camera image
MAX_WIDTH_PX = 800  # images to the page: never wider (a 10 MP frame is not sent whole)
MAX_RATE_HZ = 5.0  # and never more often, whatever the camera's rate
JPEG_QUALITY = 80
# a machine whose cores are busy (some runnable task waited for a CPU this share of the last 10 s, Linux's
# pressure stall information): the pages get fewer images and poll less, until it has calmed below CALM
BUSY_PRESSURE, CALM_PRESSURE = 0.30, 0.20
BUSY_RATE_HZ = 2.0
POLL_S, BUSY_POLL_S = 0.5, 1.0
VIEW_KEPT_S = 5.0  # a view nobody asked for in this long is unsubscribed (its node stops drawing it)
SERIES_POINTS = 1200
MESSAGES_KEPT = 12

# the area node's parameters the console sets, with what each must be
CHOICES = {"threshold_mode": THRESHOLD_MODES, "object": OBJECTS, "channel": CHANNELS, "area_mode": AREA_MODE_CHOICES,
           "tone_curve": TONE_CURVE_CHOICES}
NUMBERS = {"threshold": (0.0, 255.0), "open_px": (0, 50), "close_px": (0, 50)}
TUNED = (*NUMBERS, *CHOICES, "roi")


class ConsoleInputError(ValueError):
    """A request from the page that cannot be sent on; the message says why."""


@dataclass
class ImageFeed:
    """The newest frame of one view and its JPEG for the page, encoded at most MAX_RATE_HZ times a second
    and only when a page asks (a frame nobody looks at costs a reference, not an encoding)."""

    max_width: int = MAX_WIDTH_PX
    max_rate_hz: float = MAX_RATE_HZ
    _frame: np.ndarray | None = None
    _frame_number: int = 0
    _jpeg: bytes | None = None
    _jpeg_number: int = -1
    _encoded_at: float = -math.inf
    encodings: int = 0
    frame_size: tuple[int, int] | None = None  # (width, height) of the node's image
    shown_size: tuple[int, int] | None = None  # of the JPEG
    asked_at: float = -math.inf
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def offer(self, frame: np.ndarray | Callable[[], np.ndarray]) -> None:
        """A new frame (BGR or grey uint8), or what decodes it (called only if it is shown: a camera's every
        frame is not decoded for a page that shows five a second); kept by reference, the last one wins."""
        with self._lock:
            self._frame, self._frame_number = frame, self._frame_number + 1
            if isinstance(frame, np.ndarray):
                self.frame_size = (frame.shape[1], frame.shape[0])

    def wanted(self, now: float) -> bool:
        return now - self.asked_at < VIEW_KEPT_S

    def jpeg(self, now: float) -> tuple[bytes | None, int]:
        """The JPEG of the newest frame and its number; the previous JPEG while the rate bound holds."""
        with self._lock:
            self.asked_at = now
            stale = self._jpeg_number != self._frame_number
            if self._frame is None or not stale or now - self._encoded_at < 1.0 / self.max_rate_hz:
                return self._jpeg, self._jpeg_number
            frame, number = self._frame, self._frame_number
            self._encoded_at = now
        try:
            frame = frame if isinstance(frame, np.ndarray) else frame()
        except ValueError:  # a message that does not decode: the previous image stays
            return self._jpeg, self._jpeg_number
        jpeg, shown = encode_small(frame, self.max_width)
        with self._lock:
            if number > self._jpeg_number:
                self._jpeg, self._jpeg_number, self.shown_size = jpeg, number, shown
                self.frame_size = (frame.shape[1], frame.shape[0])
                self.encodings += 1
            return self._jpeg, self._jpeg_number


def cpu_pressure(path: str = "/proc/pressure/cpu") -> float | None:
    """The share of the last 10 s in which some runnable task waited for a CPU (Linux's pressure stall
    information, `some avg10`), or None where the kernel does not say."""
    try:
        with open(path, encoding="ascii") as file:
            for line in file:
                if line.startswith("some "):
                    fields = dict(field.split("=", 1) for field in line.split()[1:])
                    return float(fields["avg10"]) / 100.0
    except (OSError, ValueError, KeyError):
        return None
    return None


@dataclass
class LoadGovernor:
    """Whether the console gives way: where the machine's cores are busy the camera and area nodes need them,
    so the pages are sent BUSY_RATE_HZ images a second and poll every BUSY_POLL_S; back to the full rate once
    the pressure is below CALM_PRESSURE (a gap between the two, so that the pages' own load, gone once
    slowed, does not make it swing)."""

    pressure: float | None = None
    slowed: bool = False

    def update(self, pressure: float | None) -> bool:
        self.pressure = pressure
        if pressure is None:
            self.slowed = False
        elif pressure >= BUSY_PRESSURE:
            self.slowed = True
        elif pressure < CALM_PRESSURE:
            self.slowed = False
        return self.slowed

    @property
    def image_rate_hz(self) -> float:
        return BUSY_RATE_HZ if self.slowed else MAX_RATE_HZ

    def as_dict(self) -> dict:
        return {"cpu_pressure": None if self.pressure is None else round(self.pressure, 3), "slowed": self.slowed,
                "images_per_s": self.image_rate_hz, "poll_s": BUSY_POLL_S if self.slowed else POLL_S}


def encode_small(frame: np.ndarray, max_width: int) -> tuple[bytes, tuple[int, int]]:
    """A JPEG of `frame` no wider than `max_width` (INTER_AREA: a downscale without aliasing), and its size."""
    height, width = frame.shape[:2]
    if width > max_width:
        scale = max_width / width
        frame = cv2.resize(frame, (max_width, max(1, round(height * scale))), interpolation=cv2.INTER_AREA)
    ok, data = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:
        raise ValueError("the frame could not be encoded as JPEG")
    return data.tobytes(), (frame.shape[1], frame.shape[0])


@dataclass
class AreaSeries:
    """Af over time as the area node publishes it, with the newest result's summary (warnings, frame counts)."""

    points: deque = field(default_factory=lambda: deque(maxlen=SERIES_POINTS))  # (s since first, Af, std)
    first_stamp_s: float | None = None
    latest: dict | Callable[[], dict] = field(default_factory=dict)
    received: int = 0
    run: int = 0  # a new run (a replay that restarted) starts the points afresh
    appended: int = 0  # points appended in this run: a page asks only for those after the ones it has
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def add_area(self, stamp_s: float, area_m2: float, std_m2: float) -> None:
        """A result; one without a finite Af or std (no object, a refused frame) is counted, not plotted."""
        with self._lock:
            self.received += 1
            if not all(math.isfinite(v) for v in (stamp_s, area_m2, std_m2)):
                return
            if self.first_stamp_s is None or stamp_s < self.first_stamp_s:  # a replay that restarted: new run
                self.first_stamp_s = stamp_s
                self.points.clear()
                self.run += 1
                self.appended = 0
            self.points.append((round(stamp_s - self.first_stamp_s, 4), area_m2, std_m2))
            self.appended += 1

    def add_info(self, summary: dict | Callable[[], dict]) -> None:
        """The newest result's summary or what makes it (made only when a page reads it: results come at the
        camera's rate, pages ask twice a second)."""
        with self._lock:
            self.latest = summary

    def as_dict(self, shown: tuple[int, int] | None = None) -> dict:
        """The series and the newest summary. `shown`: the (run, appended) a page already has: then only the
        points after those (all of them when the run changed or the page fell behind the window), so a page
        polling twice a second is not sent the whole window each time."""
        with self._lock:
            latest = self.latest
        if callable(latest):
            latest = latest()
        with self._lock:
            new = self.appended - shown[1] if shown is not None and shown[0] == self.run else len(self.points)
            new = min(max(new, 0), len(self.points))
            points = list(itertools.islice(self.points, len(self.points) - new, None))
            return {"points": points, "complete": new == len(self.points), "run": self.run,
                    "appended": self.appended, "window": SERIES_POINTS, "received": self.received,
                    "warnings": latest.get("warnings", []),
                    "frames": {"measured": latest.get("frames_measured"), "skipped": latest.get("frames_skipped"),
                               "lost": latest.get("frames_lost"), "received": latest.get("frames_received")},
                    "area_mode": latest.get("area_mode"), "subpixel_applied": latest.get("subpixel_applied"),
                    "threshold": latest.get("threshold"), "calibrated": latest.get("calibrated"),
                    "pixel_count": latest.get("pixel_count")}


@dataclass
class CalibrationLog:
    """The calibration node's `~/progress` as it comes: the newest state and its last messages."""

    latest: dict = field(default_factory=dict)
    messages: deque = field(default_factory=lambda: deque(maxlen=MESSAGES_KEPT))
    served: dict | None = None  # the camera_info served (fx, fy, cx, cy, model)
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def add_progress(self, progress: dict) -> None:
        with self._lock:
            self.latest = progress
            if progress.get("message"):
                self.messages.append(progress["message"])

    def add_result(self, message: str) -> None:
        with self._lock:
            self.messages.append(message)

    def as_dict(self) -> dict:
        with self._lock:
            return {"progress": self.latest, "messages": list(self.messages), "served": self.served}


def checked_parameters(request: dict) -> dict:
    """The area node's parameters from a page's request, typed as the node declares them; ConsoleInputError
    for a name the console does not set or a value out of its range."""
    if not isinstance(request, dict) or not request:
        raise ConsoleInputError("no parameters given")
    checked: dict = {}
    for name, value in request.items():
        if name in NUMBERS:
            low, high = NUMBERS[name]
            kind = type(low)
            try:
                number = kind(value)
            except (TypeError, ValueError):
                raise ConsoleInputError(f"{name} must be a number, got {value!r}") from None
            if isinstance(value, bool) or not math.isfinite(number) or not low <= number <= high or \
                    (kind is int and float(value) != number):
                raise ConsoleInputError(f"{name} must be {'a whole number ' if kind is int else ''}"
                                        f"from {low} to {high}, got {value!r}")
            checked[name] = number
        elif name in CHOICES:
            if value not in CHOICES[name]:
                raise ConsoleInputError(f"{name} must be one of {', '.join(CHOICES[name])}, got {value!r}")
            checked[name] = value
        elif name == "roi":
            checked[name] = checked_roi(value)
        else:
            raise ConsoleInputError(f"{name!r} is not a parameter the console sets (it sets {', '.join(TUNED)})")
    return checked


def checked_roi(value: object) -> list[float]:
    """[0.0] (inside the targets) or a polygon of at least three finite points, as floats."""
    try:
        if not isinstance(value, list | tuple):
            raise TypeError
        values = [float(v) for v in value]
    except (TypeError, ValueError):
        raise ConsoleInputError(f"roi must be a list of numbers, got {value!r}") from None
    if values == [0.0]:
        return values
    if len(values) < 6 or len(values) % 2 or not all(math.isfinite(v) for v in values):
        raise ConsoleInputError("roi must be [0.0] or x1,y1,x2,y2,x3,y3,... (three points or more)")
    return values


def roi_from_drag(start: tuple[float, float], end: tuple[float, float], shown_size: tuple[int, int],
                  frame_size: tuple[int, int]) -> list[float]:
    """A rectangle dragged on the shown (downscaled) image, as the area node's `roi` parameter: its four
    corners in the node's pixels, clipped to the image. ConsoleInputError for a rectangle with no area."""
    scale_x = frame_size[0] / shown_size[0]
    scale_y = frame_size[1] / shown_size[1]
    xs = sorted(min(max(p[0] * scale_x, 0.0), frame_size[0] - 1.0) for p in (start, end))
    ys = sorted(min(max(p[1] * scale_y, 0.0), frame_size[1] - 1.0) for p in (start, end))
    if xs[1] - xs[0] < 2 or ys[1] - ys[0] < 2:
        raise ConsoleInputError("the rectangle drawn is less than 2 pixels wide or high")
    x0, x1 = (round(v, 1) for v in xs)
    y0, y1 = (round(v, 1) for v in ys)
    return [x0, y0, x1, y0, x1, y1, x0, y1]


@dataclass(frozen=True)
class Access:
    """Who may change things: everybody on loopback who reaches the page (its token is in the page, which
    only a page from this host name gets); beyond loopback only a request carrying the token the node printed.
    Reading needs no token."""

    host: str
    token: str

    @staticmethod
    def for_host(host: str, token: str = "") -> Access:
        return Access(host, token or secrets.token_urlsafe(18))

    @property
    def loopback_only(self) -> bool:
        return is_loopback(self.host)

    def may_change(self, given: str | None) -> bool:
        return bool(given) and secrets.compare_digest(given, self.token)

    def page_token(self, host_header: str) -> str:
        """The token put in the page: only for a page served on loopback under a loopback name (a page fetched
        through another name, e.g. DNS rebinding, must not learn it)."""
        return self.token if self.loopback_only and host_allowed(host_header, self) else ""


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def host_allowed(host_header: str, access: Access) -> bool:
    """Beyond loopback any Host; on loopback only loopback names (a foreign name is a rebinding attempt)."""
    if not access.loopback_only:
        return True
    name = host_header.rsplit(":", 1)[0] if not host_header.endswith("]") else host_header
    return is_loopback(name.strip("[]"))


def folder_size(path: str | os.PathLike) -> int:
    """Bytes in a folder's files (a bag being written)."""
    total = 0
    for root, _, files in os.walk(path):
        for name in files:
            try:
                total += os.stat(os.path.join(root, name)).st_size
            except OSError:
                continue
    return total


def now() -> float:
    return time.monotonic()
