"""Safe image decoding: read PNG/JPEG dimensions from the header before decoding.

A decompression bomb (a small file that decodes to gigapixels) is refused from
its header alone, before ``cv2.imdecode`` allocates anything. Only PNG
(ISO/IEC 15948: the IHDR chunk follows the signature) and JPEG (ITU-T T.81:
the frame size sits in the first SOFn segment) are accepted.
"""

from __future__ import annotations

import struct

import cv2
import numpy as np
from numpy.typing import NDArray

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
# SOF markers carrying the frame size (not DHT C4, JPG C8, DAC CC)
_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}
_STANDALONE = {0x01, *range(0xD0, 0xD8)}


class ImageError(ValueError):
    """Not an image we accept, a corrupt one, or one that is too large."""

    def __init__(self, message: str, too_large: bool = False) -> None:
        super().__init__(message)
        self.too_large = too_large


def image_size(data: bytes) -> tuple[str, int, int]:
    """``(format, width_px, height_px)`` from a PNG or JPEG header, without decoding."""
    if data.startswith(_PNG_SIGNATURE):
        if len(data) < 24 or data[12:16] != b"IHDR":
            raise ImageError("corrupt PNG: no IHDR chunk after the signature")
        w, h = struct.unpack(">II", data[16:24])
        return "png", int(w), int(h)
    if data.startswith(b"\xff\xd8"):
        return ("jpeg", *_jpeg_size(data))
    raise ImageError("not a PNG or JPEG image")


def _jpeg_size(data: bytes) -> tuple[int, int]:
    i, n = 2, len(data)
    while i < n:
        if data[i] != 0xFF:
            raise ImageError("corrupt JPEG: expected a marker")
        while i < n and data[i] == 0xFF:  # fill bytes
            i += 1
        if i >= n:
            break
        marker = data[i]
        i += 1
        if marker in _STANDALONE:
            continue
        if marker in (0xD9, 0xDA):  # end of image / start of scan before any frame header
            break
        if i + 2 > n:
            break
        (length,) = struct.unpack(">H", data[i:i + 2])
        if length < 2:
            raise ImageError("corrupt JPEG: segment length below 2")
        if marker in _SOF:
            if i + 7 > n:
                break
            h, w = struct.unpack(">HH", data[i + 3:i + 7])
            return int(w), int(h)
        i += length
    raise ImageError("corrupt JPEG: no frame header (SOF) found")


def decode_image(data: bytes, max_pixels: int) -> NDArray[np.uint8]:
    """Decode a PNG/JPEG to 8-bit BGR after checking its header size against ``max_pixels``.

    16-bit and grey images become 8-bit BGR; a JPEG's EXIF orientation is applied
    (``cv2.IMREAD_COLOR``), so pixel coordinates are those of the image as a
    browser shows it.
    """
    fmt, w, h = image_size(data)
    if w <= 0 or h <= 0:
        raise ImageError(f"{fmt.upper()} header gives an empty image ({w}×{h})")
    if w * h > max_pixels:
        raise ImageError(f"{fmt.upper()} image of {w}×{h} = {w * h} pixels exceeds the limit "
                         f"of {max_pixels} pixels", too_large=True)
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    if img is None:
        raise ImageError(f"corrupt or truncated {fmt.upper()} image")
    # IMREAD_COLOR applies a JPEG's EXIF orientation (as browsers do when they show it),
    # so an orientation of 5-8 swaps the header's width and height
    if (img.shape[1], img.shape[0]) not in ((w, h), (h, w)):
        raise ImageError(f"{fmt.upper()} decodes to {img.shape[1]}×{img.shape[0]}, "
                         f"not the {w}×{h} of its header")
    return np.asarray(img, dtype=np.uint8)
