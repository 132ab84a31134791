"""core.records.frozen_record: the per-step records' cheaper __init__ leaves them the dataclasses they were."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import orjson
import pytest

from navig8_fc.core.controller import ActuatorCommand, ControllerStatus, FcSensors
from navig8_fc.core.records import frozen_record


@dataclass(frozen=True)
class _Plain:
    a: float
    b: tuple[float, ...]
    c: int = 3
    d: object | None = None


@frozen_record
@dataclass(frozen=True)
class _Fast:
    a: float
    b: tuple[float, ...]
    c: int = 3
    d: object | None = None


def test_a_frozen_record_is_the_dataclass_it_was() -> None:
    for args, kwargs in (((1.5, (2.0,)), {}), ((1.5, (2.0,), 4), {"d": "x"}), ((), {"b": (1.0,), "a": 0.5})):
        plain, fast = _Plain(*args, **kwargs), _Fast(*args, **kwargs)
        assert dataclasses.astuple(plain) == dataclasses.astuple(fast)
        assert orjson.dumps(plain) == orjson.dumps(fast)  # the same fields in the same order
        assert repr(plain).replace("_Plain", "_Fast") == repr(fast)
        assert fast == _Fast(*args, **kwargs) and hash(fast) == hash(_Fast(*args, **kwargs))
        assert dataclasses.replace(fast, c=9).c == 9
        with pytest.raises(dataclasses.FrozenInstanceError):
            fast.a = 2.0  # type: ignore[misc]
    with pytest.raises(TypeError):
        _Fast(1.0)  # type: ignore[call-arg]
    with pytest.raises(TypeError):
        _Fast(1.0, (2.0,), e=1)  # type: ignore[call-arg]


def test_only_plain_frozen_dataclasses_are_taken() -> None:
    @dataclass
    class Mutable:
        a: float

    @dataclass(frozen=True)
    class Factory:
        a: list[float] = field(default_factory=list)

    @dataclass(frozen=True)
    class PostInit:
        a: float

        def __post_init__(self) -> None:
            pass

    @dataclass(frozen=True)
    class Clash:
        _fields_: float

    for cls in (Mutable, Factory, PostInit, Clash):
        with pytest.raises(TypeError):
            frozen_record(cls)


def test_the_loops_records_are_frozen_records() -> None:
    for cls in (FcSensors, ActuatorCommand, ControllerStatus):
        assert cls.__init__.__qualname__ == f"{cls.__qualname__}.__init__"
        assert "_fields_" in cls.__init__.__code__.co_varnames
