"""navig8-fc: the flight-controller process. The only FC code that touches sockets and clocks.

Links (PX4 SITL layout, ports offset per instance N):
- sim link: binds 127.0.0.1:4561+2N, talks to the bridge at 127.0.0.1:4560+2N (lockstep, docs/bridge.md);
- GCS link: binds :18570+N, sends to 14550 (QGroundControl, MAVProxy) until a GCS talks, then replies to it;
- API link: binds :14580+N, sends to 14540+N (MAVSDK, scripts).

Time: control, estimator, modes and sensor timeouts run on the bundle's time_usec (sim time, lockstep);
GCS telemetry, heartbeats and parameter pacing run on the wall clock, so a GCS sees 1 Hz heartbeats
whatever the simulation speed (mavlink_notes §1.3).

The options: `FcOptions` and the command line that fills it (`build_arg_parser`, `options_from_args`).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

from navig8_fc.shell.foxglove_out import DEFAULT_PORT as FOXGLOVE_DEFAULT_PORT


@dataclass(frozen=True)
class FcOptions:
    instance: int = 0
    scenario: str = "ground"
    host: str = "127.0.0.1"
    gcs_host: str = "127.0.0.1"
    bind_host: str = "127.0.0.1"
    sim_port: int | None = None
    bridge_port: int | None = None
    gcs_bind_port: int | None = None
    gcs_port: int = 14550
    api_bind_port: int | None = None
    api_port: int | None = None
    log_path: Path | None = None
    state_dir: Path | None = None
    defaults: bool = False
    ports_file: Path | None = None  # written after binding: {"sim": p, "gcs": p, "api": p}
    autopilot: str = "generic"  # HEARTBEAT.autopilot: "generic" or "px4" (docs/gcs.md, "Autopilot identity")
    foxglove_port: int | None = None  # --foxglove[=PORT]: serve the Foxglove channels live (0: any free port)
    foxglove_host: str = "127.0.0.1"
    foxglove_origins: tuple[str, ...] = ()  # --foxglove-allow-origin: browser origins allowed besides the defaults
    log_max_mb: float = 1024.0  # --log-max-mb: rotate the log at this size (0: no cap)
    log_keep: int = 4  # --log-keep: rotated parts kept after the first (the oldest of them is deleted)
    # connection strings (navig8_fc/links/transport.py: udpin:, udpout:, tcp:, tcpin:, serial:) replacing a link's
    # host/port options; None: UDP as the port options say
    sim_link: str | None = None
    gcs_link: str | None = None
    api_link: str | None = None
    sim_messages: str = "navig8"  # --sim-messages: navig8 (the private bundle) or px4 (PX4's simulator messages)
    timing: str | None = None  # --timing lockstep|realtime: overrides the FC_TIMING parameter (docs/hil.md)
    vehicle_path: Path | None = None  # --vehicle: its constants (vehicle.yaml format); None: packaged

    @property
    def sysid(self) -> int:
        return self.instance + 1

    def port(self, name: str) -> int:
        n = self.instance
        defaults = {"sim": 4561 + 2 * n, "bridge": 4560 + 2 * n, "gcs_bind": 18570 + n, "api_bind": 14580 + n,
                    "api": 14540 + n}
        v = getattr(self, f"{name}_port")
        return int(v) if v is not None else defaults[name]



def build_arg_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="navig8-fc", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--instance", type=int, default=0, help="sysid N+1, all ports offset by N")
    ap.add_argument("--scenario", default="ground")
    ap.add_argument("--host", default="127.0.0.1", help="sim-link host (bridge)")
    ap.add_argument("--gcs-host", default="127.0.0.1", help="where to send GCS/API traffic before a peer talks")
    ap.add_argument("--bind-host", default="127.0.0.1", help="address the GCS/API links bind (0.0.0.0 in Docker)")
    ap.add_argument("--sim-port", type=int, default=None)
    ap.add_argument("--bridge-port", type=int, default=None)
    ap.add_argument("--gcs-bind-port", type=int, default=None)
    ap.add_argument("--gcs-port", type=int, default=14550)
    ap.add_argument("--api-bind-port", type=int, default=None)
    ap.add_argument("--api-port", type=int, default=None)
    ap.add_argument("--log", default=None, help="MCAP log path")
    ap.add_argument("--log-max-mb", type=float, default=FcOptions.log_max_mb,
                    help="rotate the log at this size in MB: PATH, PATH-stem.1.mcap, ... (0: no cap; docs/logs.md)")
    ap.add_argument("--log-keep", type=int, default=FcOptions.log_keep,
                    help="log parts kept after the first when rotating (the first, the flight's start, is never "
                         "deleted; of the others the oldest is)")
    ap.add_argument("--state-dir", default=None, help="directory for persisted parameters")
    ap.add_argument("--defaults", action="store_true", help="start from default parameters (ignore stored)")
    ap.add_argument("--autopilot", choices=["generic", "px4"], default="generic",
                    help="HEARTBEAT.autopilot: generic (default) or px4 (QGroundControl's mode menu; docs/gcs.md)")
    ap.add_argument("--until-done", action="store_true", help="exit when the bridge reports the scenario done")
    ap.add_argument("--ports-file", default=None,
                    help='after binding, write {"sim": p, "gcs": p, "api": p} here as JSON (for ports given as 0; '
                         'with --foxglove also "foxglove")')
    ap.add_argument("--foxglove", nargs="?", type=int, const=FOXGLOVE_DEFAULT_PORT, default=None, metavar="PORT",
                    help=f"serve the Foxglove 3D channels live over WebSocket (default port {FOXGLOVE_DEFAULT_PORT}; "
                         "0: any free port)")
    ap.add_argument("--foxglove-host", default="127.0.0.1", help="address the Foxglove server binds")
    ap.add_argument("--foxglove-allow-origin", action="append", default=[], metavar="ORIGIN",
                    help="a browser origin allowed to open the Foxglove WebSocket besides https://app.foxglove.dev and "
                         "clients that send none (repeatable; '*': any; docs/foxglove.md)")
    conn = ("a connection string instead of the port options: udpin:H:P, udpout:H:P, tcp:H:P, tcpin:H:P, "
            "serial:DEVICE:BAUD (docs/hil.md)")
    ap.add_argument("--sim-link", default=None, metavar="CONN", help=f"the bridge/simulator link as {conn}; PX4's "
                    "simulator interface is tcp:127.0.0.1:4560")
    ap.add_argument("--gcs-link", default=None, metavar="CONN", help=f"the GCS link as {conn}")
    ap.add_argument("--api-link", default=None, metavar="CONN", help=f"the API link as {conn}")
    ap.add_argument("--sim-messages", choices=["navig8", "px4"], default="navig8",
                    help="what the sim link carries: navig8 (the private bundle, docs/bridge.md) or px4 (PX4's "
                         "simulator messages HIL_SENSOR + HIL_STATE_QUATERNION; docs/hil.md)")
    ap.add_argument("--vehicle", default=None, metavar="FILE",
                    help="the vehicle's constants (params/vehicle.yaml's format; default the packaged file): a board's "
                         "own airframe, or the world navig8-sitl --world gives the bridge (navig8-bridge "
                         "--write-fc-vehicle)")
    ap.add_argument("--timing", choices=["lockstep", "realtime"], default=None,
                    help="timing mode, overriding the FC_TIMING parameter: lockstep (one step per bundle) or realtime "
                         "(own clock at INDI_RATE_HZ; the bridge then runs --free-run; docs/hil.md)")
    return ap


def options_from_args(a: argparse.Namespace) -> FcOptions:
    return FcOptions(
        instance=a.instance, scenario=a.scenario, host=a.host, gcs_host=a.gcs_host, bind_host=a.bind_host,
        sim_port=a.sim_port, bridge_port=a.bridge_port, gcs_bind_port=a.gcs_bind_port, gcs_port=a.gcs_port,
        api_bind_port=a.api_bind_port, api_port=a.api_port, log_path=Path(a.log) if a.log else None,
        state_dir=Path(a.state_dir) if a.state_dir else None, defaults=a.defaults,
        ports_file=Path(a.ports_file) if a.ports_file else None, autopilot=a.autopilot, foxglove_port=a.foxglove,
        foxglove_host=a.foxglove_host, foxglove_origins=tuple(a.foxglove_allow_origin), log_max_mb=a.log_max_mb,
        log_keep=a.log_keep, sim_link=a.sim_link,
        gcs_link=a.gcs_link, api_link=a.api_link, timing=a.timing, sim_messages=a.sim_messages,
        vehicle_path=Path(a.vehicle) if a.vehicle else None,
    )
