"""pymavlink as the oracle of the codec tests: random field values from a generated class's own metadata, and
value equality that treats NaN as equal to itself and floats bit for bit."""

from __future__ import annotations

import math
import random
import struct


def _value(rng: random.Random, typ: str) -> float | int:
    if rng.random() < 0.3:  # zeros everywhere, so payloads end in zeros and get truncated
        return 0.0 if typ in ("float", "double") else 0
    if typ == "float":
        return rng.choice([rng.uniform(-1e3, 1e3), rng.uniform(-1e-3, 1e-3), math.inf, -math.inf, math.nan, 1e30])
    if typ == "double":
        return rng.uniform(-1e6, 1e6)
    bits = int("".join(ch for ch in typ if ch.isdigit()))
    if typ.startswith("u"):
        return rng.randrange(0, 1 << bits)
    return rng.randrange(-(1 << (bits - 1)), 1 << (bits - 1))


def random_args(rng: random.Random, cls) -> list:
    """Random constructor arguments (field order) of a generated class, from its own metadata."""
    lengths = dict(zip(cls.ordered_fieldnames, cls.array_lengths, strict=True))
    return [[_value(rng, t) for _ in range(lengths[f])] if lengths[f] else _value(rng, t)
            for t, f in zip(cls.fieldtypes, cls.fieldnames, strict=True)]


def same(a, b) -> bool:
    """Equal values, floats bit for bit (NaN == NaN), sequences element by element (list or tuple)."""
    if isinstance(a, (list, tuple)):
        return isinstance(b, (list, tuple)) and len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float):
        return isinstance(b, float) and struct.pack("<d", a) == struct.pack("<d", b)
    return type(a) is type(b) and a == b


def same_fields(got: dict, want_msg) -> bool:
    want = want_msg.to_dict()
    assert want.pop("mavpackettype") == want_msg.get_type()
    return list(got) == list(want) and all(same(got[k], want[k]) for k in want)
