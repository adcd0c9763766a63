"""Pieces shared by the quantised scene formats (`.splat`, SPZ, compressed PLY).

Speed notes (measured at a million splats): the decoders work through the splats in blocks of
BLOCK so that temporaries stay in the CPU cache; bytes that map to values through a formula go
through a 256- or 1024-entry table with `np.take(..., mode="clip")`, about twice as fast as
fancy indexing; and the "smallest three" quaternions (stored by SPZ from version 3 and by the
PlayCanvas compressed PLY) are put in place with one gather rather than masked selects.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np

BLOCK = 1 << 15  # most splats per block
_BLOCK_BYTES = 1 << 20  # output bytes per block: the block's work stays in the CPU cache
_ROWS = np.arange(BLOCK, dtype=np.intp)[:, None]


def block_size(bytes_per_splat: int) -> int:
    """Splats per block for a decoder that writes `bytes_per_splat` bytes of output per splat."""
    return int(min(BLOCK, max(1024, _BLOCK_BYTES // bytes_per_splat)))


def blocks(n: int, block: int = BLOCK) -> Iterator[tuple[int, int]]:
    """(start, stop) of consecutive blocks covering range(n)."""
    for start in range(0, n, block):
        yield start, min(n, start + block)


def byte_table(decode: Callable[[np.ndarray], np.ndarray], size: int = 256) -> np.ndarray:
    """(size,) float32 table of `decode(i)` for i in range(size) (evaluated in float64)."""
    return np.asarray(decode(np.arange(size, dtype=np.float64)), dtype=np.float64).astype(np.float32)


def lookup(table: np.ndarray, index: np.ndarray, out: np.ndarray) -> None:
    """out[...] = table[index] (indices known to be in range; `out` best contiguous)."""
    np.take(table, index, mode="clip", out=out)


class SmallestThree:
    """Rebuilds unit quaternions (w first) from the "smallest three" encoding, a block at a time.

    Fill the rows of `stored(size)` with the three stored components in increasing component
    order (the largest skipped), then call `finish`. `wxyz` gives the positions of w, x, y, z in
    the format's component order, e.g. (3, 0, 1, 2) for a format ordered x, y, z, w.
    """

    def __init__(self, wxyz: tuple[int, int, int, int]) -> None:
        # Rows 0-2 hold the stored components, row 3 the rebuilt largest one. offset[L, c] is
        # where output column c comes from in the flattened rows when the largest is L.
        source = [[3 if wxyz[c] == largest else wxyz[c] - (wxyz[c] > largest) for c in range(4)]
                  for largest in range(4)]
        self.offset = np.array(source, dtype=np.intp) * BLOCK
        self.components = np.empty((4, BLOCK), dtype=np.float32)
        self.index = np.empty((BLOCK, 4), dtype=np.intp)

    def stored(self, size: int) -> np.ndarray:
        """(3, size) float32 buffer for the stored components, one contiguous row each."""
        return self.components[:3, :size]

    def finish(self, largest: np.ndarray, out: np.ndarray) -> None:
        """Write the quaternions of the block into `out` (size, 4); `largest` holds 0..3.

        The largest component is rebuilt as sqrt(1 - |stored|^2) (encoders make it positive).
        Quantised components can have |stored| > 1; such rows get a zero largest component and
        are scaled back to unit length.
        """
        size = len(largest)
        a, b, c = self.components[:3, :size]
        squared = a * a + b * b + c * c
        np.sqrt(np.maximum(np.float32(0), np.float32(1) - squared), out=self.components[3, :size])
        index = self.index[:size]
        np.take(self.offset, largest.astype(np.intp), axis=0, mode="clip", out=index)
        index += _ROWS[:size]
        np.take(self.components.reshape(-1), index, mode="clip", out=out)
        too_long = squared > 1
        if too_long.any():
            out[too_long] /= np.sqrt(squared[too_long])[:, None]
