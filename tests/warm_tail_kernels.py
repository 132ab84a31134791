"""Compile the numba kernels that tests/conftest.py's warm-up hover reaches last, in a second process beside it.

numba compiles on one core. On a fresh clone the warm-up hover (`navig8_tools.sim.run`) spends ~70 s compiling
every kernel while the machine's other core idles (xdist starts its workers only after it). Its last ~20 s are
the eigenvalue record's kernel (g_c.ghat_ginv_eigs_truth, with ghat_ginv_eigs inside; warm_up_kernels's last
call) and the plant's step and sensor kernels (integrator.advance, sensors.sense; the first plant.step of the
flight). This script compiles those into numba's on-disk cache first, so that when the hover reaches them it loads
them instead. It calls them the way the hover does (same argument types: the same cache entries); a kernel it does
not reach is compiled by the hover as before, so a stale split costs time, never coverage. Run as a script:
`python tests/warm_tail_kernels.py`.
"""

from __future__ import annotations

import numpy as np

from navig8_fc.core.vehicle import UamModel, ghat_ginv_eig_record
from sim_bridge.plant import Plant
from sim_bridge.world import load_world


def warm_eigenvalue_record(scenario: str = "hover") -> None:
    """ghat_ginv_eig_record as warm_up_kernels calls it (G_C,UAM given as the controller's status carries it)."""
    w = load_world(scenario)
    gi = np.eye(5).ravel().tolist()
    ghat_ginv_eig_record(UamModel(w.fc_vehicle), (0.0, 0.0, 0.0), gi, (0.0, 0.0, 0.05), w.fc_vehicle.uav_inertia_array,
                         w.fc_vehicle.uam_mass_kg, 0.4, 0.1, gi)


def warm_plant_step(scenario: str = "hover") -> None:
    """The plant's step and its sensors, as navig8_tools.sim.fly calls them (plant.step, plant.sense_wire)."""
    w = load_world(scenario)
    plant = Plant(w.vehicle, w.plant, w.scenario, np.random.default_rng(1))
    plant.step(plant.trim_command(), 0.01)
    plant.sense_wire()


if __name__ == "__main__":
    # the eigenvalue record first: the plant's constructor compiles integrator.evaluate, which the hover reaches in
    # its first second (compiling it here as well would only duplicate it)
    warm_eigenvalue_record()
    warm_plant_step()
