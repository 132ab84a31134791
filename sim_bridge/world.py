"""World overrides: one run's world (plant, scenario, vehicle, the controller's model of it) from the YAML files
with named changes, so a campaign row is reproducible alone (`navig8-sim --world NAME=VALUE ...`).

A name is a dotted path into one of four documents, list items by index:

    plant.<path>        params/plant.yaml            plant.joint_servo.v_max_rad_s=2.0
    scenario.<path>     the scenario's YAML          scenario.events.0.mass_kg=3   scenario.arm.amplitude_deg=30
    vehicle.<path>      params/vehicle.yaml, the true vehicle and the controller's model alike
    fc_vehicle.<path>   params/vehicle.yaml as the controller alone sees it (model errors)

or one of the derived names in DERIVED. `NAME=VALUE` sets the value; `NAME*=VALUE` multiplies it (a key
ending in `*`), e.g. `fc_vehicle.uav.mass_kg*=1.1` is a controller that believes the UAV 10 % heavier.
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

import yaml

from navig8_fc.core.vehicle import VehicleConfig
from navig8_fc.flight.script import read_scenario_file
from sim_bridge.params import PlantParams
from sim_bridge.scenario import Scenario

DOCUMENTS = ("plant", "scenario", "vehicle", "fc_vehicle")


@dataclass(frozen=True)
class World:
    vehicle: VehicleConfig  # the truth the plant integrates
    fc_vehicle: VehicleConfig  # the constants the flight controller uses (== vehicle without model errors)
    plant: PlantParams
    scenario: Scenario


def _scale_sigmas(docs: dict[str, Any], factor: float) -> None:
    sens = docs["plant"]["sensors"]
    for k in sens:
        if "_sigma_" in k:
            sens[k] = float(sens[k]) * factor


def _scale_bandwidth(docs: dict[str, Any], factor: float) -> None:
    for name in ("tilt", "speed"):
        d = docs["plant"]["actuators"][name]
        d["omega_n_rad_s"] = float(d["omega_n_rad_s"]) * factor


# Names that change several entries at once (value: a factor, so `NAME=VALUE` and `NAME*=VALUE` are the same).
DERIVED: dict[str, tuple[Callable[[dict[str, Any], float], None], str]] = {
    "sensor_noise_scale": (_scale_sigmas, "multiplies every sensor sigma in plant.sensors"),
    "actuator_bandwidth_scale": (_scale_bandwidth, "multiplies omega_n of the duct-tilt and propeller-speed dynamics"),
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
        DERIVED[path][0](docs, float(value))
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
    return yaml.safe_load((files("navig8_params") / name).read_text())


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
    # `vehicle.` is the truth and the controller's model alike: apply it before fc_vehicle is split off.
    for name, value in items:
        if name.startswith("vehicle."):
            _apply_one(docs, name, value)
    docs["fc_vehicle"] = copy.deepcopy(docs["vehicle"])
    for name, value in items:
        if not name.startswith("vehicle."):
            _apply_one(docs, name, value)
    return docs


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


__all__ = ["World", "DERIVED", "DOCUMENTS", "load_world", "world_documents", "parse_world_items", "world_args"]
