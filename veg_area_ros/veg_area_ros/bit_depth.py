"""16-bit frames (files, image messages) read as the 8-bit grey levels the measurement works on.

A scientific camera's 10-, 12- or 14-bit values in a 16-bit container read as 16-bit data leave 4 to 64 grey
levels (a 12-bit frame read as 'clipped shadows' throughout, a 10-bit one found no targets), so the depth is
taken as the smallest of SENSOR_DEPTHS that holds the values. A single file can only be judged on its own
values; a stream of frames (a camera's messages, a bag) carries the deepest depth it has shown in a
`StreamDepth`, so a darker frame of the same camera is not read brighter than the frames before it.

No ROS here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SENSOR_DEPTHS = (10, 12, 14, 16)  # bits a camera's 16-bit frame may hold


@dataclass
class StreamDepth:
    """What a stream of 16-bit frames carries from frame to frame: the deepest depth its values have shown
    (8 until a frame's values pass 255) and the largest value behind it."""
    bits: int = 8
    top: int = 0


def depth_holding(top: int) -> int:
    """The smallest sensor depth that holds a largest value of `top` (8 when it fits in 8 bits)."""
    return 8 if top < 256 else next(d for d in SENSOR_DEPTHS if top < 2**d)


def to_8_bit(image: np.ndarray, stream: StreamDepth | None = None) -> tuple[np.ndarray, str]:
    """A 16-bit image as 8 bits, and what was assumed ('' when nothing was): the low bits dropped, as OpenCV's
    own 16-to-8 bits, at the depth its values use (at least the `stream`'s so far, which it then holds). A depth
    of 16 is said nowhere: that is how OpenCV and cv_bridge read a 16-bit image."""
    if image.dtype == np.uint8:
        return image, ""
    top = int(image.max()) if image.size else 0  # one pass over a 10 MP frame, not one per use
    depth = depth_holding(top)
    if stream is not None:
        depth = stream.bits = max(stream.bits, depth)
        stream.top = max(stream.top, top)
    scaled = (image >> (depth - 8)).astype(np.uint8)
    if depth == 16:
        return scaled, ""
    if stream is None:
        return scaled, (f"16-bit image read as {depth}-bit data: its values reach {top}, so each is divided by "
                        f"{2 ** (depth - 8)} (not 256); a darker frame of the same camera would be read brighter")
    return scaled, (f"16-bit image read as {depth}-bit data: this stream's values have reached {stream.top} "
                    f"(this frame's {top}), so each is divided by {2 ** (depth - 8)} (not 256); frames "
                    "before a brighter one of a deeper sensor were read brighter")
