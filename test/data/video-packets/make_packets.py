"""Writes the H.264, H.265 and AV1 packet streams beside this file (PyAV's libx264, libx265, libsvtav1; by hand:
`pip install av numpy` in a scratch venv, then `python make_packets.py [name ...]`). Each frame is a grey 160x120 image
with a bright bar at x = 10 + 8 * (its capture number), so a decoded frame tells which capture it is.

Each file is a run of packets in decode order, each as <uint32 capture number (pts)> <uint32 length> <bytes>
(H.264 and H.265 in Annex B, AV1 in its low-overhead form).
"""

import struct
import sys
from fractions import Fraction
from pathlib import Path

import av
import numpy as np

FRAMES = 12
HERE = Path(__file__).parent


def bar_frame(number: int) -> np.ndarray:
    image = np.full((120, 160, 3), 60, np.uint8)
    image[20:100, 10 + 8 * number:18 + 8 * number] = 230
    return image


def encode(codec: str, options: dict[str, str], name: str, frames: int = FRAMES) -> None:
    context = av.CodecContext.create(codec, "w")
    context.width, context.height, context.pix_fmt = 160, 120, "yuv420p"
    context.time_base, context.framerate = Fraction(1, 10), 10
    context.options = options
    packets = []
    for number in range(frames):
        frame = av.VideoFrame.from_ndarray(bar_frame(number), format="rgb24").reformat(format="yuv420p")
        frame.pts = number
        packets += context.encode(frame)
    packets += context.encode(None)
    with (HERE / name).open("wb") as file:
        for packet in packets:
            data = bytes(packet)
            file.write(struct.pack("<II", packet.pts, len(data)) + data)


STREAMS = {
    "h264_no_b.bin": ("libx264", {"bf": "0", "g": "6", "keyint_min": "6", "sc_threshold": "0", "crf": "18"}),
    "h264_b.bin": ("libx264", {"bf": "2", "g": "6", "keyint_min": "6", "sc_threshold": "0", "crf": "18",
                               "x264-params": "b-adapt=0"}),
    # open GOPs: the keyframes after the first are I-frames with a recovery point, not IDRs (18 frames: two)
    "h264_open_gop.bin": ("libx264", {"bf": "2", "g": "6", "keyint_min": "6", "sc_threshold": "0", "crf": "18",
                                      "x264-params": "b-adapt=0:open-gop=1"}, 18),
    "hevc_open_gop.bin": ("libx265", {"x265-params": "keyint=6:min-keyint=6:bframes=2:b-adapt=0:open-gop=1:"
                                                     "scenecut=0:log-level=error", "crf": "18"}),
    "av1.bin": ("libsvtav1", {"g": "6", "preset": "8", "crf": "30"}),  # no AV1 decoder in OpenCV's wheel
}

if __name__ == "__main__":  # python make_packets.py [name ...]: those streams only (else all)
    for name in sys.argv[1:] or STREAMS:
        codec, options, *frames = STREAMS[name]
        encode(codec, options, name, *frames)
