"""Per-step records built cheaply: `frozen_record`, for the frozen dataclasses the control loop builds every step.

A frozen dataclass's generated __init__ sets each field through object.__setattr__ (its own __setattr__ refuses),
~0.1 us a field; the control step builds ~70 such fields (sensors, status, command). `frozen_record` gives the
class an __init__ that stores the same fields, in the same order, straight into the instance's __dict__ (~0.03 us a
field). Everything else is the dataclass's own: equality, hash, repr, `dataclasses.replace`, assignment refused
(FrozenInstanceError), orjson's serialisation (the __dict__ in field order).
"""

from __future__ import annotations

from dataclasses import MISSING, fields
from typing import TypeVar

T = TypeVar("T")


def frozen_record(cls: type[T]) -> type[T]:
    """Replace the __init__ of `cls` (a frozen dataclass: plain fields, defaults allowed; no default_factory,
    keyword-only field, init=False field or __post_init__) by one writing the instance dict directly."""
    params = getattr(cls, "__dataclass_params__", None)
    if params is None or not params.frozen:
        raise TypeError(f"{cls.__name__}: frozen_record takes a frozen dataclass")
    fs = fields(cls)
    if hasattr(cls, "__post_init__") or hasattr(cls, "__slots__"):
        raise TypeError(f"{cls.__name__}: __post_init__ or __slots__ is not supported")
    for f in fs:
        if f.name in ("_self_", "_fields_") or f.name.startswith("_d_"):
            raise TypeError(f"{cls.__name__}.{f.name}: a name frozen_record's __init__ uses itself")
        if not f.init or f.kw_only or f.default_factory is not MISSING:
            raise TypeError(f"{cls.__name__}.{f.name}: only plain fields (with or without a default) are supported")
    defaults = {f"_d_{f.name}": f.default for f in fs if f.default is not MISSING}
    args = ", ".join(f.name if f.default is MISSING else f"{f.name}=_d_{f.name}" for f in fs)
    body = "".join(f"    _fields_[{f.name!r}] = {f.name}\n" for f in fs)  # local names no field can take
    namespace = dict(defaults)
    exec(f"def __init__(_self_, {args}):\n    _fields_ = _self_.__dict__\n{body}", namespace)  # as dataclasses
    init = namespace["__init__"]
    init.__qualname__ = f"{cls.__qualname__}.__init__"
    init.__module__ = cls.__module__
    cls.__init__ = init  # type: ignore[misc]
    return cls


__all__ = ["frozen_record"]
