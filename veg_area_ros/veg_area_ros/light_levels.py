"""Stage 3 of a frame's measurement, the light and the levels: the band evened where the light is uneven, its
histogram over the ROI, and the object's and the background's grey levels that sub-pixel shares are read from.

It exists because the light is a property of the scene, not of one frame: a steady camera's flat field and
interior levels are found in one frame and carried to the next, found afresh every LIGHT_REFRESH_FRAMES
frames, when the weights were rebuilt, or when the light drifts. Takes the frame's raw band over the weights'
window, gives a `LitFrame` (the band, threshold, flat field, 2-D histogram, level estimator) and the levels
at the thresholds the area asks for (`levels_for`); carries a `LightMemory` from frame to frame.

No ROS here.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import cv2
import numpy as np

from .classify import (
    MIN_SPREAD_DN,
    Classifier,
    ClassifyError,
    LevelEstimator,
    Levels,
    SharesOnlyError,
    check_levels,
    otsu_level,
    pure_level,
)
from .light import FlatField, check_background_frame, flat_field
from .weights import Weights

LIGHT_REFRESH_FRAMES = 20  # a steady camera's light and levels are found afresh this often (and on a drift)
INTERIOR_PX = 3  # a class's interior: this far inside it, a blurred edge (1 px sd) adds under 0.1 % of the contrast
SAME_FRAME_DN = 1.0  # a background frame this close to the frame (mean over the ROI) is the frame itself
MAX_INTERIOR_PX = 30  # ... or deeper while the levels still move (a DSLR's turbid water: 7 px sd), up to this


@dataclass
class LightSettings:
    """How a camera's light is read: the classifier's band, whether it is evened (sub-pixel shares of a dark or
    bright object), a background frame's band, and the user's levels (object, background) if given."""
    classifier: Classifier
    even_light: bool
    background_band: np.ndarray | None
    given_levels: tuple[float, float] | None

    @classmethod
    def checked(cls, classifier: Classifier, area_mode: str, levels: Sequence[float] | None,
                background: np.ndarray | None, even_light: bool, image_size: tuple[int, int] | None) -> LightSettings:
        """The settings, each refused with its reason where it does not apply (ClassifyError)."""
        given = check_levels(levels)
        if given is not None and area_mode != "subpixel":
            raise SharesOnlyError("levels give the sub-pixel shares the object's and background's grey levels; "
                                  "they do not apply to count mode (whole pixels are taken at the threshold)", "levels")
        if given is not None:  # reversed levels turned Af inside out (+906 %)
            object_level, background_level = given
            if (object_level > background_level) != (classifier.object != "dark"):
                raise ClassifyError(f"levels {object_level:g},{background_level:g} are reversed for a "
                                    f"{classifier.object} object: its level must lie "
                                    f"{'below' if classifier.object == 'dark' else 'above'} the background's "
                                    "(give OBJECT,BACKGROUND)")
        # sub-pixel shares under uneven light: the band evened by the background's surface (a frame of the empty
        # scene, else fitted per frame); not for the excess-green index, which is no brightness
        even_light = even_light and area_mode == "subpixel" and classifier.object != "green"
        if background is not None and not even_light:
            raise SharesOnlyError("a background frame evens the light for sub-pixel shares of a dark or bright "
                                  "object; it does not apply to " + ("count mode" if area_mode != "subpixel"
                                                                     else "the excess-green index"), "background")
        if background is not None and image_size is not None:
            check_background_frame(background, (image_size[1], image_size[0]))
        band = None if background is None else classifier.index_image(background)
        return cls(classifier, even_light, band, given)


@dataclass
class Light:
    """What a steady camera's frames share about the light, found in one frame and carried to the next."""
    weights: Weights  # the layout it was found for
    unevenness: float | None  # relative, left for the levels' errors; None: no surface, a level may be off by a spread
    flat: FlatField | None = None  # applied to every frame (None: the light is even, or could not be fitted)
    levels: Levels | None = None  # from the classes' interiors
    seen_levels: Levels | None = None  # the histogram's levels in the frame it was found in: what drift is held to
    age: int = 0  # frames carried since


@dataclass
class LightMemory:
    """What this stage carries from frame to frame: the light found and its age, how often it was found, and the
    carried levels as `levels_at` gives them (made once per levels and light, not per threshold of the sweep)."""
    light: Light | None = None
    fits: int = 0  # how often the flat field and levels were found: every LIGHT_REFRESH_FRAMES, or a drift
    pure: tuple[Levels, float | None, Levels | None] | None = None

    def forget(self) -> None:
        self.light = None


@dataclass
class LitFrame:
    """One frame's band as the shares are read from it and what it gives."""
    band: np.ndarray  # evened where the light is uneven
    threshold: float
    flat: FlatField | None  # the flat field applied (None: none)
    histogram: np.ndarray  # band value x weight level over the ROI
    roi_count: np.ndarray  # the ROI's pixels at every band value
    estimator: LevelEstimator


def light_frame(raw_band: np.ndarray, weights: Weights, settings: LightSettings, memory: LightMemory) -> LitFrame:
    """The frame's band evened by the carried light, or by light found afresh where it drifted."""
    object_is_high = settings.classifier.object != "dark"
    band, threshold, flat, histogram = _evened(raw_band, weights, settings, memory, fresh=False)
    roi_count = histogram.sum(axis=1)
    estimator = LevelEstimator(roi_count, object_is_high, settings.classifier.tone_curve)
    if _light_drifted(estimator, threshold, memory):  # the light changed since it was fitted
        band, threshold, flat, histogram = _evened(raw_band, weights, settings, memory, fresh=True)
        roi_count = histogram.sum(axis=1)
        estimator = LevelEstimator(roi_count, object_is_high, settings.classifier.tone_curve)
        _light_drifted(estimator, threshold, memory)  # found in this frame: what the next frames are held to
    return LitFrame(band, threshold, flat, histogram, roi_count, estimator)


def levels_for(lit: LitFrame, thresholds: list[float], settings: LightSettings, memory: LightMemory
               ) -> dict[float, Levels | None]:
    """The levels at each of `thresholds` (`levels_at`), in that order."""
    found = {}
    for threshold in thresholds:
        if threshold not in found:
            found[threshold] = levels_at(lit.estimator, threshold, settings, memory)
    return found


def levels_at(estimator: LevelEstimator, threshold: float, settings: LightSettings, memory: LightMemory
              ) -> Levels | None:
    """The object/background levels at this threshold: the carried interior levels, estimated from the ROI's
    band histogram, or the user's with the spreads the histogram shows around them."""
    light = memory.light
    unevenness = None if light is None else light.unevenness

    def with_light(levels: Levels) -> Levels:
        # without a surface the light may vary: a level may be off by up to its spread
        return (replace(levels, object_error=None, background_error=None) if unevenness is None
                else levels.with_unevenness(unevenness))

    if light is not None and light.levels is not None and settings.given_levels is None:
        # the carried levels at every threshold of the sweep: made once for these levels and this light
        if memory.pure is None or memory.pure[0] is not light.levels or memory.pure[1] != unevenness:
            pure = with_light(light.levels)
            memory.pure = light.levels, unevenness, pure if pure.resolvable() else None
        return memory.pure[2]
    estimated = estimator.at(threshold)
    if estimated is not None:
        estimated = with_light(estimated)
    if settings.given_levels is None:
        return estimated if estimated is not None and estimated.resolvable() else None
    object_level, background_level = settings.given_levels
    # the classes' spreads as the light leaves them: the evened interiors where the light was read (the band's
    # histogram at the threshold holds the shading too: 13 DN for 3.5 on a shaded print, never resolvable)
    spread_from = light.levels if light is not None and light.levels is not None else estimated
    spreads = ((spread_from.object_spread, spread_from.background_spread) if spread_from is not None
               else (MIN_SPREAD_DN, MIN_SPREAD_DN))
    given = Levels(object_level, background_level, *spreads, estimated=False,
                   tone_curve=settings.classifier.tone_curve)
    return given if given.resolvable() else None


def _flat_field(band: np.ndarray, weights: Weights, threshold: float, settings: LightSettings,
                reach: int = INTERIOR_PX) -> FlatField | None:
    """The flat field of this frame's window: from the background frame, or fitted to the background
    pixels at least `reach` - 1 pixels from any pixel of the object's class (blurred edges stay out)."""
    if settings.background_band is not None:
        background = settings.background_band[weights.window]
        if cv2.mean(cv2.absdiff(band, background), weights.roi)[0] < SAME_FRAME_DN:
            raise ClassifyError("the --background image is this very frame (they differ by under "
                                f"{SAME_FRAME_DN:g} DN in the ROI): it must show the scene without the object")
        return flat_field(band, weights.roi, background_band=background)
    size = 2 * (reach - 1) + 1

    def fitted_beyond(split: float) -> FlatField | None:
        background = ~settings.classifier.object_side(band, split)
        background = cv2.erode(background.astype(np.uint8), np.ones((size, size), np.uint8)) > 0
        return flat_field(band, weights.roi, background)

    found = fitted_beyond(threshold)
    if found is None and (settings.classifier.threshold != "otsu" or settings.classifier.tone_curve != "linear"):
        # the threshold classifies; where the light is uneven enough that it leaves too little background to
        # fit (a real photo's dim whites on the object's side of 150, or of Otsu's split in light), Otsu's split
        # of the band's values as they are finds the background the light is fitted to (worked out only then)
        split = otsu_level(np.bincount(band[weights.roi > 0], minlength=256))
        if split != threshold:
            found = fitted_beyond(split)
    return found


def _evened(raw_band: np.ndarray, weights: Weights, settings: LightSettings, memory: LightMemory, fresh: bool
            ) -> tuple[np.ndarray, float, FlatField | None, np.ndarray]:
    """The band to read the shares from (evened where the light is uneven), its threshold, the flat field
    applied, and its 2-D histogram (band value x weight level) over the ROI. The flat field and the levels
    from the classes' interiors are found afresh every LIGHT_REFRESH_FRAMES frames, when the weights were
    rebuilt, or when `fresh` (the light drifted); in between they are carried, as a steady camera's light is."""
    classifier = settings.classifier
    threshold = classifier.resolve_threshold(raw_band, weights.roi)
    band, light = raw_band, memory.light
    if settings.even_light:
        if fresh or light is None or light.weights is not weights or light.age >= LIGHT_REFRESH_FRAMES:
            raw_threshold, reach, start = threshold, INTERIOR_PX, INTERIOR_PX
            memory.fits += 1
            nearer = None
            for _ in range(2):  # again, the background kept as far from the edges as they are wide
                # where the deeper background holds too few cells for a surface (a chessboard's white squares
                # eroded by wide edges), the nearer one's flat field stands: no flat field at all left a real
                # photo's 25 % shading in the shares (Af +6.5 % instead of +0.2 %)
                found = nearer = _flat_field(raw_band, weights, raw_threshold, settings, reach) or nearer
                light = Light(weights, None if found is None else found.unevenness,
                              found if found is not None and found.needed else None)
                band, threshold = raw_band, raw_threshold
                if light.flat is not None:
                    band = light.flat.apply(raw_band)
                    threshold = classifier.resolve_threshold(band, weights.roi)
                light.levels, settled, before = interior_levels(band, weights.roi, threshold, classifier, start)
                if settled <= reach:
                    break
                reach, start = settled, before  # the last step is taken again on the evened band
            memory.light = light
        else:
            light.age += 1
            if light.flat is not None:
                band = light.flat.apply(raw_band)
                threshold = classifier.resolve_threshold(band, weights.roi)
    histogram = weights.histogram(band, weights.roi)
    return band, threshold, light.flat if settings.even_light else None, histogram


def _light_drifted(estimator: LevelEstimator, threshold: float, memory: LightMemory) -> bool:
    """Whether the carried flat field and levels no longer fit this frame: its background's level and spread
    as the histogram gives them (cheap) moved by more than 2 DN (or three level errors), or the spread grew
    by half (the light's shape changed), against the same figures of the frame they were found in."""
    light = memory.light
    if light is None or light.levels is None:
        return False
    now = estimator.at(threshold)
    if light.age == 0:  # found in this very frame: what later frames are held to
        light.seen_levels = now
        return False
    then = light.seen_levels
    if now is None or then is None:
        return now is not then
    return (abs(now.background - then.background) > max(2.0, 3 * light.levels.error("background"))
            or now.background_spread > 1.5 * then.background_spread + 1.0)


def interior_levels(band: np.ndarray, roi: np.ndarray, threshold: float, classifier: Classifier,
                    start: int = INTERIOR_PX) -> tuple[Levels | None, int, int]:
    """Both levels from the pixels at least `start` pixels inside their class (and the ROI), or deeper; the
    reach they were read at and the one before it. No edge pixel, blurred or not, pulls them towards each
    other, as it pulls a histogram's modes where an object is mostly edge (a bush's twigs under blur and
    noise: its level 2.4 DN off, Af +0.9 %). Where the edges are wider (turbid water, a DSLR's 7 px sd of
    blur) the levels still move as the interior shrinks (the bush's object level 57 DN at 3 px inside,
    40.2 at 18, truly 40): the reach grows by half until neither level moves away from the other class by
    more than twice its standard error. Where a class runs out of interior pixels (or the reach its
    limit) while a level still moved, the last move is added to that level's error: a deeper reading might
    have moved it as far again. None where a class has too small an interior even at `start` (twigs 1-3 px
    wide): the histogram's modes are used."""
    kind = classifier.object_side(band, threshold)
    inside = roi > 0
    classes = [(kind & inside).astype(np.uint8), (~kind & inside).astype(np.uint8)]
    levels = levels_inside(band, classes, start)
    reach = before = start
    if levels is None:
        return None, reach, before
    last_move = None
    while reach < MAX_INTERIOR_PX:
        deeper = min(MAX_INTERIOR_PX, int(np.ceil(reach * 1.5)))
        further = levels_inside(band, classes, deeper)
        if further is None:
            break
        if not _levels_moved(levels, further):
            last_move = None  # settled: a deeper reading agrees
            break
        last_move = (abs(further.object - levels.object), abs(further.background - levels.background))
        levels, before, reach = further, reach, deeper
    if last_move is not None:
        levels = replace(levels, object_error=math.hypot(levels.error("object"), last_move[0]),
                         background_error=math.hypot(levels.error("background"), last_move[1]))
    return replace(levels, tone_curve=classifier.tone_curve), reach, before


def levels_inside(band: np.ndarray, classes: list[np.ndarray], reach: int) -> Levels | None:
    """The object's and the background's levels from their classes' pixels `reach` pixels inside."""
    kernel = cv2.getStructuringElement(cv2.MORPH_RECT if reach > INTERIOR_PX else cv2.MORPH_ELLIPSE,
                                       (2 * reach + 1, 2 * reach + 1))
    found = []
    for members in classes:
        interior = cv2.erode(members, kernel)
        found.append(pure_level(cv2.calcHist([band], [0], interior, [256], [0, 256]).ravel()))
    if found[0] is None or found[1] is None:
        return None
    (obj, obj_spread, obj_error), (bg, bg_spread, bg_error) = found
    return Levels(obj, bg, obj_spread, bg_spread, object_error=obj_error, background_error=bg_error)


def _levels_moved(nearer: Levels, deeper: Levels) -> bool:
    """Whether either level moved, deeper inside its class, away from the other class by more than twice the two
    readings' error: a blurred edge only ever pulls a level towards the other class; a move the other way is
    the object's texture or the light (a dark leaf with a lighter midrib), which a deeper interior does not cure."""
    away = np.sign(nearer.background - nearer.object)  # the background's side of the object
    moves = {"object": (nearer.object - deeper.object) * away,
             "background": (deeper.background - nearer.background) * away}
    return any(moved > 2 * math.hypot(nearer.error(name), deeper.error(name)) for name, moved in moves.items())
