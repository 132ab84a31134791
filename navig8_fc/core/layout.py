"""Named slots of the flat float64 arrays the numba kernels share with Python.

A kernel reads and writes fixed offsets of a flat array (numba sees module-level ints as constants); Python
reads the same slots through named views. One table generates both, so the offsets are written once:

    OUT = Layout(x_hat=4, innovation=5)
    O_X_HAT, O_INNOV = OUT.start("x_hat"), OUT.start("innovation")  # constants for the kernel
    out = np.zeros(OUT.size); v = OUT.views(out); v.innovation  # a view of out[4:9]
"""

from __future__ import annotations

from collections import namedtuple
from typing import Any

import numpy as np

__all__ = ["Layout"]


class Layout:
    """Consecutive named slots (name = length) of a flat array; `size` is the total length."""

    def __init__(self, **fields: int) -> None:
        self._slices: dict[str, slice] = {}
        start = 0
        for name, length in fields.items():
            if length < 1:
                raise ValueError(f"slot {name!r} needs a positive length, got {length}")
            self._slices[name] = slice(start, start + length)
            start += length
        self.size = start
        self._views_type = namedtuple("Views", tuple(fields))  # type: ignore[misc]

    def start(self, name: str) -> int:
        return self._slices[name].start

    def zeros(self) -> np.ndarray:
        return np.zeros(self.size)

    def views(self, arr: np.ndarray) -> Any:
        """A named tuple of views of `arr`, one per slot (they stay valid while arr is not replaced)."""
        if arr.shape != (self.size,):
            raise ValueError(f"layout of size {self.size} over an array of shape {arr.shape}")
        return self._views_type(*(arr[s] for s in self._slices.values()))
