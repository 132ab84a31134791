"""Named layouts of the flat float64 vectors the numba kernels take.

One table per vector: `layout("IO", acc_f=5, u0=5, ...)` gives an IntEnum whose members are the fields'
start slots (`IO.ACC_F == 0`, `IO.U0 == 5`, `IO.SIZE == 10`). numba reads IntEnum members as compile-time
integer constants, so a kernel indexes `out[IO.U0 + i]` at the cost of a literal; Python callers take the
same table's slices (`IO.U0.sl`), build vectors by name (`IO.pack(acc_f=..., u0=...)`) and cut named
views (`IO.views(arr)`). The kernel and its callers therefore cannot disagree about an offset.

numba's on-disk cache freezes these constants into the compiled code and keys the cache on the kernel's
source file: define a layout in the module of the kernels that use it, so editing it invalidates them. A kernel
that reads another module's layout is decorated with jit.njit_cached(that module), whose digest covers the
module's layouts.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from types import SimpleNamespace
from typing import Any

import numpy as np


class Slots(enum.IntEnum):
    """Start slot of each field of one vector (plus SIZE, the vector's length); built by `layout`."""

    @property
    def size(self) -> int:
        """Number of slots of this field (0 for SIZE)."""
        return type(self).__sizes__[self._value_]  # type: ignore[attr-defined]

    @property
    def sl(self) -> slice:
        """The field's slice of the vector."""
        return type(self).__slices__[self._value_]  # type: ignore[attr-defined]

    @classmethod
    def fields(cls) -> list[Slots]:
        return [m for m in cls if m.name != "SIZE"]

    @classmethod
    def zeros(cls) -> np.ndarray:
        return np.zeros(int(cls.SIZE))  # type: ignore[attr-defined]

    @classmethod
    def pack(cls, **values: Any) -> np.ndarray:
        """A new vector with every field given by its (lower-case) name: a scalar or a sequence of its size."""
        names = {m.name.lower(): m for m in cls.fields()}
        missing, extra = set(names) - set(values), set(values) - set(names)
        if missing or extra:
            raise KeyError(f"{cls.__name__}.pack: missing {sorted(missing)}, unknown {sorted(extra)}")
        out = cls.zeros()
        for name, v in values.items():
            m = names[name]
            arr = np.asarray(v, dtype=float).reshape(-1)
            if arr.size != m.size:
                raise ValueError(f"{cls.__name__}.{m.name} takes {m.size} values, got {arr.size}")
            out[m.sl] = arr
        return out

    @classmethod
    def views(cls, vec: np.ndarray) -> SimpleNamespace:
        """Named views of `vec` (lower-case field names): a scalar field is a 1-element view."""
        if vec.shape[0] != int(cls.SIZE):  # type: ignore[attr-defined]
            raise ValueError(f"{cls.__name__} has {int(cls.SIZE)} slots, got a vector of {vec.shape[0]}")  # type: ignore[attr-defined]
        return SimpleNamespace(**{m.name.lower(): vec[m.sl] for m in cls.fields()})


def layout(name: str, fields: Mapping[str, int] | None = None, **sizes: int) -> type[Slots]:
    """The Slots enum of a vector made of the given fields, in order, each `size` slots long (>= 1)."""
    table = dict(fields or {}, **sizes)
    starts: dict[str, int] = {}
    size_of: dict[int, int] = {}  # by start slot (every field starts at a different slot: sizes are >= 1)
    pos = 0
    for field, n in table.items():
        if n < 1:
            raise ValueError(f"layout {name}: field {field} has size {n}")
        starts[field.upper()] = pos
        size_of[pos] = n
        pos += n
    starts["SIZE"] = pos
    size_of[pos] = 0
    cls = Slots(name, starts)  # type: ignore[call-overload]
    type.__setattr__(cls, "__sizes__", size_of)
    type.__setattr__(cls, "__slices__", {at: slice(at, at + n) for at, n in size_of.items()})
    return cls
