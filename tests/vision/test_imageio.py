"""Header-checked decoding: sizes read from PNG/JPEG headers, bombs refused before decoding."""

from __future__ import annotations

import struct
import zlib

import cv2
import numpy as np
import pytest

from vision.imageio import ImageError, decode_image, image_size


def _img(w: int = 37, h: int = 23) -> np.ndarray:
    rng = np.random.default_rng(0)
    return rng.integers(0, 255, (h, w, 3), dtype=np.uint8)


@pytest.mark.parametrize("ext,params", [(".png", []), (".jpg", []),
                                        (".jpg", [cv2.IMWRITE_JPEG_PROGRESSIVE, 1])])
def test_size_from_header(ext: str, params: list[int]) -> None:
    ok, buf = cv2.imencode(ext, _img(), params)
    assert ok
    fmt, w, h = image_size(buf.tobytes())
    assert (w, h) == (37, 23) and fmt in ("png", "jpeg")
    assert decode_image(buf.tobytes(), 10_000).shape == (23, 37, 3)


def test_png_bomb_refused_without_decoding() -> None:
    ihdr = struct.pack(">IIBBBBB", 200_000, 200_000, 8, 2, 0, 0, 0)
    data = (b"\x89PNG\r\n\x1a\n" + struct.pack(">I", 13) + b"IHDR" + ihdr
            + struct.pack(">I", zlib.crc32(b"IHDR" + ihdr)))
    assert image_size(data) == ("png", 200_000, 200_000)
    with pytest.raises(ImageError) as exc:
        decode_image(data, 40_000_000)
    assert exc.value.too_large and "200000" in str(exc.value)


def test_jpeg_limit_checked_before_decoding() -> None:
    ok, buf = cv2.imencode(".jpg", _img(100, 100))
    with pytest.raises(ImageError) as exc:
        decode_image(buf.tobytes(), 9_999)
    assert exc.value.too_large


@pytest.mark.parametrize("data,word", [
    (b"GIF89a....", "not a PNG or JPEG"),
    (b"", "not a PNG or JPEG"),
    (b"\x89PNG\r\n\x1a\n\x00\x00", "IHDR"),
    (b"\xff\xd8\xff\xe0\x00\x10JFIF\x00", "SOF"),
    (b"\xff\xd8\x00\x00", "marker"),
])
def test_not_images_and_corrupt_headers(data: bytes, word: str) -> None:
    with pytest.raises(ImageError, match=word):
        decode_image(data, 1_000_000)


def test_truncated_png_body_is_an_image_error() -> None:
    ok, buf = cv2.imencode(".png", _img())
    with pytest.raises(ImageError):
        decode_image(buf.tobytes()[:40], 1_000_000)
