"""Whole-flight arrays that stay on disk and are read in row chunks.

A streamed run (trn_env.sim.log.SimLog with a sink) ends with every update row on disk. Its largest
per-row quantity, the estimate's 9 x 9 covariance (648 bytes a row, two thirds of a row's arrays), is handed
on as a `ChunkedRows`: an array-like of known shape whose rows are read back in the log's row groups. The
consumers that must see the whole flight (the summary's metrics, `log.npz`) walk it a chunk at a time
(`iter_chunks`, `diagonals`, `write_npz`), so the end of a long run does not hold it whole;
anything else gets the ordinary array through `numpy.asarray` (`__array__`), the same values bit for bit.
"""

from __future__ import annotations

import zipfile
from collections.abc import Callable, Iterator

import numpy as np


class ChunkedRows:
    """An (n, ...) array read from disk in row chunks, never held whole.

    Parameters
    ----------
    shape : tuple of int
        The array's shape; rows are the first axis.
    dtype : numpy dtype
        The values' type.
    chunks : callable
        ``chunks()`` yields ``(start_row, block)`` in row order, blocks of shape ``(k,) + shape[1:]`` that
        together cover every row once.
    """

    def __init__(self, shape: tuple[int, ...], dtype, chunks: Callable[[], Iterator[tuple[int, np.ndarray]]]):
        self.shape = tuple(int(x) for x in shape)
        self.dtype = np.dtype(dtype)
        self._chunks = chunks

    @property
    def ndim(self) -> int:
        return len(self.shape)

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    def __len__(self) -> int:
        return self.shape[0]

    def chunks(self) -> Iterator[tuple[int, np.ndarray]]:
        """(start row, block) pairs in row order."""
        return self._chunks()

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        out = np.empty(self.shape, self.dtype)
        for start, block in self.chunks():
            out[start:start + block.shape[0]] = block
        return out if dtype is None else out.astype(dtype, copy=False)

    def __getitem__(self, key):
        return np.asarray(self)[key]

    def __reduce__(self):
        return (np.array, (np.asarray(self),))       # (pickled as the ordinary array it stands for)

    def __repr__(self) -> str:
        return f"ChunkedRows(shape={self.shape}, dtype={self.dtype})"


def iter_chunks(a) -> Iterator[tuple[int, np.ndarray]]:
    """(start row, block) of a ChunkedRows, or the whole of an ordinary array as one block."""
    if isinstance(a, ChunkedRows):
        yield from a.chunks()
    else:
        yield 0, np.asarray(a)


def diagonals(cov) -> np.ndarray:
    """The per-row diagonals (n, m) of an (n, m, m) array or ChunkedRows, as a new array."""
    if not isinstance(cov, ChunkedRows):
        return np.diagonal(cov, axis1=1, axis2=2).copy()
    out = np.empty(cov.shape[:2], cov.dtype)
    for start, block in cov.chunks():
        out[start:start + block.shape[0]] = np.diagonal(block, axis1=1, axis2=2)
    return out


# rows per piece written to an npz member: about 1 MB (numpy's own writer copies up to 16 MB at once)
NPZ_PIECE_BYTES = 1 << 20


def _npz_member(f, value) -> None:
    """One `.npy` member as numpy's `format.write_array` writes it (version 1.0 header, C order), its rows
    in pieces of about NPZ_PIECE_BYTES; object and non-contiguous arrays through numpy's own writer."""
    if isinstance(value, ChunkedRows):
        header = {"descr": np.lib.format.dtype_to_descr(value.dtype), "fortran_order": False,
                  "shape": value.shape}
        pieces = (block for _, block in value.chunks())
    else:
        arr = np.asanyarray(value)
        if arr.dtype.hasobject or arr.ndim == 0 or not arr.flags.c_contiguous:
            np.lib.format.write_array(f, arr, allow_pickle=True)
            return
        header = np.lib.format.header_data_from_array_1_0(arr)
        step = max(1, NPZ_PIECE_BYTES // max(1, arr[:1].nbytes))
        pieces = (arr[s:s + step] for s in range(0, arr.shape[0], step))
    np.lib.format.write_array_header_1_0(f, header)
    for block in pieces:
        if block.size:
            f.write(memoryview(np.ascontiguousarray(block)).cast("B"))


def write_npz(path, arrays: dict) -> None:
    """`numpy.savez_compressed(path, **arrays)` in bounded pieces: the same archive (members `NAME.npy`,
    deflated, the same .npy bytes), read by `numpy.load`; a ChunkedRows is written a chunk at a time."""
    with zipfile.ZipFile(path, mode="w", compression=zipfile.ZIP_DEFLATED, allowZip64=True) as zf:
        for name, value in arrays.items():
            with zf.open(name + ".npy", "w", force_zip64=True) as f:
                _npz_member(f, value)
