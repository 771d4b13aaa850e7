"""The golden set of the measurement: every field of every frame's result over a fixed set of inputs (the
paper-table scenes, flume scenes, frame sequences from a video with noise, a bump and a change of light, the
real photos of test/data, a flat port, every classifier option), kept in test/data/golden_area.json.
`test_golden_area.py` holds the code to it; rewrite it only with a reason in the commit:

    .venv/bin/python test/golden_area.py --write
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent / "veg_area_ros"), str(HERE)]  # the working tree
from board_photos import board_photos, calibrated  # noqa: E402
from helpers import OPENCV_LEFT, TEST_DATA, calibrated_camera  # noqa: E402

from veg_area_ros.area import AreaMeasurer  # noqa: E402
from veg_area_ros.camera_model import BrownCamera  # noqa: E402
from veg_area_ros.classify import Classifier  # noqa: E402
from veg_area_ros.flat_port import FlatPort, FlatPortCamera  # noqa: E402
from veg_area_ros.port_area import PortAreaMeasurer  # noqa: E402
from veg_area_ros.sim.reproduction import CONDITIONS, SETUPS, distance_scene  # noqa: E402
from veg_area_ros.sim.synthetic import (  # noqa: E402
    DISTANCE_M,
    ENDOSCOPE,
    bush_scene,
    cube_scene,
    empty_scene,
    render_scene,
    scene_targets,
    twig_scene,
)
from veg_area_ros.targets import TargetsSpec  # noqa: E402

GOLDEN = TEST_DATA / "golden_area.json"
# the cameras the cases measure with, kept in the golden file: the calibration (threaded BLAS sums in another
# order) differs from run to run in the tenth digit, and the golden set holds the measurement, not the fit
CAMERAS: dict[str, BrownCamera] = {}


def camera(name: str) -> BrownCamera:
    """'endoscope air', 'endoscope water', 'dslr water' or 'opencv-left': from the golden file when it is being
    checked, calibrated when it is being written."""
    if name not in CAMERAS:
        if name == "opencv-left":
            CAMERAS[name] = calibrated(str(OPENCV_LEFT), "chessboard:9x6:1")
        else:
            CAMERAS[name] = calibrated_camera(*name.split())
    return CAMERAS[name]
SQUARE_MARKERS = {0: (-0.15, -0.15), 1: (0.15, -0.15), 2: (0.15, 0.15), 3: (-0.15, 0.15)}
FLUME = dict(noise_sigma=4.0, blur_sigma_px=1.0, light_gradient=0.3)


def targets_for(scene, **extra) -> TargetsSpec:
    return TargetsSpec.from_dict({"dictionary": scene.dictionary,
                                  "markers": {i: list(xy) for i, xy in scene.markers.items()}, **extra})


def _digest(image: np.ndarray | None) -> str | None:
    return None if image is None else hashlib.sha256(np.ascontiguousarray(image).tobytes()).hexdigest()[:16]


def record(measurer, frames, keep_images: bool = False, grey: bool = False) -> list[dict]:
    """Each frame's summary (plus its images' digests when kept) and the measurer's counters after it."""
    rows = []
    for frame in frames:
        grey_frame = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if grey and frame.ndim == 3 else None
        try:
            result = measurer.measure(frame, keep_images=keep_images, grey=grey_frame)
        except Exception as exc:  # a refused frame is part of what the golden set keeps
            rows.append({"error": f"{type(exc).__name__}: {exc}"})
            continue
        row = result.summary()
        row["rebuilds"] = measurer.rebuilds
        row["light_fits"] = getattr(measurer, "light_fits", None)
        if keep_images:
            row["images"] = [_digest(result.mask), _digest(result.roi), _digest(result.image)]
        rows.append(row)
    return rows


def _paper_cases() -> Iterator[tuple[str, Callable[[], list[dict]]]]:
    for camera_name in ("endoscope", "dslr"):
        setup = SETUPS[camera_name]
        scenes = {"cube": cube_scene(pixels_per_metre=setup.texels_per_metre),
                  "bush": bush_scene(pixels_per_metre=setup.texels_per_metre,
                                     oversample=max(2, round(16000 / setup.texels_per_metre)))}
        targets = targets_for(scenes["cube"])
        for condition in CONDITIONS:
            medium = "air" if condition.port is None else "water"
            for object_name, scene in scenes.items():
                if camera_name == "dslr" and (condition.name != "flume" or object_name != "bush"):
                    continue  # one DSLR frame: the 10 MP geometry window and the bush that fell back

                def case(setup=setup, scene=scene, condition=condition, medium=medium, targets=targets):
                    frame = render_scene(setup.camera, scene, DISTANCE_M, condition.port,
                                         noise_sigma=condition.noise_sigma, seed=11,
                                         blur_sigma_px=condition.blur_fraction * setup.camera.width,
                                         light_gradient=condition.light_gradient, supersample=setup.supersample)
                    lens = camera(f"{setup.name} {medium}")
                    classifier = Classifier(threshold=120)
                    rows = record(AreaMeasurer(None, targets, classifier), [frame])
                    rows += record(AreaMeasurer(lens, targets, classifier), [frame], keep_images=True)
                    rows += record(AreaMeasurer(lens, targets, classifier, area_mode="count"), [frame])
                    return rows

                yield f"paper {camera_name} {condition.name} {object_name}", case


def _flume_cases() -> Iterator[tuple[str, Callable[[], list[dict]]]]:
    rng = np.random.default_rng(26)
    for k in range(6):
        roll = [0.0, 90.0, 0.0, 90.0][k] if k < 4 else float(rng.uniform(-30, 30))
        plan = dict(roll=roll, direction=float(rng.uniform(0, 360)), side=float(rng.uniform(0.08, 0.12)),
                    centre=tuple(rng.uniform(-0.004, 0.004, 2)), distance=float(rng.uniform(0.66, 0.74)))

        def case(plan=plan, k=k):
            lens = camera("endoscope water")
            scene = cube_scene(side=plan["side"], markers=SQUARE_MARKERS)
            view = dict(roll_deg=plan["roll"], centre=plan["centre"], light_direction_deg=plan["direction"],
                        **FLUME)
            frame = render_scene(ENDOSCOPE, scene, plan["distance"], FlatPort(), seed=k, **view)
            empty = render_scene(ENDOSCOPE, empty_scene(scene), plan["distance"], FlatPort(), seed=100 + k, **view)
            rows = record(AreaMeasurer(lens, targets_for(scene), Classifier(threshold="otsu")), [frame])
            rows += record(AreaMeasurer(lens, targets_for(scene), Classifier(threshold="otsu"), background=empty),
                           [frame])
            return rows

        yield f"flume {k}", case


def _video_frames(count: int, noise: float, seed: int) -> list[np.ndarray]:
    """A steady camera's MJPG video of the cube: every frame with fresh noise, decoded as OpenCV decodes it."""
    clean = render_scene(ENDOSCOPE, cube_scene(), 0.7, noise_sigma=0.0)
    rng = np.random.default_rng(seed)
    frames = []
    for _ in range(count):
        noisy = np.clip(clean + rng.normal(0, noise, clean.shape), 0, 255).astype(np.uint8)
        _, jpeg = cv2.imencode(".jpg", noisy, [cv2.IMWRITE_JPEG_QUALITY, 90])
        frames.append(cv2.imdecode(jpeg, cv2.IMREAD_COLOR))
    return frames


def _sequence_cases() -> Iterator[tuple[str, Callable[[], list[dict]]]]:
    def video():
        measurer = AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier(threshold=120))
        return record(measurer, _video_frames(25, 3.0, 0), grey=True)

    def bumped():
        clean = render_scene(ENDOSCOPE, cube_scene(), 0.7, noise_sigma=0.0)
        moved = cv2.warpAffine(clean, np.float32([[1, 0, 2.6], [0, 1, -1.3]]), ENDOSCOPE.image_size,
                               borderMode=cv2.BORDER_REPLICATE)
        rng = np.random.default_rng(1)
        frames = [np.clip((clean if k < 12 else moved) + rng.normal(0, 4, clean.shape), 0, 255).astype(np.uint8)
                  for k in range(24)]
        measurer = AreaMeasurer(camera("endoscope air"), scene_targets(), Classifier(threshold=120))
        return record(measurer, frames, keep_images=True)

    def cloud():  # the light drifts: a cloud over the flume, then the light comes back
        lens = camera("endoscope water")
        scene = cube_scene(side=0.1, markers=SQUARE_MARKERS)
        frames = [render_scene(ENDOSCOPE, scene, 0.7, FlatPort(), seed=k, gain=0.8 if 8 <= k < 16 else 1.0,
                               **FLUME) for k in range(30)]
        return record(AreaMeasurer(lens, targets_for(scene), Classifier(threshold="otsu")), frames)

    def hidden_marker():  # a marker covered for a few frames, found again
        frames = _video_frames(10, 2.0, 5)
        for k in (3, 4, 5):
            frames[k] = frames[k].copy()
            cv2.rectangle(frames[k], (20, 20), (200, 150), (200, 200, 200), cv2.FILLED)
        return record(AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier(threshold=120)), frames)

    yield "video mjpg noise 3", video
    yield "bumped camera", bumped
    yield "cloud over the flume", cloud
    yield "hidden marker", hidden_marker


def _option_cases() -> Iterator[tuple[str, Callable[[], list[dict]]]]:
    def frame_of(scene, **kwargs):
        return render_scene(ENDOSCOPE, scene, 0.7, seed=4, noise_sigma=2.0, **kwargs)

    cube, bush, twigs = cube_scene(), bush_scene(), twig_scene()
    air = lambda: camera("endoscope air")  # noqa: E731
    options = {
        "count otsu": (cube, lambda: (air(), Classifier(), {"area_mode": "count"})),
        "morphology": (bush, lambda: (air(), Classifier(threshold="otsu", open_px=1, close_px=1), {})),
        "morphology count": (bush, lambda: (air(), Classifier(threshold=120, open_px=1, close_px=2),
                                            {"area_mode": "count"})),
        "given levels": (cube, lambda: (air(), Classifier(threshold=120), {"levels": (40, 200)})),
        "bright object": (cube, lambda: (air(), Classifier(threshold=120, object="bright"), {})),
        "green": (cube, lambda: (air(), Classifier(threshold=140, object="green"), {})),
        "red channel": (bush, lambda: (air(), Classifier(threshold=110, channel="red"), {})),
        "twigs": (twigs, lambda: (air(), Classifier(threshold="otsu"), {})),
        "no even light": (bush, lambda: (air(), Classifier(threshold=120), {"even_light": False})),
        "user roi": (cube, lambda: (air(), Classifier(threshold=120),
                                    {"roi": np.array([[200.0, 130.0], [450.0, 140.0], [430.0, 350.0],
                                                      [210.0, 340.0]])})),
        "uncalibrated": (bush, lambda: (None, Classifier(threshold="otsu"), {})),
        "calibration conditions": (cube, lambda: (air(), Classifier(threshold=120), {
            "calibration_conditions": {"medium": "air", "calibration_distance_m": 0.5}})),
        "empty scene": (empty_scene(cube), lambda: (air(), Classifier(threshold="otsu"), {})),
    }
    for name, (scene, make) in options.items():
        def case(scene=scene, make=make, name=name):
            lens, classifier, extra = make()
            frame = frame_of(scene)
            if name == "green":
                frame = frame.copy()
                frame[..., 1] = np.where(frame[..., 1] < 100, 180, frame[..., 1])
            if name == "red channel":
                frame = frame.copy()
                frame[..., 0] = frame[..., 0] // 2
            measurer = AreaMeasurer(lens, targets_for(scene), classifier, **extra)
            return record(measurer, [frame, frame_of(scene, light_gradient=0.2)], keep_images=True)

        yield f"option {name}", case

    def clipped():
        frame = frame_of(cube, gain=1.5)
        return record(AreaMeasurer(air(), targets_for(cube), Classifier(threshold=150)), [frame])

    def offset_plane():
        frame = frame_of(cube)
        targets = targets_for(cube, object_plane_offset_m=0.01, object_plane_offset_std_m=0.003)
        return record(AreaMeasurer(air(), targets, Classifier(threshold=120)), [frame])

    def port():
        from veg_area_ros.flat_port import FlatPort as Port
        port = Port(0.02, thickness=0.006, glass_index=1.49, tilt_x_rad=np.radians(2.0), tilt_y_rad=np.radians(-1.0))
        scene, targets = distance_scene(0.7)
        frames = [render_scene(ENDOSCOPE, scene, 0.7, port, seed=seed) for seed in range(3)]
        measurer = PortAreaMeasurer(FlatPortCamera(camera("endoscope air"), port), targets,
                                    Classifier(threshold=120))
        return record(measurer, frames, keep_images=True, grey=True)

    yield "clipped highlights", clipped
    yield "object plane offset", offset_plane
    yield "flat port", port


def _real_cases() -> Iterator[tuple[str, Callable[[], list[dict]]]]:
    def photos(area_mode: str):
        rows = []
        for photo in board_photos(OPENCV_LEFT, camera=camera("opencv-left")):
            measurer = AreaMeasurer(camera("opencv-left"), photo.targets, Classifier(threshold="otsu"),
                                    roi=np.array(photo.roi), area_mode=area_mode)
            rows += [{"photo": photo.name, **row} for row in record(measurer, [photo.frame], keep_images=True)]
        return rows

    yield "real opencv-left subpixel", lambda: photos("subpixel")
    yield "real opencv-left count", lambda: photos("count")


def cases() -> Iterator[tuple[str, Callable[[], list[dict]]]]:
    yield from _paper_cases()
    yield from _flume_cases()
    yield from _sequence_cases()
    yield from _option_cases()
    yield from _real_cases()


def _plain(value):
    """JSON's view of a value (tuples as lists, numpy scalars as Python's), floats exactly as repr gives them."""
    return json.loads(json.dumps(value, default=lambda v: v.item() if hasattr(v, "item") else str(v)))


def measure_all(progress: Callable[[str], None] = lambda _: None, cameras: dict | None = None) -> dict:
    """Every case's rows, and the cameras measured with under "cameras" (`cameras`: those to use)."""
    CAMERAS.clear()
    CAMERAS.update({name: BrownCamera(**fields) for name, fields in (cameras or {}).items()})
    found = {}
    for name, case in cases():
        found[name] = _plain(case())
        progress(f"{name}: {len(found[name])} rows")
    found["cameras"] = {name: _plain(dataclasses.asdict(lens)) for name, lens in CAMERAS.items()}
    return found


def main() -> int:
    """--write: measure every case and write the set; with the cameras the set holds (a rewrite then shows what
    the code changed, not the calibration's threaded sums), unless --new-cameras."""
    kept = None
    if GOLDEN.exists() and "--new-cameras" not in sys.argv:
        kept = json.loads(GOLDEN.read_text()).get("cameras")
    found = measure_all(lambda line: print(line, flush=True), cameras=kept)
    if "--write" in sys.argv:
        GOLDEN.write_text(json.dumps(found, indent=0, sort_keys=True) + "\n")
        print(f"wrote {GOLDEN}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
