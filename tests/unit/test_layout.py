"""navig8_fc.core.layout: the slot constants, the slices, pack and the named views agree."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from navig8_fc.core.layout import layout

LAY = layout("LAY", a=3, b=1, c=2)


@njit(cache=False)
def _write_c(vec):
    vec[LAY.C] = 7.0
    vec[LAY.C + 1] = 8.0


def test_slots_are_consecutive_and_views_alias_the_array() -> None:
    assert (LAY.A, LAY.B, LAY.C, LAY.SIZE) == (0, 3, 4, 6)
    assert (LAY.A.size, LAY.B.size, LAY.C.size) == (3, 1, 2)
    assert LAY.C.sl == slice(4, 6)
    arr = LAY.zeros()
    v = LAY.views(arr)
    v.b[0] = 5.0
    _write_c(arr)  # a compiled kernel indexes by the same constants
    assert arr.tolist() == [0.0, 0.0, 0.0, 5.0, 7.0, 8.0]
    assert v.c.tolist() == [7.0, 8.0] and np.shares_memory(v.a, arr)


def test_pack_by_name_and_errors() -> None:
    vec = LAY.pack(a=(1, 2, 3), b=4, c=(5, 6))
    assert vec.tolist() == [1, 2, 3, 4, 5, 6]
    with pytest.raises(KeyError):
        LAY.pack(a=(1, 2, 3), b=4)
    with pytest.raises(ValueError):
        LAY.pack(a=(1, 2), b=4, c=(5, 6))
    with pytest.raises(ValueError):
        LAY.views(np.zeros(5))
    with pytest.raises(ValueError):
        layout("BAD", a=0)
