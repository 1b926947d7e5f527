"""Whole-flight arrays that stay on disk and are read in row chunks.

A streamed run (trn_env.sim.log.SimLog with a sink) ends with every update row on disk. Its largest
per-row quantity, the estimate's 9 x 9 covariance (648 bytes a row, two thirds of a row's arrays), is handed
on as a `ChunkedRows`: an array-like of known shape whose rows are read back in the log's row groups. The
consumers that must see the whole flight (the summary's metrics, `log.npz`) walk it a chunk at a time
(`iter_chunks`, `covariance_blocks`, `write_npz`), so the end of a long run does not hold it whole;
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


def covariance_blocks(cov, k: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """(the leading k x k blocks (n, k, k), the diagonals (n, m)) of an (n, m, m) covariance array or
    ChunkedRows; an ordinary array gives views, a ChunkedRows new arrays of the same values."""
    if not isinstance(cov, ChunkedRows):
        cov = np.asarray(cov, float)
        return cov[:, :k, :k], np.diagonal(cov, axis1=1, axis2=2)
    lead = np.empty((cov.shape[0], k, k), cov.dtype)
    for start, block in cov.chunks():
        lead[start:start + block.shape[0]] = block[:, :k, :k]
    return lead, diagonals(cov)


def write_npz(path, arrays: dict) -> None:
    """`numpy.savez_compressed(path, **arrays)`, a ChunkedRows written a chunk at a time: the same archive
    (members `NAME.npy`, deflated, version 1.0 headers as numpy writes them), read by `numpy.load`."""
    with zipfile.ZipFile(path, mode="w", compression=zipfile.ZIP_DEFLATED, allowZip64=True) as zf:
        for name, value in arrays.items():
            with zf.open(name + ".npy", "w", force_zip64=True) as f:
                if not isinstance(value, ChunkedRows):
                    np.lib.format.write_array(f, np.asanyarray(value), allow_pickle=True)
                    continue
                header = {"descr": np.lib.format.dtype_to_descr(value.dtype), "fortran_order": False,
                          "shape": value.shape}
                np.lib.format.write_array_header_1_0(f, header)
                for _, block in value.chunks():
                    f.write(np.ascontiguousarray(block, value.dtype).tobytes("C"))
