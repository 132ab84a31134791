"""numba's first compilation of every kernel, into its on-disk cache, on both cores (tests/conftest.py runs it).

`python tests/warm_kernels.py DONE_FILE` flies a short in-process hover through the public `navig8-sim` entry point,
which reaches every FC and plant kernel, then writes DONE_FILE (`<seconds> <tail exit code>`; written whatever
happened, so that nobody waiting for it waits for nothing). On a fresh clone the hover compiles for ~70 s on one
core. Its last ~20 s are the eigenvalue record's kernel (g_c.ghat_ginv_eigs_truth, with ghat_ginv_eigs inside:
warm_up_kernels's last call) and the plant's step and sensor kernels (integrator.advance, sensors.sense: the first
plant.step of the flight); `python tests/warm_kernels.py --tail` compiles those in a second process beside it, so
the hover loads them from the cache when it reaches them. The tail calls them the way the hover does (the same
argument types: the same cache entries); a kernel it does not reach the hover compiles as before, so a stale split
costs time, never coverage.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path


def warm_eigenvalue_record(scenario: str = "hover") -> None:
    """ghat_ginv_eig_record as warm_up_kernels calls it (G_C,UAM given as the controller's status carries it)."""
    import numpy as np

    from navig8_fc.core.vehicle import UamModel, ghat_ginv_eig_record
    from sim_bridge.world import load_world

    w = load_world(scenario)
    gi = np.eye(5).ravel().tolist()
    ghat_ginv_eig_record(UamModel(w.fc_vehicle), (0.0, 0.0, 0.0), gi, (0.0, 0.0, 0.05), w.fc_vehicle.uav_inertia_array,
                         w.fc_vehicle.uam_mass_kg, 0.4, 0.1, gi)


def warm_plant_step(scenario: str = "hover") -> None:
    """The plant's step and its sensors, as navig8_tools.sim.fly calls them (plant.step, plant.sense_wire)."""
    import numpy as np

    from sim_bridge.plant import Plant
    from sim_bridge.world import load_world

    w = load_world(scenario)
    plant = Plant(w.vehicle, w.plant, w.scenario, np.random.default_rng(1))
    plant.step(plant.trim_command(), 0.01)
    plant.sense_wire()


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
        # the eigenvalue record first: the plant's constructor compiles integrator.evaluate, which the hover reaches
        # in its first second (compiling it here as well would only duplicate it)
        warm_eigenvalue_record()
        warm_plant_step()
    else:
        warm_all(Path(sys.argv[1]))
