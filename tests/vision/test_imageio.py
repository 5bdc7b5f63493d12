"""Header-checked decoding: sizes read from PNG/JPEG headers, bombs refused before decoding."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

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


def _with_exif_orientation(jpeg: bytes, orientation: int, long: bool = False) -> bytes:
    """Insert an APP1 Exif segment (TIFF, one IFD entry 0x0112) after SOI: big-endian
    SHORT, or (``long``) little-endian LONG as some writers store it."""
    if long:
        ifd = struct.pack("<H", 1) + struct.pack("<HHII", 0x0112, 4, 1, orientation)
        tiff = b"II\x2a\x00\x08\x00\x00\x00" + ifd + struct.pack("<I", 0)
    else:
        ifd = struct.pack(">H", 1) + struct.pack(">HHIHH", 0x0112, 3, 1, orientation, 0)
        tiff = b"MM\x00\x2a\x00\x00\x00\x08" + ifd + struct.pack(">I", 0)
    app1 = b"Exif\x00\x00" + tiff
    return jpeg[:2] + b"\xff\xe1" + struct.pack(">H", len(app1) + 2) + app1 + jpeg[2:]


def test_exif_rotated_jpeg_decodes_as_shown() -> None:
    """Orientation 6 (turn 90° clockwise to show): a 60×40 raster is shown 40 wide, 60 high."""
    img = np.full((40, 60, 3), 100, np.uint8)
    img[2:8, 2:8] = 255  # top-left of the raster → top-right once shown
    ok, buf = cv2.imencode(".jpg", img)
    out = decode_image(_with_exif_orientation(buf.tobytes(), 6), 10_000)
    assert out.shape == (60, 40, 3)
    assert out[5, 40 - 6].min() > 200 and out[5, 5].max() < 150


@pytest.mark.parametrize("shape,dtype", [((1, 1, 3), np.uint8), ((30, 20), np.uint8),
                                         ((30, 20, 3), np.uint16), ((30, 20, 4), np.uint8)])
def test_odd_pngs_decode_to_8bit_bgr(shape: tuple[int, ...], dtype: type) -> None:
    ok, buf = cv2.imencode(".png", np.full(shape, np.iinfo(dtype).max, dtype))
    out = decode_image(buf.tobytes(), 10_000)
    assert out.dtype == np.uint8 and out.shape == (shape[0], shape[1], 3)
    assert out.min() == 255


def _real_frame() -> np.ndarray:
    path = (Path(__file__).parents[1] / "data" / "real-sky"
            / "Wettermast_20160615_125430UTCp1_sunrow1306_suncol1076.jpg")
    return cv2.imread(str(path), cv2.IMREAD_COLOR)


def test_a_12_bit_png_and_a_transparent_border_find_the_same_sun() -> None:
    """A camera's 12-bit samples stored in a 16-bit PNG, and a frame whose outside of the
    image circle is transparent white: the sun is found where the 8-bit JPEG puts it
    (before, the 12-bit frame decoded to its top byte, 0–15, and found no sun; the white
    corners hid the image circle)."""
    from vision.detect import detect_robust

    frame = _real_frame()
    ref = detect_robust(frame)
    assert ref.sun_found and ref.centroid_px is not None
    twelve = (frame.astype(np.int64) * 4095 // 255).astype(np.uint16)
    ok, png12 = cv2.imencode(".png", twelve)
    out12 = decode_image(png12.tobytes(), 10**8)
    assert np.abs(out12.astype(int) - frame).max() <= 1
    h, w = frame.shape[:2]
    yy, xx = np.mgrid[:h, :w]
    outside = (xx - w / 2) ** 2 + (yy - h / 2) ** 2 > (0.5 * min(h, w) - 2) ** 2
    rgba = np.dstack([frame, np.full((h, w), 255, np.uint8)])
    rgba[outside] = (255, 255, 255, 0)
    ok, png_a = cv2.imencode(".png", rgba)
    out_a = decode_image(png_a.tobytes(), 10**8)
    assert out_a[0, 0].max() == 0 and (out_a[~outside] == frame[~outside]).all()
    for out in (out12, out_a):
        got = detect_robust(out)
        assert got.sun_found and got.centroid_px is not None
        assert np.hypot(*np.subtract(got.centroid_px, ref.centroid_px)) < 1.0


def _chunk(kind: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))


def _png_of(w: int, depth: int, colour_type: int, row: bytes, extra: bytes = b"") -> bytes:
    """A one-row PNG written by hand (the chunks cv2.imencode does not write)."""
    ihdr = struct.pack(">IIBBBBB", w, 1, depth, colour_type, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + extra
            + _chunk(b"IDAT", zlib.compress(b"\x00" + row)) + _chunk(b"IEND", b""))


def test_a_16_bit_png_is_its_top_byte_unless_its_data_fit_12_bits() -> None:
    """The format scales a 12-bit camera's samples to 16 bits and says so in sBIT: the top
    byte (a reviewer's repro: sBIT read as a shift made it 16× too bright); unscaled 12-bit
    data (no sBIT, brightest ≤ 4095) saturate at 4095; a real 16-bit frame is not stretched
    by its brightest value (3000 of 65535 is 11, not 187)."""
    vals = (100, 1000, 2000, 4095)
    scaled = b"".join(struct.pack(">H", (v << 4) | (v >> 8)) for v in vals)
    out = decode_image(_png_of(4, 16, 0, scaled, _chunk(b"sBIT", b"\x0c")), 100)
    assert out[0, :, 0].tolist() == [6, 62, 125, 255]
    raw12 = b"".join(struct.pack(">H", v) for v in vals)
    assert decode_image(_png_of(4, 16, 0, raw12), 100)[0, :, 0].tolist() == [6, 62, 125, 255]
    real16 = b"".join(struct.pack(">H", v) for v in (3000, 20000, 65535, 0))
    assert decode_image(_png_of(4, 16, 0, real16), 100)[0, :, 0].tolist() == [11, 78, 255, 0]


@pytest.mark.parametrize("colour_type,row,extra", [
    (3, b"\x00\x01", _chunk(b"PLTE", b"\xff\xff\xff\xff\x00\x00") + _chunk(b"tRNS", b"\x00")),
    (0, b"\xff\x80", _chunk(b"tRNS", b"\x00\xff")),
    (2, b"\xff\xff\xff\x10\x20\x30", _chunk(b"tRNS", b"\x00\xff\x00\xff\x00\xff")),
])
def test_a_transparent_colour_is_no_light(colour_type: int, row: bytes, extra: bytes) -> None:
    """tRNS (a palette's transparent entry, a grey or RGB value) is composited onto black,
    as an alpha channel is: transparent white corners read as white sky."""
    out = decode_image(_png_of(2, 8, colour_type, row, extra), 100)
    assert out[0, 0].tolist() == [0, 0, 0] and out[0, 1].max() > 0


REAL_SKY = Path(__file__).resolve().parents[1] / "data" / "real-sky"
WOLF = REAL_SKY / "Wolf_20160530_095000_UTCp1_sunrow1337_suncol634.jpg"


def _damaged(data: bytes) -> dict[str, bytes]:
    """A JPEG with its entropy-coded data damaged as a failing link or card leaves it:
    bytes lost mid-stream, bytes zeroed, the file cut short (even by its end marker alone)."""
    sos = data.find(b"\xff\xda")
    mid = sos + (len(data) - sos) // 2
    return {"100 bytes lost": data[:mid] + data[mid + 100:],
            "7 bytes lost": data[:mid] + data[mid + 7:],
            "64 bytes zeroed": data[:mid] + bytes(64) + data[mid + 64:],
            "cut at half": data[:mid],
            "end marker missing": data[:-2]}


@pytest.mark.parametrize("kind", ["100 bytes lost", "7 bytes lost", "64 bytes zeroed",
                                  "cut at half", "end marker missing"])
def test_a_damaged_jpeg_is_refused(kind: str) -> None:
    """Issue 24: a real frame with bytes lost or zeroed mid-stream decoded to a whole
    1920×1920 frame (libjpeg only warns; ``cv2.imdecode`` says nothing) and was analysed as
    such. Refused, with libjpeg's own words."""
    data = WOLF.read_bytes()
    damaged = _damaged(data)[kind]
    if kind not in ("cut at half", "end marker missing"):  # what cv2 did with it
        silent = cv2.imdecode(np.frombuffer(damaged, np.uint8), cv2.IMREAD_COLOR)
        assert silent is not None and silent.shape == (1920, 1920, 3)
    with pytest.raises(ImageError, match="corrupt or truncated JPEG image: (Corrupt JPEG data"
                                         "|Premature end of JPEG file)"):
        decode_image(damaged, 40_000_000)


def test_every_real_jpeg_decodes_as_opencv_does_and_trailing_bytes_are_read_as_whole() -> None:
    """Every real frame of tests/data/real-sky decodes, to the pixels ``cv2.imdecode`` gives
    (the same library, libjpeg-turbo); bytes after the end-of-image marker, which some
    cameras append (a vendor's trailer), leave a file whole."""
    paths = sorted(REAL_SKY.glob("*.jpg")) + sorted((REAL_SKY / "eurocontrol").glob("*.jpg"))
    assert len(paths) == 34
    for path in paths:
        data = path.read_bytes()
        ref = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
        assert np.array_equal(decode_image(data, 40_000_000), ref), path.name
    data = WOLF.read_bytes()
    assert np.array_equal(decode_image(data + b"\x00" * 64 + b"trailer", 40_000_000),
                          decode_image(data, 40_000_000))


@pytest.mark.parametrize("long", [False, True], ids=["short", "long"])
@pytest.mark.parametrize("orientation", range(1, 9))
def test_every_exif_orientation_as_opencv_applies_it(orientation: int, long: bool) -> None:
    """The eight EXIF orientations turn the raster as OpenCV's own EXIF reader does
    (``cv2.IMREAD_COLOR``), on a raster with no symmetry; also stored as a LONG (a
    reviewer's finding: it was read as no orientation)."""
    img = _img(60, 40)
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 100])
    data = _with_exif_orientation(buf.tobytes(), orientation, long)
    ref = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    assert np.array_equal(decode_image(data, 10_000), ref)


def test_a_warning_about_metadata_alone_is_no_damage() -> None:
    """A JFIF revision 2.01 makes libjpeg warn ("unknown JFIF revision number"), which the
    strict decoder raised as a corrupt file (a reviewer's finding); the pixels are whole."""
    data = bytearray(WOLF.read_bytes())
    at = data.find(b"JFIF\x00")
    assert at > 0
    data[at + 5:at + 7] = b"\x02\x01"
    ref = cv2.imdecode(np.frombuffer(bytes(data), np.uint8), cv2.IMREAD_COLOR)
    assert np.array_equal(decode_image(bytes(data), 40_000_000), ref)


def test_a_warning_about_metadata_does_not_hide_damaged_data() -> None:
    """libjpeg stops at its first warning: a JFIF 2.01 header before damaged scan data let
    the damage through the metadata fallback (a reviewer's finding)."""
    data = bytearray(WOLF.read_bytes())
    at = data.find(b"JFIF\x00")
    data[at + 5:at + 7] = b"\x02\x01"
    for kind, damaged in _damaged(bytes(data)).items():
        if kind in ("cut at half", "end marker missing"):
            continue  # OpenCV 5 refuses these itself
        with pytest.raises(ImageError, match="corrupt or truncated JPEG image: Corrupt JPEG"):
            decode_image(damaged, 40_000_000)


@pytest.mark.parametrize("jfif_2_01", [False, True], ids=["strict-decoder", "opencv-fallback"])
def test_a_big_endian_long_orientation_is_applied_whichever_decoder_reads_it(
        jfif_2_01: bool) -> None:
    """One EXIF rule on both decoding paths: a big-endian LONG orientation 6 (which OpenCV's
    own reader ignores) turns the frame on the strict path and on the fallback alike."""
    img = _img(60, 40)
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 100])
    ifd = struct.pack(">H", 1) + struct.pack(">HHII", 0x0112, 4, 1, 6)
    tiff = b"MM\x00\x2a\x00\x00\x00\x08" + ifd + struct.pack(">I", 0)
    app1 = b"Exif\x00\x00" + tiff
    raw = buf.tobytes()
    data = bytearray(raw[:2] + b"\xff\xe1" + struct.pack(">H", len(app1) + 2) + app1 + raw[2:])
    if jfif_2_01:
        at = data.find(b"JFIF\x00")
        assert at > 0
        data[at + 5:at + 7] = b"\x02\x01"
    out = decode_image(bytes(data), 10_000)
    assert out.shape == (60, 40, 3)  # turned 90° clockwise: 40 wide, 60 high


def _with_png_exif(png: bytes, orientation: int) -> bytes:
    """Insert an ``eXIf`` chunk (a big-endian TIFF, one IFD entry 0x0112) after the IHDR."""
    ifd = struct.pack(">H", 1) + struct.pack(">HHIHH", 0x0112, 3, 1, orientation, 0)
    tiff = b"MM\x00\x2a\x00\x00\x00\x08" + ifd + struct.pack(">I", 0)
    chunk = struct.pack(">I", len(tiff)) + b"eXIf" + tiff \
        + struct.pack(">I", zlib.crc32(b"eXIf" + tiff))
    return png[:33] + chunk + png[33:]  # signature (8) + IHDR (25)


@pytest.mark.parametrize("orientation", range(1, 9))
def test_a_pngs_exif_orientation_is_applied_at_every_depth(orientation: int) -> None:
    """A PNG's EXIF orientation turns it as OpenCV's reader turns an 8-bit PNG, and a
    16-bit or RGBA PNG of the same raster alike: those were decoded as stored, unturned
    (a tester's finding: the same frame came out turned 90° or 180° by its depth)."""
    img = _img(60, 40)
    ok, buf = cv2.imencode(".png", img)
    plain = _with_png_exif(buf.tobytes(), orientation)
    ref = cv2.imdecode(np.frombuffer(plain, np.uint8), cv2.IMREAD_COLOR)
    assert np.array_equal(decode_image(plain, 10_000), ref)
    alpha = np.full(img.shape[:2], 255, np.uint8)
    for raster in (img.astype(np.uint16) * 257, np.dstack([img, alpha])):
        ok, buf = cv2.imencode(".png", raster)
        assert np.array_equal(decode_image(_with_png_exif(buf.tobytes(), orientation), 10_000),
                              ref)


@pytest.mark.parametrize("name", ["Wolf_20160530_102400_UTCp1_sunrow1354_suncol730.jpg",
                                  "Wolf_20160530_122200_UTCp1_sunrow1319_suncol1067.jpg"])
def test_the_library_reads_16_bit_and_float_frames_as_the_service_decodes_them(name: str) -> None:
    """A frame handed to the library as 16-bit samples (full range, or a 12-bit sensor's
    0–4095) or as floats in 0–1 is found where its 8-bit frame is (``vision.imageio.to_8bit``,
    the decoder's rule). Before, the detection read 16 bits by the top byte and ran its colour
    tests on 8-bit frames only: these two Wolf frames × 257 lay 21.8 and 19.1 px from their
    8-bit answers (the white core of their glare skipped), 20.4 px from a label."""
    from vision.detect import detect_robust

    frame = cv2.imread(str(Path(__file__).parents[1] / "data" / "real-sky" / name),
                       cv2.IMREAD_COLOR)
    ref = detect_robust(frame)
    assert ref.sun_found and ref.centroid_px is not None
    for other in (frame.astype(np.uint16) * 257,
                  (frame.astype(np.int64) * 4095 // 255).astype(np.uint16),
                  frame.astype(np.float32) / 255.0):
        got = detect_robust(other)
        assert got.sun_found and got.centroid_px is not None
        assert np.hypot(got.centroid_px[0] - ref.centroid_px[0],
                        got.centroid_px[1] - ref.centroid_px[1]) < 0.5, other.dtype
        assert got.confidence == pytest.approx(ref.confidence, abs=0.01)
    with pytest.raises(ValueError, match="unsupported image dtype int32"):
        detect_robust(frame.astype(np.int32))
    with pytest.raises(ValueError, match="largest is 4095: scale it"):
        detect_robust(frame.astype(np.float32) * 4095 / 255)


def test_every_method_reads_a_16_bit_frame_as_its_8_bit_one() -> None:
    """The seeds' pipelines behind ``detect_sun`` too: seed 003's grey > 240 on 16-bit
    samples was true almost everywhere (the frame's centre, 364 px from its 8-bit answer, on this
    Wettermast frame) and seed 000's HSV conversion raised OpenCV's error on them."""
    from vision.detect import METHODS, detect_sun

    frame = _real_frame()
    for method in METHODS:
        ref, got = detect_sun(frame, method), detect_sun(frame.astype(np.uint16) * 257, method)
        assert ref.centroid_px is not None and got.centroid_px == ref.centroid_px, method
