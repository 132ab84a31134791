"""Plant parameters (params/plant.yaml) as a frozen, validated dataclass."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from navig8_fc.yaml_text import safe_load


@dataclass(frozen=True)
class ActuatorDynamics:
    """Second-order actuator y'' = wn^2 (u - y) - 2 zeta wn y' (paper Sec. 3.1, Eq. 10)."""

    omega_n_rad_s: float
    zeta: float

    def __post_init__(self) -> None:
        if not (self.omega_n_rad_s > 0.0 and self.zeta > 0.0):
            raise ValueError(f"actuator dynamics need omega_n > 0 and zeta > 0, got {self}")


@dataclass(frozen=True)
class SensorParams:
    """Sample rates (Hz), white-noise standard deviations per sample, and constant biases (the same offset on
    every body axis; 0 in plant.yaml, set by a campaign's sensor-bias factor)."""

    imu_rate_hz: float = 100.0
    mocap_rate_hz: float = 100.0
    actuator_rate_hz: float = 100.0
    joint_rate_hz: float = 100.0
    gyro_sigma_rad_s: float = 0.01
    accel_sigma_m_s2: float = 0.5
    prop_speed_sigma_rad_s: float = 20.0
    duct_tilt_sigma_rad: float = 0.08
    joint_pos_sigma_rad: float = 0.08
    joint_rate_sigma_rad_s: float = 0.01
    mocap_pos_sigma_m: float = 0.001
    mocap_vel_sigma_m_s: float = 0.01
    mocap_att_sigma_rad: float = 0.002
    gyro_bias_rad_s: float = 0.0
    accel_bias_m_s2: float = 0.0

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            negative_ok = "_bias_" in f.name
            if not math.isfinite(v) or (v < 0.0 and not negative_ok) or (f.name.endswith("_hz") and v <= 0.0):
                raise ValueError(f"sensor parameter {f.name} = {v} is invalid")


@dataclass(frozen=True)
class GroundParams:
    """Spring-damper contact with regularised Coulomb friction at points fixed to the UAV body."""

    contact_points_frd_m: tuple[tuple[float, float, float], ...]
    stiffness_n_m: float
    damping_n_s_m: float
    friction_coeff: float
    friction_reg_speed_m_s: float

    def __post_init__(self) -> None:
        if not 0 <= len(self.contact_points_frd_m) <= 8:
            raise ValueError("at most 8 ground contact points")
        if min(self.stiffness_n_m, self.damping_n_s_m, self.friction_coeff) < 0.0:
            raise ValueError("ground contact constants must be >= 0")
        if not self.friction_reg_speed_m_s > 0.0:
            raise ValueError("friction_reg_speed_m_s must be > 0")


def _dynamics(d: dict[str, Any]) -> ActuatorDynamics:
    return ActuatorDynamics(float(d["omega_n_rad_s"]), float(d["zeta"]))


@dataclass(frozen=True)
class PlantParams:
    physics_rate_hz: float
    servo_rate_hz: float
    tilt_dynamics: ActuatorDynamics
    speed_dynamics: ActuatorDynamics
    joint_v_max_rad_s: float
    joint_a_max_rad_s2: float
    sensors: SensorParams
    ground: GroundParams
    # joint-servo faults (robustness tests of the FC's arm preview; none by default): every joint follows its
    # scheduled target joint_lag_s late; joint joint_stall_index (0-2; -1 none) stops dead at joint_stall_t_s
    joint_lag_s: float = 0.0
    joint_stall_index: int = -1
    joint_stall_t_s: float = 0.0
    # duct fault (none by default): the thrust of duct 1 (right) and duct 3 (left), and the drag torque that comes
    # with it, times duct_efficiency[i] from duct_fault_t_s on (a damaged rotor, a partly blocked duct, a weak motor)
    duct_efficiency: tuple[float, float] = (1.0, 1.0)
    duct_fault_t_s: float = 0.0

    def __post_init__(self) -> None:
        h_us = 1e6 / self.physics_rate_hz
        if abs(h_us - round(h_us)) > 1e-9 or round(h_us) < 1:
            raise ValueError(f"the physics step must be a whole number of microseconds, got {h_us} us")
        ratio = self.physics_rate_hz / self.servo_rate_hz
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ValueError("physics_rate_hz must be an integer multiple of servo_rate_hz")
        if not (self.joint_v_max_rad_s > 0.0 and self.joint_a_max_rad_s2 > 0.0):
            raise ValueError("joint servo limits must be > 0")
        if not (self.joint_lag_s >= 0.0 and self.joint_stall_index in (-1, 0, 1, 2) and self.joint_stall_t_s >= 0.0):
            raise ValueError("joint servo faults: lag_s >= 0, stall_joint in -1..2, stall_t_s >= 0")
        if not (len(self.duct_efficiency) == 2 and all(0.0 < e <= 1.0 for e in self.duct_efficiency)
                and math.isfinite(self.duct_fault_t_s) and self.duct_fault_t_s >= 0.0):
            raise ValueError(f"duct fault: two efficiencies in (0, 1] and duct_fault_t_s >= 0, got "
                             f"{list(self.duct_efficiency)}, {self.duct_fault_t_s}")

    @property
    def duct_faulted(self) -> bool:
        """A duct loses efficiency at some time in the run."""
        return any(e != 1.0 for e in self.duct_efficiency)

    @property
    def physics_step_us(self) -> int:
        return round(1e6 / self.physics_rate_hz)

    @property
    def servo_substeps(self) -> int:
        return round(self.physics_rate_hz / self.servo_rate_hz)

    def without_noise(self) -> PlantParams:
        """Same parameters with every sensor sigma set to zero (for physics checks)."""
        zero = {f.name: 0.0 for f in dataclasses.fields(SensorParams) if "sigma" in f.name}
        return dataclasses.replace(self, sensors=dataclasses.replace(self.sensors, **zero))

    @staticmethod
    def from_dict(d: dict[str, Any]) -> PlantParams:
        integ, act, servo = d["integration"], d["actuators"], d["joint_servo"]
        sens, gnd = d["sensors"], d["ground"]
        return PlantParams(
            physics_rate_hz=float(integ["physics_rate_hz"]),
            servo_rate_hz=float(integ["servo_rate_hz"]),
            tilt_dynamics=_dynamics(act["tilt"]),
            speed_dynamics=_dynamics(act["speed"]),
            joint_v_max_rad_s=float(servo["v_max_rad_s"]),
            joint_a_max_rad_s2=float(servo["a_max_rad_s2"]),
            joint_lag_s=float(servo.get("lag_s", 0.0)),
            joint_stall_index=int(servo.get("stall_joint", -1)),
            joint_stall_t_s=float(servo.get("stall_t_s", 0.0)),
            duct_efficiency=tuple(float(e) for e in act.get("duct_efficiency", (1.0, 1.0))),  # type: ignore[arg-type]
            duct_fault_t_s=float(act.get("duct_fault_t_s", 0.0)),
            sensors=SensorParams(**{k: float(v) for k, v in sens.items()}),
            ground=GroundParams(
                contact_points_frd_m=tuple(
                    (float(p[0]), float(p[1]), float(p[2])) for p in gnd["contact_points_frd_m"]
                ),
                stiffness_n_m=float(gnd["stiffness_n_m"]),
                damping_n_s_m=float(gnd["damping_n_s_m"]),
                friction_coeff=float(gnd["friction_coeff"]),
                friction_reg_speed_m_s=float(gnd["friction_reg_speed_m_s"]),
            ),
        )

    @staticmethod
    def load(path: str | Path | None = None) -> PlantParams:
        """Load params/plant.yaml (default: the packaged copy)."""
        if path is None:
            from importlib.resources import files

            text = (files("navig8_params") / "plant.yaml").read_text()
        else:
            text = Path(path).read_text()
        return PlantParams.from_dict(safe_load(text))
