"""The parameters QGroundControl reads of a PX4 vehicle (docs/research/mavsdk_examples.md, section 4.1): this
vehicle's fixed facts under PX4's names, and a change refused with the reason (the value stays)."""

from __future__ import annotations

import pytest

from navig8_fc.params.registry import ParamRegistry


@pytest.mark.parametrize(("name", "value"), [("PD_GRIPPER_EN", 1), ("COM_RC_IN_MODE", 1)])
def test_a_fixed_px4_name_reads_its_fact_and_refuses_a_change(name: str, value: int) -> None:
    reg = ParamRegistry.from_defaults()
    d = reg.definition(name)
    assert (d.type, reg.get(name)) == ("INT32", value)
    res = reg.set(name, 1 - value)
    assert not res.accepted and res.value == value and name in res.reason
    assert reg.get(name) == value
