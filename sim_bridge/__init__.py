"""sim_bridge: the Navig8-UAM plant (physics, actuators, sensors, scenarios) and, later, its I/O loop.

The plant itself does no I/O; see sim_bridge/plant.py for the API.
"""

from sim_bridge.messages import ActuatorCommand, SensorBundle, SensorField, Truth
from sim_bridge.params import PlantParams
from sim_bridge.plant import Plant, PlantDivergedError
from sim_bridge.scenario import Scenario, load_scenario

__all__ = [
    "ActuatorCommand",
    "Plant",
    "PlantDivergedError",
    "PlantParams",
    "Scenario",
    "SensorBundle",
    "SensorField",
    "Truth",
    "load_scenario",
]
