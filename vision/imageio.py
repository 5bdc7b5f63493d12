"""Safe image decoding: read PNG/JPEG dimensions from the header before decoding.

A decompression bomb (a small file that decodes to gigapixels) is refused from
its header alone, before anything is decoded. Only PNG (ISO/IEC 15948: the IHDR chunk
follows the signature) and JPEG (ITU-T T.81: the frame size sits in the first SOFn
segment) are accepted. A damaged JPEG is refused too (:func:`_decode_jpeg`): libjpeg
decodes around bytes lost or altered in its entropy-coded data with no more than a
warning on stderr, and ``cv2.imdecode`` gives no signal of it.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from typing import Any

import cv2
import numpy as np
import simplejpeg
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


def _jpeg_segments(data: bytes) -> Iterator[tuple[int, int, int]]:
    """The marker segments before the first scan, as ``(marker, start, end)`` of each
    payload (after its length field; ``end`` may pass the data's end when it is cut)."""
    i, n = 2, len(data)
    while i < n:
        if data[i] != 0xFF:
            raise ImageError("corrupt JPEG: expected a marker")
        while i < n and data[i] == 0xFF:  # fill bytes
            i += 1
        if i >= n:
            return
        marker = data[i]
        i += 1
        if marker in _STANDALONE:
            continue
        if marker in (0xD9, 0xDA) or i + 2 > n:  # end of image / start of scan
            return
        (length,) = struct.unpack(">H", data[i:i + 2])
        if length < 2:
            raise ImageError("corrupt JPEG: segment length below 2")
        yield marker, i + 2, i + length
        i += length


def _jpeg_size(data: bytes) -> tuple[int, int]:
    for marker, start, _ in _jpeg_segments(data):
        if marker in _SOF:
            if start + 5 > len(data):
                break
            h, w = struct.unpack(">HH", data[start + 1:start + 5])
            return int(w), int(h)
    raise ImageError("corrupt JPEG: no frame header (SOF) found")


_EXIF_ORIENTATION_TAG = 0x0112


def _tiff_orientation(tiff: bytes) -> int:
    """The orientation (1–8; 1 when absent or unreadable) in an EXIF TIFF structure: the
    tag 0x0112 of its first directory (CIPA DC-008, the EXIF 2.3 standard, §4.6.4)."""
    order = {b"II": "<", b"MM": ">"}.get(tiff[:2])
    if order is None or len(tiff) < 8:
        return 1
    (ifd,) = struct.unpack(order + "I", tiff[4:8])
    if ifd + 2 > len(tiff):
        return 1
    (count,) = struct.unpack(order + "H", tiff[ifd:ifd + 2])
    for k in range(count):
        entry = tiff[ifd + 2 + 12 * k:ifd + 14 + 12 * k]
        if len(entry) < 12:
            return 1
        tag, kind = struct.unpack(order + "HH", entry[:4])
        if tag == _EXIF_ORIENTATION_TAG and kind in (3, 4):  # SHORT, or LONG as some
            # writers store it (OpenCV reads both); in the value field
            fmt, size = ("H", 2) if kind == 3 else ("I", 4)
            (value,) = struct.unpack(order + fmt, entry[8:8 + size])
            return int(value) if 1 <= value <= 8 else 1
    return 1


def _exif_orientation(data: bytes) -> int:
    """A JPEG's EXIF orientation (1–8; 1, as stored, when it has none or it is unreadable),
    from the TIFF structure in its APP1 ``Exif`` segment."""
    for marker, start, end in _jpeg_segments(data):
        if marker == 0xE1 and data[start:start + 6] == b"Exif\x00\x00":
            return _tiff_orientation(data[start + 6:end])
    return 1


def _png_orientation(data: bytes) -> int:
    """A PNG's EXIF orientation (1–8; 1 when it has none): the TIFF structure of its
    ``eXIf`` chunk (PNG Third Edition, §11.3.3.8), wherever the chunk lies."""
    i = 8
    while i + 8 <= len(data):
        (length,) = struct.unpack(">I", data[i:i + 4])
        kind = data[i + 4:i + 8]
        if kind == b"eXIf":
            return _tiff_orientation(data[i + 8:i + 8 + length])
        if kind == b"IEND":
            break
        i += 12 + length
    return 1


def _oriented(img: NDArray[Any], orientation: int) -> NDArray[Any]:
    """The stored raster turned as EXIF ``orientation`` asks for it to be shown (as browsers
    and ``cv2.IMREAD_COLOR`` do): 2 mirrored, 3 turned 180°, 4 flipped, 5 transposed, 6
    turned 90° clockwise, 7 transposed the other way, 8 turned 90° anticlockwise."""
    if orientation == 2:
        return cv2.flip(img, 1)
    if orientation == 3:
        return cv2.rotate(img, cv2.ROTATE_180)
    if orientation == 4:
        return cv2.flip(img, 0)
    if orientation == 5:
        return cv2.transpose(img)
    if orientation == 6:
        return cv2.rotate(img, cv2.ROTATE_90_CLOCKWISE)
    if orientation == 7:
        return cv2.rotate(cv2.transpose(img), cv2.ROTATE_180)
    if orientation == 8:
        return cv2.rotate(img, cv2.ROTATE_90_COUNTERCLOCKWISE)
    return img


#: libjpeg's warnings (jerror.h) that say the entropy-coded data is damaged or cut: bytes
#: lost (JWRN_HIT_MARKER, JWRN_MUST_RESYNC), altered (JWRN_HUFF_BAD_CODE,
#: JWRN_ARITH_BAD_CODE, JWRN_BOGUS_PROGRESSION, JWRN_NOT_SEQUENTIAL), added
#: (JWRN_EXTRANEOUS_DATA) or the file cut (JWRN_JPEG_EOF). Its other warnings are about
#: metadata (JWRN_JFIF_MAJOR, JWRN_ADOBE_XFORM, JWRN_BOGUS_ICC, the thumbnail's size).
_JPEG_DAMAGE = ("premature end", "bad huffman code", "bad arithmetic code", "instead of rst",
                "extraneous bytes", "inconsistent progression", "invalid sos parameters")


def _decode_jpeg(data: bytes) -> NDArray[np.uint8]:
    """A JPEG → 8-bit BGR (grey and CMYK converted), its EXIF orientation applied; a damaged
    one is an :class:`ImageError` naming what libjpeg found.

    Decoded by libjpeg-turbo through ``simplejpeg`` with ``strict=True``, which makes
    libjpeg's warnings errors: bytes lost or altered mid-stream ("Corrupt JPEG data:
    premature end of data segment", "… extraneous bytes before marker", "bad Huffman
    code") and a file cut short ("Premature end of JPEG file"). Without it libjpeg decodes
    around the damage — the rest of the frame grey, or its blocks shifted — which
    ``cv2.imdecode`` returns as a whole frame. The same library's pixels as
    ``cv2.imdecode`` (identical on every real frame of ``tests/data/real-sky``), in about
    half its time. Bytes after the end-of-image marker, which some cameras append, are
    not read: such a file is whole. A bit flipped in the entropy-coded data that still
    decodes as valid codes is no damage any decoder can see (JPEG has no checksum). A
    warning about metadata only (:data:`_JPEG_DAMAGE` names the others) is no damage."""
    def damage(exc: ValueError) -> bool:
        return any(words in str(exc).lower() for words in _JPEG_DAMAGE)

    try:
        img = simplejpeg.decode_jpeg(data, colorspace="BGR", strict=True)
    except ValueError as exc:
        if damage(exc):
            raise ImageError(f"corrupt or truncated JPEG image: {exc}") from None
        # a warning about the file's metadata (a JFIF revision 2.01, an Adobe transform
        # code, an ICC chunk) leaves its pixels whole, but simplejpeg refuses it strict or
        # not, and stops at that first warning: the scan is checked once more without the
        # segments that warn (a metadata warning hid damaged data: a reviewer), and the
        # pixels are OpenCV's (the same libjpeg-turbo), turned by the one EXIF rule here
        try:
            simplejpeg.decode_jpeg(_without_metadata(data), colorspace="BGR", strict=True)
        except ValueError as again:
            if damage(again):
                raise ImageError(f"corrupt or truncated JPEG image: {again}") from None
        img = cv2.imdecode(np.frombuffer(data, np.uint8),
                           cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)
        if img is None:
            raise ImageError(f"unreadable JPEG image: {exc}") from None
    return np.asarray(_oriented(img, _exif_orientation(data)), dtype=np.uint8)


def _without_metadata(data: bytes) -> bytes:
    """The JPEG without its APP0 (JFIF), APP2 (ICC) and APP14 (Adobe) segments, whose
    contents make libjpeg warn without touching the scan."""
    out, last = bytearray(data[:2]), 2
    for marker, start, end in _jpeg_segments(data):
        out += data[last:start - 4]  # the marker and the length field before the payload
        if marker not in (0xE0, 0xE2, 0xEE):
            out += data[start - 4:end]
        last = end
    return bytes(out + data[last:])


def _png_chunks_before_data(data: bytes) -> dict[bytes, bytes]:
    """The chunks from the IHDR up to the first IDAT (``sBIT``, ``tRNS`` …) by kind."""
    chunks, i = {}, 8
    while i + 8 <= len(data):
        (length,) = struct.unpack(">I", data[i:i + 4])
        kind = data[i + 4:i + 8]
        if kind == b"IDAT":
            break
        chunks[kind] = data[i + 8:i + 8 + length]
        i += 12 + length
    return chunks


def _transparent_colour(raw: NDArray[Any], colour_type: int, trns: bytes) -> NDArray[Any]:
    """A grey or RGB PNG's ``tRNS`` colour (one value, transparent) as an alpha channel
    (the decoder expands a palette's itself, not these): ``raw`` with alpha appended."""
    if raw.ndim == 3 and raw.shape[2] in (2, 4):
        return raw  # expanded already
    full = 65535 if raw.dtype == np.uint16 else 255
    if colour_type == 0 and len(trns) >= 2:
        clear = raw == struct.unpack(">H", trns[:2])[0]
    elif colour_type == 2 and len(trns) >= 6 and raw.ndim == 3:
        r, g, b = struct.unpack(">HHH", trns[:6])
        clear = (raw[..., 2] == r) & (raw[..., 1] == g) & (raw[..., 0] == b)  # BGR order
    else:
        return raw
    alpha = np.where(clear, 0, full).astype(raw.dtype)
    return np.dstack([raw if raw.ndim == 3 else raw[..., None], alpha])


def _to_bgr8(raw: NDArray[Any], scaled: bool) -> NDArray[np.uint8]:
    """A PNG decoded as stored (8/16 bits, grey or colour, with or without alpha) → 8-bit
    BGR, its samples by :func:`to_8bit` (``scaled``: an ``sBIT`` chunk says the camera's
    depth). Alpha (a channel, or ``tRNS`` expanded by the decoder) is composited onto black:
    a transparent corner outside a fisheye's image circle is no light, not the white its
    colour says."""
    arr = raw if raw.ndim == 3 else raw[..., None]
    alpha = arr[..., -1] if arr.shape[2] in (2, 4) else None
    colour = arr[..., :-1] if alpha is not None else arr
    if colour.shape[2] == 1:
        colour = cv2.cvtColor(np.ascontiguousarray(colour), cv2.COLOR_GRAY2BGR)
    full = 65535 if raw.dtype == np.uint16 else 255
    if alpha is not None:
        a = cv2.merge([alpha] * 3)
        colour = cv2.multiply(np.ascontiguousarray(colour), a, scale=1.0 / full)
    # shifted in place (copy=False): 16-bit frames are large, and this one is ours
    return to_8bit(np.ascontiguousarray(colour), scaled, copy=False)


def to_8bit(image: NDArray[Any], scaled: bool = False, copy: bool = True
            ) -> NDArray[np.uint8]:
    """A frame's samples as 8-bit ones, by the one rule of the service's decoding
    (:func:`_to_bgr8`) and of the library's detection (``vision.detect.detect_robust``,
    ``vision.fov.to_gray``). 8 bits as given. 16 bits: a PNG holds its samples scaled to the
    full 16 bits, as the format asks (``scaled``: its ``sBIT`` chunk says so), so its top
    byte; without ``sBIT`` the data's depth is the smallest of 10, 12, 14 and 16 bits that
    holds its brightest value: machine-vision cameras write their 10-, 12- or 14-bit
    sensor's samples unscaled (a 12-bit frame is 0–4095), and the top byte alone made such
    a frame almost black (0–15 for 12 bits, 0–63 for 14: no sun; a tester's finding), so its
    saturation is 255 here, as the sensor's was. A frame with a value above 14 bits is
    full-range 16-bit data and keeps its top byte. The price: a true 16-bit frame with
    nothing above a quarter of its range (16383) is read as 14-bit data, four times
    brighter, its brightest patch near 255: the content cannot tell the two apart, and a
    PNG that means its full range can say so with ``sBIT``. Floats: 0–1 when none is above
    1, else 0–255, clipped; one above 255 is refused (a linear frame in its sensor's units was
    clipped to white before). The detection read a 16-bit array by its top byte alone, and ran
    its colour tests (the white core of a large glare) on 8-bit frames only: the Wolf
    frames × 257 lay up to 20 px farther from their labels than the same frames at 8 bits.
    ``copy=False``: a 16-bit frame the caller no longer needs is shifted in place."""
    img = np.asarray(image)
    if img.dtype == np.uint8:
        return img
    if img.dtype == np.uint16:
        brightest = int(img.max()).bit_length() if img.size else 0
        bits = 16 if scaled or brightest > 14 else max(10, brightest + brightest % 2)
        shifted = np.right_shift(img, bits - 8, out=None if copy else img)
        np.minimum(shifted, 255, out=shifted)
        return np.ascontiguousarray(shifted, dtype=np.uint8)
    if np.issubdtype(img.dtype, np.floating):
        top = float(img.max()) if img.size else 0.0
        if not top <= 255.0:  # NaN too: a raw or linear frame's scale cannot be guessed
            raise ValueError(f"a float frame's samples must lie in 0–1 or 0–255; its largest "
                             f"is {top:g}: scale it, or pass its integer samples")
        return np.clip(img * (255.0 if top <= 1.0 else 1.0), 0, 255).astype(np.uint8)
    raise ValueError(f"unsupported image dtype {img.dtype}: 8- or 16-bit integers or floats")


def decode_image(data: bytes, max_pixels: int) -> NDArray[np.uint8]:
    """Decode a PNG/JPEG to 8-bit BGR after checking its header size against ``max_pixels``.

    Grey images become BGR; a 16-bit PNG is brought to 8 bits by its data's depth and an
    alpha channel is composited onto black (:func:`_to_bgr8`); the EXIF orientation of a JPEG
    (:func:`_decode_jpeg`) and of a PNG of any depth (its ``eXIf`` chunk) is applied by
    :func:`_oriented`, so pixel coordinates are those of the image as a browser shows it. A
    damaged JPEG is an :class:`ImageError`.
    """
    fmt, w, h = image_size(data)
    if w <= 0 or h <= 0:
        raise ImageError(f"{fmt.upper()} header gives an empty image ({w}×{h})")
    if w * h > max_pixels:
        raise ImageError(f"{fmt.upper()} image of {w}×{h} = {w * h} pixels exceeds the limit "
                         f"of {max_pixels} pixels", too_large=True)
    # a PNG of 16 bits (IHDR bit depth), with alpha (colour type 4 or 6) or a transparent
    # colour (tRNS: a palette's or a grey/RGB value) is read as stored
    chunks = _png_chunks_before_data(data) if fmt == "png" else {}
    as_stored = fmt == "png" and len(data) > 25 and (
        data[24] == 16 or data[25] in (4, 6) or b"tRNS" in chunks)
    img: NDArray[Any] | None
    if fmt == "jpeg":
        img = _decode_jpeg(data)
    else:
        buf = np.frombuffer(data, np.uint8)
        img = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED if as_stored
                           else cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)
    if img is None:
        raise ImageError(f"corrupt or truncated {fmt.upper()} image")
    if as_stored:
        if b"tRNS" in chunks:
            img = _transparent_colour(img, data[25], chunks[b"tRNS"])
        img = _to_bgr8(img, b"sBIT" in chunks)
    if fmt == "png":
        # one EXIF rule for every PNG: OpenCV applied an 8-bit PNG's orientation and not
        # that of a PNG read as stored (16 bits, alpha), so one frame came out turned or not
        img = _oriented(img, _png_orientation(data))
    # a JPEG's EXIF orientation (as browsers apply it when they show it) of 5-8 swaps the
    # header's width and height
    if (img.shape[1], img.shape[0]) not in ((w, h), (h, w)):
        raise ImageError(f"{fmt.upper()} decodes to {img.shape[1]}×{img.shape[0]}, "
                         f"not the {w}×{h} of its header")
    return np.asarray(img, dtype=np.uint8)
