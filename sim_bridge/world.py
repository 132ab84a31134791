"""World overrides: one run's world (plant, scenario, vehicle, the controller's model of it) from the YAML files
with named changes, so a campaign row is reproducible alone (`navig8-sim --world NAME=VALUE ...`).

A name is a dotted path into one of four documents, list items by index:

    plant.<path>        params/plant.yaml            plant.joint_servo.v_max_rad_s=2.0
    scenario.<path>     the scenario's YAML          scenario.events.0.mass_kg=3   scenario.arm.amplitude_deg=30
    vehicle.<path>      params/vehicle.yaml, the true vehicle and the controller's model alike
    fc_vehicle.<path>   params/vehicle.yaml as the controller alone sees it (model errors)

or one of the derived names in DERIVED (sensor_noise_scale, actuator_bandwidth_scale, arm_servo_speed_scale: the
plant's; tail_max_thrust_n: the vehicle's, truth and model alike). `NAME=VALUE` sets the value; `NAME*=VALUE`
multiplies it (a key ending in `*`), e.g. `fc_vehicle.uav.mass_kg*=1.1` is a controller that believes the UAV
10 % heavier.
An unknown name or a path that is not in the file is a ValueError, before anything runs; the documents'
own validation (PlantParams, Scenario, VehicleConfig) then checks the values.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path
from typing import Any

from navig8_fc.core.vehicle import VehicleConfig
from navig8_fc.flight.script import read_scenario_file
from navig8_fc.yaml_text import safe_load
from sim_bridge.params import PlantParams
from sim_bridge.scenario import Scenario

DOCUMENTS = ("plant", "scenario", "vehicle", "fc_vehicle")


@dataclass(frozen=True)
class World:
    vehicle: VehicleConfig  # the truth the plant integrates
    fc_vehicle: VehicleConfig  # the constants the flight controller uses (== vehicle without model errors)
    plant: PlantParams
    scenario: Scenario


def _scale_sigmas(docs: dict[str, Any], factor: float, _scale: bool) -> None:
    sens = docs["plant"]["sensors"]
    for k in sens:
        if "_sigma_" in k:
            sens[k] = float(sens[k]) * factor


def _scale_bandwidth(docs: dict[str, Any], factor: float, _scale: bool) -> None:
    for name in ("tilt", "speed"):
        d = docs["plant"]["actuators"][name]
        d["omega_n_rad_s"] = float(d["omega_n_rad_s"]) * factor


def _scale_servo_speed(docs: dict[str, Any], factor: float, _scale: bool) -> None:
    # The servo's motion played slower in time by 1/factor: v by factor, a by factor^2, so a move keeps its shape
    # (v^2/a, the distance spent accelerating, is unchanged) and only takes longer. Scaling a linearly would
    # make a slow servo reach its rate almost at once (4 -> 0.3 rad/s at 42 -> 3.2 rad/s^2: 0.1 s), a
    # fast-accelerating slow servo, which is not what a geared-down heavy-payload servo is.
    if not factor > 0.0:
        raise ValueError(f"world override 'arm_servo_speed_scale': must be > 0, got {factor}")
    d = docs["plant"]["joint_servo"]
    d["v_max_rad_s"] = float(d["v_max_rad_s"]) * factor
    d["a_max_rad_s2"] = float(d["a_max_rad_s2"]) * factor * factor


def tail_speed_limit_rad_s(vehicle_doc: Mapping[str, Any]) -> float:
    """The tail propeller's largest speed magnitude (vehicle.limits.tail_speed_rad_s): where it gives its
    maximum thrust K_T2 w^2."""
    return max(abs(float(w)) for w in vehicle_doc["limits"]["tail_speed_rad_s"])


def _tail_max_thrust(docs: dict[str, Any], value: float, scale: bool) -> None:
    # K_T2 = T / w_max^2, and K_Q2 with it so the tail's drag torque per newton (K_Q2/K_T2, 0.02 m in
    # params/vehicle.yaml) stays the propeller's: a stronger tail is a bigger propeller of the same kind, not a
    # propeller without drag (navig8_tools.authority.with_tail_thrust makes the same choice).
    prop = docs["vehicle"]["propulsion"]
    w = tail_speed_limit_rad_s(docs["vehicle"])
    kt_old, kq_old = float(prop["k_thrust_tail"]), float(prop["k_torque_tail"])
    thrust = kt_old * w * w * value if scale else value
    if not (thrust > 0.0 and kt_old > 0.0 and w > 0.0):
        raise ValueError(f"world override 'tail_max_thrust_n': the thrust must be > 0 (got {thrust} N) on a tail "
                         f"with K_T2 > 0 and a speed limit > 0")
    kt = thrust / (w * w)
    prop["k_thrust_tail"] = kt
    prop["k_torque_tail"] = kq_old * kt / kt_old


@dataclass(frozen=True)
class Derived:
    """A name that changes several entries at once. `apply(docs, value, scaled)`: `scaled` is True for
    `NAME*=VALUE`. `vehicle`: it changes the vehicle document, the truth and the controller's model alike, so
    it applies before fc_vehicle is split off (as a `vehicle.` name does)."""

    apply: Callable[[dict[str, Any], float, bool], None]
    description: str
    vehicle: bool = False


# The scale names take a factor, so `NAME=VALUE` and `NAME*=VALUE` are the same for them; tail_max_thrust_n
# takes newtons, and `tail_max_thrust_n*=F` multiplies the tail's current maximum thrust by F.
DERIVED: dict[str, Derived] = {
    "sensor_noise_scale": Derived(_scale_sigmas, "multiplies every sensor sigma in plant.sensors"),
    "actuator_bandwidth_scale": Derived(_scale_bandwidth,
                                        "multiplies omega_n of the duct-tilt and propeller-speed dynamics"),
    "arm_servo_speed_scale": Derived(_scale_servo_speed, "multiplies plant.joint_servo.v_max_rad_s by the factor "
                                     "and a_max_rad_s2 by its square (the servo's motion slowed in time)"),
    "tail_max_thrust_n": Derived(_tail_max_thrust, "the tail's maximum thrust (N) at its speed limit: sets "
                                 "vehicle.propulsion.k_thrust_tail, and k_torque_tail keeping K_Q2/K_T2",
                                 vehicle=True),
}


def _index(node: Any, key: str, name: str) -> tuple[Any, Any]:
    """(container, key) of `key` in node, or ValueError naming the override."""
    if isinstance(node, list):
        try:
            i = int(key)
            node[i]
        except (ValueError, IndexError):
            raise ValueError(f"world override {name!r}: no item {key!r} in a list of {len(node)}") from None
        return node, i
    if isinstance(node, dict) and key in node:
        return node, key
    keys = sorted(node) if isinstance(node, dict) else "-"
    raise ValueError(f"world override {name!r}: no key {key!r} here (keys: {keys})")


def _apply_one(docs: dict[str, Any], name: str, value: float) -> None:
    scale = name.endswith("*")
    path = name[:-1] if scale else name
    if path in DERIVED:
        DERIVED[path].apply(docs, float(value), scale)
        return
    doc, _, rest = path.partition(".")
    if doc not in DOCUMENTS or not rest:
        raise ValueError(f"world override {name!r}: expected one of {DOCUMENTS} + '.path', or {sorted(DERIVED)}")
    node: Any = docs[doc]
    keys = rest.split(".")
    for k in keys[:-1]:
        parent, key = _index(node, k, name)
        node = parent[key]
    parent, key = _index(node, keys[-1], name)
    old = parent[key]
    if scale:
        if isinstance(old, list):
            parent[key] = [float(x) * float(value) for x in old]
        elif isinstance(old, (int, float)) and not isinstance(old, bool):
            parent[key] = float(old) * float(value)
        else:
            raise ValueError(f"world override {name!r}: cannot scale {old!r}")
    else:
        if isinstance(old, (dict, list)):
            raise ValueError(f"world override {name!r}: {path} is a {type(old).__name__}; set one of its entries")
        parent[key] = value


def _packaged_yaml(name: str) -> dict[str, Any]:
    return safe_load((files("navig8_params") / name).read_text())


def world_documents(scenario: str | Path, overrides: Mapping[str, float] | None = None) -> dict[str, Any]:
    """The four raw documents with the overrides applied in order (the caller's dict order)."""
    docs: dict[str, Any] = {
        "plant": _packaged_yaml("plant.yaml"),
        "scenario": copy.deepcopy(read_scenario_file(scenario)),
        "vehicle": _packaged_yaml("vehicle.yaml"),
    }
    # A scenario may carry its own overrides (`world: {NAME: VALUE}`, e.g. a controller with a wrong model); the
    # caller's apply after them.
    own = docs["scenario"].pop("world", None) or {}
    if any(str(name).startswith("scenario.") for name in own):
        raise ValueError(f"a scenario's own world overrides cannot change the scenario: {sorted(own)}")
    items = [(str(n), float(v)) for n, v in own.items()] + list((overrides or {}).items())
    # `vehicle.` (and a derived name of the vehicle) is the truth and the controller's model alike: apply it before
    # fc_vehicle is split off.
    first = [is_vehicle_name(name) for name, _ in items]
    for (name, value), vehicle in zip(items, first, strict=True):
        if vehicle:
            _apply_one(docs, name, value)
    docs["fc_vehicle"] = copy.deepcopy(docs["vehicle"])
    for (name, value), vehicle in zip(items, first, strict=True):
        if not vehicle:
            _apply_one(docs, name, value)
    return docs


def is_vehicle_name(name: str) -> bool:
    """A name that changes the vehicle document (truth and controller's model alike): `vehicle.<path>` or a
    derived name of the vehicle (tail_max_thrust_n)."""
    path = name.removesuffix("*")
    return path.startswith("vehicle.") or (path in DERIVED and DERIVED[path].vehicle)


def load_world(scenario: str | Path, overrides: Mapping[str, float] | None = None) -> World:
    """The run's world: scenario by name or path, then `overrides` (names as in the module docstring)."""
    d = world_documents(scenario, overrides)
    return World(vehicle=VehicleConfig.from_dict(d["vehicle"]), fc_vehicle=VehicleConfig.from_dict(d["fc_vehicle"]),
                 plant=PlantParams.from_dict(d["plant"]), scenario=Scenario.from_dict(d["scenario"]))


def parse_world_items(items: list[str]) -> dict[str, float]:
    """`NAME=VALUE` / `NAME*=VALUE` strings (the command line's --world) as an ordered dict {NAME or NAME*: VALUE}."""
    out: dict[str, float] = {}
    for it in items:
        name, sep, value = it.partition("=")
        if not sep or not name.strip():
            raise ValueError(f"--world expects NAME=VALUE or NAME*=VALUE, got {it!r}")
        try:
            out[name.strip()] = float(value)
        except ValueError:
            raise ValueError(f"--world {it!r}: the value must be a number") from None
    return out


def world_args(overrides: Mapping[str, float]) -> list[str]:
    """The command-line form of `overrides` (inverse of parse_world_items), for replay commands."""
    return [a for name, value in overrides.items() for a in ("--world", f"{name}={value!r}")]


__all__ = ["World", "Derived", "DERIVED", "DOCUMENTS", "load_world", "world_documents", "parse_world_items",
           "world_args", "is_vehicle_name", "tail_speed_limit_rad_s"]
