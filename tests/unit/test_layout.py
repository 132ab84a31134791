"""navig8_fc.core.layout: the slot constants and the named views agree."""

from __future__ import annotations

import numpy as np
import pytest

from navig8_fc.core.layout import Layout


def test_slots_are_consecutive_and_views_alias_the_array() -> None:
    lay = Layout(a=3, b=1, c=2)
    assert (lay.start("a"), lay.start("b"), lay.start("c"), lay.size) == (0, 3, 4, 6)
    arr = lay.zeros()
    v = lay.views(arr)
    v.c[:] = (7.0, 8.0)
    v.b[0] = 5.0
    assert arr.tolist() == [0.0, 0.0, 0.0, 5.0, 7.0, 8.0]
    assert np.shares_memory(v.a, arr)
    with pytest.raises(ValueError):
        lay.views(np.zeros(5))
    with pytest.raises(ValueError):
        Layout(a=0)
