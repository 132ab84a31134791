"""The flight controller as one pure object: `FlightStack` (mode manager + failsafe decisions + controller core),
its seams (`VehicleCommands`, `VehicleState`, `StepResult`, `Notice`) and the scenario's setpoint script.
navig8-fc, navig8-sim and the tests drive the same `FlightStack`."""

from navig8_fc.flight.script import FlightScript, load_flight_script, parse_flight_script, read_scenario_file
from navig8_fc.flight.stack import FlightStack, rotor_thrusts_n
from navig8_fc.flight.state import ArmRequest, Notice, StepResult, VehicleCommands, VehicleState

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
