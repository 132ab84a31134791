"""numba's first compilation of every kernel, into its on-disk cache, on both cores (tests/conftest.py runs it).

`python tests/warm_kernels.py DONE_FILE` flies a short in-process hover through the public `navig8-sim` entry point,
which reaches every FC and plant kernel, then writes DONE_FILE (`<seconds> <tail exit code>`; written whatever
happened, so that nobody waiting for it waits for nothing). On a fresh clone the hover compiles for ~70 s on one
core, 27 s of it kalman.kf_step, which its first engaged tick reaches after ~10 s. What it reaches after that, the
INDI's, the outer loop's, the command shaper's and the arm preview's kernels (~20 s) and the plant's step and sensor
kernels (integrator.advance, sensors.sense: the first plant.step of the flight, ~6 s), `python tests/warm_kernels.py
--tail` compiles in a second process beside it, so the hover loads them from the cache when it reaches them. The
tail calls them the way the hover does (the same argument types: the same cache entries); a kernel it does not reach
the hover compiles as before, so a stale split costs time, never coverage.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path


def warm_plant_step(scenario: str = "hover") -> None:
    """The plant's step and its sensors, as navig8_tools.sim.fly calls them (plant.step, plant.sense_wire)."""
    import numpy as np

    from sim_bridge.plant import Plant
    from sim_bridge.world import load_world

    w = load_world(scenario)
    plant = Plant(w.vehicle, w.plant, w.scenario, np.random.default_rng(1))
    plant.step(plant.trim_command(), 0.01)
    plant.sense_wire()


def warm_inner_loops(scenario: str = "hover") -> None:
    """The INDI's, the outer loop's, the command shaper's and the arm preview's kernels, called as the hover's ticks
    and warm_up_kernels call them (the controller's config as navig8_tools.sim.run builds it): the hover reaches
    them only after kalman.kf_step, its longest kernel, so here they compile while it does."""
    import numpy as np

    from navig8_fc.core.arm_preview import arm_preview_step, hold_plan, preview_supervise
    from navig8_fc.core.indi import IndiController, IndiInputs
    from navig8_fc.core.outer_loop import (
        OFF,
        OSP,
        SH,
        Setpoint,
        outer_loop_config_array,
        outer_loop_step,
        shape_reference,
        shaper_config_array,
    )
    from navig8_fc.core.vehicle import UamModel
    from navig8_fc.flight import FlightStack
    from navig8_fc.params.registry import ParamRegistry
    from navig8_tools.sim import CONTROLLERS
    from sim_bridge.world import load_world

    w = load_world(scenario)
    reg = ParamRegistry.from_defaults()
    reg.set("CKF_MODE", CONTROLLERS["proposed"])
    cfg = FlightStack(w.fc_vehicle, reg, w.scenario.script).core.config
    gyro, sf, tilt, speed = (0.01, -0.02, 0.005), (0.1, 0.0, -9.81), (0.1, 0.1), (600.0, 50.0, 600.0)
    gc = np.eye(5)
    indi = IndiController(cfg.indi)
    indi.measure(IndiInputs(gyro, sf, tilt, speed, (0.0,) * 5, gc, np.eye(5)))  # the disengaged tick's
    # the shaper and the outer loop in the order the engaged tick calls them, then the INDI step (twice: the second
    # runs the actuator model's bank on the command the first flew)
    shape_reference(shaper_config_array(cfg.outer, cfg.dt_s), SH.zeros(), OSP.zeros(), np.zeros(3), np.zeros(3),
                    np.array((1.0, 0.0, 0.0, 0.0)), OSP.zeros(), OFF.zeros())
    outer_loop_step(outer_loop_config_array(cfg.outer), Setpoint((0.0, 0.0, -2.0), 0.0, 0.0), (0.0, 0.0, -2.0),
                    (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), gyro, OFF.zeros())
    for _ in range(2):
        indi.step(IndiInputs(gyro, sf, tilt, speed, (0.0,) * 5, gc, np.eye(5), np.eye(5)))
    arm_preview_step(hold_plan((0.1, 0.0, -0.1)), 0.0, cfg.dt_s, 0.05, np.zeros(3), np.zeros(3), 1e-3, 42.0, 4.0, 0.0,
                     UamModel(w.fc_vehicle).geometry, np.zeros(10), np.zeros(9))
    pv = cfg.indi.arm_preview
    preview_supervise(pv.supervisor_state(), pv.supervisor_config(), 0.1, np.zeros(3), np.zeros(10), cfg.dt_s)


def warm_all(done: Path) -> None:
    """The hover, with the tail beside it; DONE_FILE written at the end, also when anything raised (an import
    included: xdist workers poll for the file)."""
    t0 = time.perf_counter()
    rc: int | str = "not started"
    try:
        tail = subprocess.Popen([sys.executable, __file__, "--tail"], stdin=subprocess.DEVNULL)
        try:
            from navig8_tools.sim import run

            run("hover", duration_s=0.05, log_path=None)
        finally:
            rc = tail.wait()
    finally:
        tmp = done.with_name(done.name + ".tmp")
        tmp.write_text(f"{time.perf_counter() - t0:.1f} {rc}\n")
        tmp.replace(done)  # whole or absent for a reader polling it


if __name__ == "__main__":
    if sys.argv[1:] == ["--tail"]:
        # in the order the hover reaches them after kf_step; the plant last: its constructor compiles
        # integrator.evaluate, which the hover reaches in its first seconds (by then it is in the cache). The
        # eigenvalue record (~12 s, warm_up_kernels's last call) is left to the hover: here it would end after the
        # hover reached it, and both would compile it.
        warm_inner_loops()
        warm_plant_step()
    else:
        warm_all(Path(sys.argv[1]))
