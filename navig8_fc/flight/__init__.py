"""The flight controller as one pure object: `FlightStack` (mode manager + failsafe decisions + controller core),
its seams (`VehicleCommands`, `VehicleState`, `StepResult`, `Notice`) and the scenario's setpoint script.
navig8-fc, navig8-sim and the tests drive the same `FlightStack`."""

from importlib import import_module
from typing import Any

from navig8_fc.flight.script import FlightScript, load_flight_script, parse_flight_script, read_scenario_file

# loaded on first use: the stack and its records pull in the controller core (numba kernels, scipy), which a reader
# of scenario scripts alone (navig8-bridge: sim_bridge/scenario.py) does not need (~0.6 s of every bridge's start)
_LAZY = {"FlightStack": "stack", "rotor_thrusts_n": "stack", "ArmRequest": "state", "Notice": "state",
         "StepResult": "state", "VehicleCommands": "state", "VehicleState": "state"}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(import_module(f"navig8_fc.flight.{_LAZY[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "ArmRequest",
    "FlightScript",
    "FlightStack",
    "Notice",
    "StepResult",
    "VehicleCommands",
    "VehicleState",
    "load_flight_script",
    "parse_flight_script",
    "read_scenario_file",
    "rotor_thrusts_n",
]
