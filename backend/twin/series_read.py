"""A stored run's series read a block of rows at a time, for answers streamed as written.

A year at one minute is 527,040 rows of ≈ 20 columns: as Python dicts it took
> 1 GB to answer at once. :class:`PackedSeries` reads the packed series
(:func:`backend.twin.simulations.write_npz`: one deflated ``.npy`` member per
column) member by member, as streams: only the time column is read whole (8
bytes a row, the range's rows are found in it), the other columns a block of
rows at a time, so what is held beside the packed bytes is one block.
"""

from __future__ import annotations

import io
import math
import warnings
import zipfile
from collections.abc import Iterator
from typing import IO

import numpy as np

#: Rows per block read and written: a year of JSON peaked at +52 MB with 8,192 rows a block,
#: +16 MB with 2,048 (and was faster), measured on the development machine on 2026-12-03.
BLOCK_ROWS = 2048


def _array_start(f: IO[bytes]) -> tuple[np.dtype, int]:
    """Read a ``.npy`` header: the dtype and the row count of its 1-D array."""
    version = np.lib.format.read_magic(f)
    read = (np.lib.format.read_array_header_1_0 if version == (1, 0)
            else np.lib.format.read_array_header_2_0)
    shape, fortran, dtype = read(f)
    if len(shape) != 1 or fortran:
        raise ValueError(f"a packed series column is 1-D, got shape {shape}")
    return dtype, int(shape[0])


class PackedSeries:
    """The packed series of one run: its columns, its times, and its rows block by block."""

    def __init__(self, blob: bytes, keep: object = None) -> None:
        """``keep``: an object to hold while this series is read (the owner of ``blob``)."""
        self._keep = keep
        self._zip = zipfile.ZipFile(io.BytesIO(blob))
        names = [n.removesuffix(".npy") for n in self._zip.namelist()]
        self.columns = [n for n in names if n != "ts_s"]
        #: the columns that are compass directions [°] (the sun's azimuth): averaged as
        #: directions (a joint's azimuth, which winds past 360° on its cable, is an angle)
        self.directions = np.array([c.startswith("solar_azimuth") for c in self.columns])
        with self._zip.open("ts_s.npy") as f:
            self.ts_s: np.ndarray = np.lib.format.read_array(f)

    def __len__(self) -> int:
        return len(self.ts_s)

    def index_range(self, start_s: int | None, end_s: int | None) -> tuple[int, int]:
        """The rows ``[i0, i1)`` with times in ``[start_s, end_s)`` (Unix seconds)."""
        i0 = 0 if start_s is None else int(np.searchsorted(self.ts_s, start_s, "left"))
        i1 = len(self) if end_s is None else int(np.searchsorted(self.ts_s, end_s, "left"))
        return i0, max(i0, i1)

    def blocks(self, i0: int, i1: int, per: int = 1
               ) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """Rows ``[i0, i1)`` as ``(ts_s, values)`` blocks (values: rows × columns, float64),
        or, with ``per`` > 1, the means of each ``per`` rows (NaN ignored; the time of a
        bucket is its first row's; the last bucket may be shorter)."""
        files = [self._zip.open(f"{c}.npy") for c in self.columns]
        try:
            itemsizes = []
            for f in files:
                dtype, n = _array_start(f)
                if n != len(self):
                    raise ValueError("a packed series column differs in length from its times")
                itemsizes.append(dtype)
                f.seek(f.tell() + i0 * dtype.itemsize)
            block = max(per, BLOCK_ROWS // per * per)
            for b0 in range(i0, i1, block):
                b1 = min(i1, b0 + block)
                values = np.empty((b1 - b0, len(files)))
                for j, (f, dtype) in enumerate(zip(files, itemsizes, strict=True)):
                    raw = f.read((b1 - b0) * dtype.itemsize)
                    values[:, j] = np.frombuffer(raw, dtype)
                ts = self.ts_s[b0:b1]
                if per > 1:
                    ts, values = ts[::per], bucket_means(values, per, self.directions)
                yield ts, values
        finally:
            for f in files:
                f.close()


def bucket_means(values: np.ndarray, per: int, directions: np.ndarray | None = None
                 ) -> np.ndarray:
    """Means of each ``per`` rows of ``values`` (NaN ignored, an all-NaN bucket NaN).

    ``directions``: a mask of the columns that are compass directions [°], averaged as
    unit vectors into [0, 360) (the midnight sun's hour from 349° through 0° to 10° is
    north, not the 272° of its plain mean; a tester's finding)."""
    m = math.ceil(len(values) / per)
    pad = m * per - len(values)
    padded = np.vstack([values, np.full((pad, values.shape[1]), np.nan)]) if pad else values
    groups = padded.reshape(m, per, -1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an all-NaN bucket: NaN, as wanted
        out = np.nanmean(groups, axis=1)
        if directions is not None and directions.any():
            rad = np.radians(groups[:, :, directions])
            mean = np.degrees(np.arctan2(np.nanmean(np.sin(rad), axis=1),
                                         np.nanmean(np.cos(rad), axis=1)))
            out[:, directions] = np.mod(mean, 360.0)
    return out
