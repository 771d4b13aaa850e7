"""Glare, part of stage 5 (the checks): a sheen or specular reflection in the ROI, found as pixels brighter than
the brighter class's level, and what it may have done to Af, read from the pixels it left between the levels.

It exists apart from the other checks because glare is the one check that reads the frame twice over (its
bright pixels, then the pixels between the levels away from every edge) and the one whose rule was measured on
its own photos: glossy prints' sheens and rendered ones. Takes the lit band, the object mask, the `Weights` and
the levels; gives the `glare` record of an `AreaResult` and its std term. Carries nothing from frame to frame.

No ROS here.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import cv2
import numpy as np

from .classify import BAND_VALUES, Classifier, Levels, in_edge_zone
from .markers import DetectedMarker
from .weights import Weights

if TYPE_CHECKING:
    from .area_result import AreaResult

# glare: pixels brighter than the brighter class's level by this share of the contrast (or this many of its
# spreads, where noise is larger), over this share of the ROI (real photos: a glossy print's sheen 0.6-1.1 % of
# the ROI, Af -1 to -2.5 %; sheen-free ones up to 0.08 %), or, near the object, over this share of its own pixels,
# so a small object in a large ROI is not let off (real photos: sheens 1.2-2.3 %, sheen-free ones up to 0.17 %;
# a rendered 90 DN spot 10 px wide on the cube, 0.08 % of the ROI, 0.9 % of the object, Af -2.8 %)
GLARE_CONTRAST, GLARE_SPREADS, GLARE_SHARE, GLARE_OBJECT_SHARE = 0.10, 4.0, 0.0025, 0.005
GLARE_NEAR = 0.25  # of the square root of the object's pixels: a marker's paper afar is not the object's sheen
MARKER_PAPER = 2.0  # a marker's white paper reaches this many times its own size about its centre: not glare
GLARE_WHOLE_PX, GLARE_ROW_STEP = 2_000_000, 4  # windows larger than this are read every fourth row for glare
# under glare, pixels between the levels farther than this (or the markers' edge width) from the object's edges
# are taken as lifted by it: a blurred edge's own pixels lie within it
GLARE_EDGE_REACH_PX = 2


def glare_in(band: np.ndarray, weights: Weights, levels: Levels | None, classifier: Classifier,
             markers: dict[int, DetectedMarker], mask: np.ndarray | None = None) -> dict | None:
    """A sheen or specular reflection in the ROI: pixels brighter than the brighter class's level by more than
    GLARE_CONTRAST of the contrast (and GLARE_SPREADS of that level's spread); it matters over GLARE_SHARE of
    the ROI, or near the object (`mask`, over the window) over GLARE_OBJECT_SHARE of the object's pixels. No
    pure surface sends more light than its level, so these are reflections; one that lifts the darker class (a
    glossy print's black, a wet leaf) turns part of it into the brighter one. Read in the evened band, so
    shading is not taken for it; the markers' white paper, which may well be whiter than the background, is
    left out. None where nothing is that bright, or the object is no grey level (an excess-green index)."""
    if levels is None or classifier.object == "green":
        return None
    bright_is_background = levels.background >= levels.object
    bright = max(levels.background, levels.object)
    spread = levels.background_spread if bright_is_background else levels.object_spread
    above = bright + max(GLARE_CONTRAST * abs(levels.background - levels.object), GLARE_SPREADS * spread)
    if cv2.minMaxLoc(band, weights.roi)[1] <= above:  # one pass where nothing is that bright (most frames)
        return None
    # every GLARE_ROW_STEP-th row of a large window (a sheen spans many rows): a 10 MP frame's check costs a
    # quarter; a small window is read whole
    step = GLARE_ROW_STEP if band.size > GLARE_WHOLE_PX else 1
    looked = weights.roi[::step]
    if markers:
        looked = looked.copy()
        offset = np.array([weights.window[1].start, weights.window[0].start], float)
        for marker in markers.values():
            paper = (marker.centre + MARKER_PAPER * (marker.corners - marker.centre) - offset) / [1.0, step]
            cv2.fillConvexPoly(looked, np.round(paper).astype(np.int32), 0)
    roi_pixels = cv2.countNonZero(looked)
    # the band is whole DN: over `above` is over its floor (cv2.compare would round the scalar)
    bright_pixels = cv2.bitwise_and(cv2.compare(band[::step], math.floor(above), cv2.CMP_GT), looked)
    over = cv2.countNonZero(bright_pixels)
    if not over or not roi_pixels:
        return None
    share = over / roi_pixels
    object_pixels = 0 if mask is None else cv2.countNonZero(mask)
    of_object = 0.0
    if object_pixels:  # in the object's bounding box grown by GLARE_NEAR of its size (rows read as above)
        reach = round(GLARE_NEAR * math.sqrt(object_pixels))
        x, y, w, h = cv2.boundingRect(mask)
        rows = slice(-(-max(0, y - reach) // step), -(-(y + h + reach) // step))
        of_object = cv2.countNonZero(bright_pixels[rows, max(0, x - reach):x + w + reach]) * step / object_pixels
    return {"share": float(share), "object_share": float(of_object), "above_dn": float(above),
            "matters": share >= GLARE_SHARE or of_object >= GLARE_OBJECT_SHARE,
            "reads": "low" if bright_is_background else "high"}


def lifted_read_as_brighter(band: np.ndarray, mask: np.ndarray, weights: Weights, factor: float,
                            result: AreaResult, reach: int) -> float:
    """What a sheen's lift of the darker class may have moved Af by (m²): the ROI's pixels between the two
    levels' outer EDGE_ZONE farther than `reach` px from the object's edges (no edge's blur explains them),
    each by the share of it read as the brighter class (sub-pixel) or wholly where it was read as that class
    (counted). Were they the darker class lifted, that much of it is lost to the brighter one; were they
    shading or texture, nothing is: a frame without glare is not read for them."""
    levels = result.levels
    low, high = sorted((levels.object, levels.background))
    between = in_edge_zone(BAND_VALUES, low, high).astype(np.uint8) * 255
    edges = cv2.morphologyEx(mask, cv2.MORPH_GRADIENT, np.ones((3, 3), np.uint8))
    near_edges = cv2.dilate(edges, np.ones((2 * reach + 1, 2 * reach + 1), np.uint8))
    away = cv2.bitwise_and(cv2.LUT(band, between), cv2.bitwise_and(weights.roi, cv2.bitwise_not(near_edges)))
    area_at = weights.histogram(band, away) @ weights.level_area * factor  # m² at each band value
    if result.subpixel_applied:
        fractions = levels.fractions()
        brighter = fractions if levels.object > levels.background else 1 - fractions
    else:
        brighter = (result.threshold < BAND_VALUES).astype(float)
    return float(area_at @ brighter)
