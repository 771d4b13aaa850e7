"""Damage inside a video that FFmpeg decodes: it conceals a damaged frame's blocks with guesses from other
frames and goes on, without an error OpenCV passes up; what it printed meanwhile (`decoder_messages`) says where.
The frames that refer to the damaged one, up to the next keyframe, carry the guess.

No ROS here.
"""

from __future__ import annotations

from pathlib import Path

import cv2

from .decoder_messages import FFMPEG_MESSAGE
from .video_container import Keyframes, keyframes

REORDER_MARGIN = 4  # frames past a keyframe (in decoding order) that may still be shown before it (B-frames)


# codecs whose every frame is a keyframe (Motion-JPEG, ProRes, DNxHD, FFV1, HuffYUV, raw): damage stays in its frame;
# a stream without a codec tag (Matroska's) is named by the first four letters of FFmpeg's codec name
INTRA_ONLY_FOURCCS = {b"MJPG", b"AVDJ", b"DMB1", b"JPEG", b"MJPE", b"APCH", b"APCN", b"APCS", b"APCO", b"AP4H", b"AP4X",
                      b"PROR", b"AVDN", b"AVDH", b"DNXH", b"FFV1", b"HFYU", b"FFVH", b"HUFF", b"RAWV", b"I420", b"YUY2",
                      b"UYVY"}


def one_thread_capture(path: str, api: int = cv2.CAP_ANY) -> cv2.VideoCapture:
    """OpenCV's capture of a video decoding with one thread: FFmpeg's words about a damaged frame are then printed
    while that frame is read (`decoder_messages`); a plain one where the backend takes no thread count."""
    capture = cv2.VideoCapture(path, api, [cv2.CAP_PROP_N_THREADS, 1])
    return capture if capture.isOpened() else cv2.VideoCapture(path, api)


def video_keyframes(path: Path, capture: cv2.VideoCapture) -> Keyframes | None:
    """Where a video's keyframes are: every frame for an intra-only codec, else its MP4 or QuickTime sync sample
    table; None where neither tells."""
    fourcc = int(capture.get(cv2.CAP_PROP_FOURCC)) & 0xFFFFFFFF
    if fourcc.to_bytes(4, "little").upper() in INTRA_ONLY_FOURCCS:
        return Keyframes(None, reordered=False)
    return keyframes(path)


class VideoDamage:
    """What FFmpeg reported while decoding a video (it conceals a damaged frame's blocks with guesses from
    other frames and goes on, without an error OpenCV passes up): the frames from the report up to the next
    keyframe, which refer to the damaged one, each say it. Keyframes are known from an MP4 or QuickTime file's
    sync sample table; in other containers every frame after the report says it."""

    def __init__(self, keys: Keyframes | None) -> None:
        self.keys = keys
        self.said = ""
        self.since = 0
        self.where = ""
        self.until: int | None = 0  # the first frame clear of it (None: none is known to be)

    def note(self, frame: int, said: str, seeking: bool = False) -> tuple[str, ...]:
        """The note for `frame`, given what the decoder printed while reading it (`seeking`: while decoding the
        frames before it to seek there); () where none applies."""
        if said and seeking and self.intra_only:
            return ()  # a frame before this one, which nothing after it refers to
        if said:
            self.said, self.since = said, frame
            self.where = f"while seeking to frame {frame}" if seeking else f"at frame {frame}"
            key = self.keys.next_after(frame) if self.keys is not None else None
            self.until = None if key is None else key + (REORDER_MARGIN if self.keys.reordered else 0)
        if not self.said or (self.until is not None and frame >= self.until):
            return ()
        reach = ("it and every later frame of this video carry the guess (its container lists no keyframes)"
                 if self.until is None else f"frames {self.since} to {self.until - 1} carry the guess (up to the next "
                 "keyframe)")
        return (f"video damaged: the decoder reported an error {self.where} ({decoder_words(self.said)}) "
                f"and filled the damaged blocks with guesses from other frames; {reach}, so Af may be off: look at "
                "the overlay",)

    @property
    def intra_only(self) -> bool:
        """Every frame a keyframe: damage stays in its frame, which a decoder fills with no guess."""
        return self.keys is not None and self.keys.frames is None


def decoder_words(said: str) -> str:
    """FFmpeg's first message without the component's address: 'h264: error while decoding MB 3 7'."""
    text = said.strip()
    match = FFMPEG_MESSAGE.match(text)
    if match is None:
        return f"FFmpeg: {text[:120]}"
    following = FFMPEG_MESSAGE.search(text, match.end())
    words = text[match.end():following.start() if following else None].strip()
    return f"{match.group(0)[1:].split(' @ ')[0]}: {words[:120]}"
