"""navig8-bridge's options (docs/bridge.md): the scenario and world, pacing, the FC link's ports, the time limits."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

BASE_BRIDGE_PORT = 4560  # + 2 N: the bridge binds here (PX4's simulator port)
BASE_FC_PORT = 4561  # + 2 N: the FC's sim link


@dataclass(frozen=True)
class BridgeOptions:
    scenario: str = "ground"
    seed: int = 1
    speed: float = 1.0  # 1 real time, N x real time, 0 as fast as possible
    instance: int = 0
    bridge_port: int | None = None
    fc_port: int | None = None
    host: str = "127.0.0.1"
    until_done: bool = False
    duration_s: float | None = None
    dt_s: float = 0.01  # must equal 1 / INDI_RATE_HZ of the FC
    step_timeout_s: float = 2.0
    stall_abort_s: float = 20.0
    startup_timeout_s: float = 0.0  # 0: wait for the FC forever (reminding every 10 s)
    grab_mass_kg: float | None = None  # object mass a GRAB picks up (default: from the scenario)
    ports_file: Path | None = None  # written after binding: {"bridge": port}
    world: tuple[tuple[str, float], ...] = ()  # world overrides (sim_bridge.world), as navig8-sim --world
    free_run: bool = False  # real time: step on the wall clock with the newest answer, never wait (docs/hil.md)
    link: str | None = None  # connection string of the FC link (udpin:, udpout:, tcpin:, tcp:, serial:); None: UDP

    @property
    def sysid(self) -> int:
        return self.instance + 1

    @property
    def bridge_port_resolved(self) -> int:
        return self.bridge_port if self.bridge_port is not None else BASE_BRIDGE_PORT + 2 * self.instance

    @property
    def fc_port_resolved(self) -> int:
        return self.fc_port if self.fc_port is not None else BASE_FC_PORT + 2 * self.instance
