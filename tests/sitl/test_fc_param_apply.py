"""A parameter accepted over MAVLink reaches the controller at the next control step (the FC process's wiring:
registry -> FlightStack.reconfigure -> FlightControllerCore), for gains swapped in place and for settings that
rebuild the core. In-process FlightControllerProcess on free loopback ports; no bridge needed."""

from __future__ import annotations

from pathlib import Path

import pytest
from sitl_helpers import free_udp_ports

from navig8_fc.core.outer_loop import OuterLoopConfig, outer_loop_config_array
from navig8_fc.shell import fc_options as fo
from navig8_fc.shell import fc_process as fp


def test_accepted_parameters_reach_the_controller_at_the_next_step(tmp_path: Path) -> None:
    bridge, gcs, api = free_udp_ports(3)  # where the FC sends; it binds port 0
    args = fo.build_arg_parser().parse_args([
        "--sim-port", "0", "--bridge-port", str(bridge), "--gcs-bind-port", "0",
        "--api-bind-port", "0", "--gcs-port", str(gcs), "--api-port", str(api),
        "--state-dir", str(tmp_path), "--defaults"])
    fc = fp.FlightControllerProcess(fo.options_from_args(args))
    try:
        core = fc.stack.core
        # Gains: swapped in place (filters and estimator keep their state), and what the tick reads changes.
        assert fc.registry.set("OL_POS_K", float(fc.registry["OL_POS_K"]) * 1.5).accepted
        assert fc.registry.set("INDI_K_MIN", 0.6).accepted
        fc.stack.reconfigure()
        assert fc.stack.core is core
        want = OuterLoopConfig.from_params(fc.registry.as_dict(), fc.vehicle.gravity_m_s2)
        assert core.config.outer == want
        assert core.config.k_min == float(fc.registry["INDI_K_MIN"]) == pytest.approx(0.6)  # REAL32 on the wire
        assert (core._outer_cfg == outer_loop_config_array(want)).all()
        # A filter constant: the core is rebuilt with it.
        assert fc.registry.set("INDI_LPF_TAU", 0.08).accepted
        fc.stack.reconfigure()
        assert fc.stack.core is not core and fc.stack.core.config.indi.lpf_tau_s == pytest.approx(0.08)
    finally:
        fc.close()
