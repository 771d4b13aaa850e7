"""libjpeg's warnings caught per image while other threads decode and print (a Dask worker runs several
measurements in threads of one process): each image gets its own warning, no other line is taken for one or
lost, and stderr is where it was afterwards."""

from __future__ import annotations

import os
import threading
import time

import cv2
import numpy as np

from veg_area_ros.frames import _decode_jpeg, decode_image_file

OTHER_LINE = "another thread's progress line"


def _jpegs() -> tuple[bytes, bytes]:
    """A clean JPEG of a textured frame, and the same with 16 bytes before its end marker (libjpeg warns
    that bytes lie before its end marker and decodes it)."""
    rng = np.random.default_rng(7)
    frame = cv2.GaussianBlur(rng.integers(0, 256, (480, 640, 3), dtype=np.uint8), (5, 5), 0)
    clean = cv2.imencode(".jpg", frame)[1].tobytes()
    return clean, clean[:-2] + b"\x00" * 16 + b"\xff\xd9"


def test_each_image_gets_its_own_warning_while_threads_decode_and_print(capfd):
    clean, corrupt = _jpegs()
    assert _decode_jpeg(clean)[1] == ""
    warned = _decode_jpeg(corrupt)[1]
    assert warned.startswith("Corrupt JPEG data: ") and warned.endswith("extraneous bytes before marker 0xd9")
    capfd.readouterr()
    stderr_before = os.fstat(2)
    results: list[tuple[bool, str]] = []
    done = threading.Event()
    printed = 0

    def decode(seed: int) -> None:
        for k in range(40):
            is_corrupt = (k + seed) % 2 == 1
            image, warning = _decode_jpeg(corrupt if is_corrupt else clean)
            results.append((is_corrupt, warning if image is not None else "not decoded"))

    def chatter() -> None:
        nonlocal printed
        while not done.is_set():
            os.write(2, f"{OTHER_LINE}\n".encode())
            printed += 1
            time.sleep(0.0002)

    talker = threading.Thread(target=chatter)
    talker.start()
    decoders = [threading.Thread(target=decode, args=(seed,)) for seed in range(4)]
    for thread in decoders:
        thread.start()
    for thread in decoders:
        thread.join()
    done.set()
    talker.join()
    assert _decode_jpeg(clean)[1] == ""  # passes on a line that was still on its way when stderr was put back

    after = os.fstat(2)
    assert (after.st_dev, after.st_ino) == (stderr_before.st_dev, stderr_before.st_ino)
    assert len(results) == 160
    wrong = [(is_corrupt, warning) for is_corrupt, warning in results
             if (warning == warned)
             != is_corrupt]
    assert not wrong, wrong[:3]
    err = capfd.readouterr().err
    assert [line for line in err.splitlines() if line != OTHER_LINE] == []
    assert printed > 0 and err.count(OTHER_LINE) == printed  # every line of the other thread reached stderr
    assert "Corrupt JPEG" not in err


def test_a_corrupt_jpeg_file_is_still_refused_with_the_decoders_words():
    clean, corrupt = _jpegs()
    image, problem = decode_image_file(corrupt)
    assert image is None and "corrupt JPEG" in problem and "extraneous bytes" in problem
    image, problem = decode_image_file(clean)
    assert image is not None and problem == ""
