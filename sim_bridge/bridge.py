"""navig8-bridge: the plant behind MAVLink, in lockstep with navig8-fc (docs/bridge.md is the contract).

    navig8-bridge [--scenario NAME|FILE] [--seed N] [--speed X] [--instance N] [--until-done] [--duration S]
                  [--bridge-port P] [--fc-port P] [--host H] [--dt S] [--step-timeout S] [--stall-abort S]
                  [--ports-file PATH]

The bridge is the time master (DESIGN §4). Each step k it sends ONE datagram with the sensor bundle
stamped time_usec = round(k * dt * 1e6) + 1 (ODOMETRY, NAVIG8_ACTUATOR_STATE, NAVIG8_ARM_STATE, NAVIG8_TRUTH,
HIL_SENSOR last) and waits for the FC's single HIL_ACTUATOR_CONTROLS echoing that stamp; it then holds that
command for dt (zero-order hold), steps the plant and sends step k + 1. A thin I/O loop: no controller code.

Ports: --bridge-port 0 binds a free port; --ports-file PATH then receives {"bridge": port} (JSON, written
atomically after binding). Pairing (docs/bridge.md, "Pairing and sequencing"): until paired the bridge sends pair
requests to --fc-port at --host (none with --fc-port 0); the FC's announcement carries a session nonce, the bridge
echoes it and from then on talks only to that address and takes answers only from it.

Exit codes: 0 done (--until-done) or stopped by SIGINT/SIGTERM; 1 cannot start; 2 bad arguments or the
port in use; 3 navig8-fc stalled longer than --stall-abort; 4 the plant diverged.
"""

# The process: options (bridge_options.py), the command line, signals and exit codes. The step loop is
# lockstep.py, the socket, pairing and datagrams fc_link.py.

from __future__ import annotations

import argparse
import signal
import sys
from pathlib import Path
from typing import Any

from navig8_fc.blas import limit_to_one_thread
from navig8_fc.links.mavlink_link import PortInUseError
from navig8_fc.links.transport import parse_connection
from sim_bridge.bridge_options import BASE_BRIDGE_PORT, BridgeOptions
from sim_bridge.lockstep import Bridge, BridgeStalled
from sim_bridge.plant import PlantDivergedError
from sim_bridge.world import parse_world_items

EXIT_OK, EXIT_START, EXIT_USAGE, EXIT_STALL, EXIT_DIVERGED = 0, 1, 2, 3, 4


class _Shutdown(BaseException):
    """SIGINT/SIGTERM: leave the loop, close the socket, exit 0.

    A BaseException (like KeyboardInterrupt) so that no `except Exception` on the way (the datagram
    parser guards against pymavlink bugs with one) can swallow it.
    """


def build_arg_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="navig8-bridge", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenario", default="ground", help="scenario name (params/scenarios) or YAML file")
    ap.add_argument("--seed", type=int, default=1, help="sensor-noise seed")
    ap.add_argument("--speed", type=float, default=1.0, help="1 real time, N N x real time, 0 as fast as possible")
    ap.add_argument("--instance", type=int, default=0, help="vehicle N: sysid N+1, ports 4560+2N / 4561+2N")
    ap.add_argument("--bridge-port", type=int, default=None,
                    help="UDP port the bridge binds (default 4560+2N; 0: any free port, see --ports-file)")
    ap.add_argument("--fc-port", type=int, default=None,
                    help="UDP port navig8-fc listens on (default 4561+2N; 0: learn it from the FC's announcement)")
    ap.add_argument("--host", default="127.0.0.1", help="address to bind and of the FC")
    ap.add_argument("--free-run", action="store_true",
                    help="real time: step on the wall clock at --speed with the newest answer, never wait for the FC "
                         "(for navig8-fc --timing realtime or a board; docs/hil.md)")
    ap.add_argument("--link", default=None, metavar="CONN",
                    help="the FC link as a connection string instead of --bridge-port/--fc-port: udpin:H:P, "
                         "udpout:H:P, tcpin:H:P (PX4's simulator side, 4560), tcp:H:P, serial:DEVICE:BAUD "
                         "(the bundle must fit the line: docs/hil.md)")
    ap.add_argument("--until-done", action="store_true",
                    help="stop at the scenario's duration, send NAVIG8_SIM_STATUS done and exit 0")
    ap.add_argument("--duration", type=float, default=None, help="override the scenario's duration (s)")
    ap.add_argument("--dt", type=float, default=0.01, help="control period (s); must equal 1/INDI_RATE_HZ of the FC")
    ap.add_argument("--step-timeout", type=float, default=2.0, help="wall s to wait for an answer before re-sending")
    ap.add_argument("--stall-abort", type=float, default=20.0,
                    help="wall s without an answer for one step before exiting with code 3")
    ap.add_argument("--startup-timeout", type=float, default=0.0,
                    help="wall s to wait for the FC's first answer (0: forever)")
    ap.add_argument("--grab-mass", type=float, default=None,
                    help="mass (kg) of the object a gripper GRAB picks up (default: the scenario's object)")
    ap.add_argument("--ports-file", default=None, help='after binding, write {"bridge": port} here as JSON')
    ap.add_argument("--world", action="append", default=[], metavar="NAME=VALUE",
                    help="override the plant/scenario/vehicle (NAME*=VALUE scales; names: sim_bridge/world.py)")
    ap.add_argument("--write-fc-vehicle", default=None, metavar="FILE",
                    help="write the vehicle the flight controller should know in this world (the vehicle file with "
                         "the --world overrides of vehicle.* and fc_vehicle.* applied) to FILE for navig8-fc "
                         "--vehicle, and exit")
    return ap


def options_from_args(a: argparse.Namespace) -> BridgeOptions:
    return BridgeOptions(
        scenario=a.scenario, seed=a.seed, speed=a.speed, instance=a.instance, bridge_port=a.bridge_port,
        fc_port=a.fc_port, host=a.host, until_done=a.until_done, duration_s=a.duration, dt_s=a.dt,
        step_timeout_s=a.step_timeout, stall_abort_s=a.stall_abort, startup_timeout_s=a.startup_timeout,
        grab_mass_kg=a.grab_mass, ports_file=Path(a.ports_file) if a.ports_file else None,
        world=tuple(parse_world_items(a.world).items()), link=a.link, free_run=a.free_run,
    )


def _raise_shutdown(signum: int, _frame: Any) -> None:
    raise _Shutdown(signal.Signals(signum).name)


def _check_args(ap: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """What the parser cannot check (exits 2 through ap.error)."""
    if args.scenario.endswith((".yaml", ".yml")) and not Path(args.scenario).is_file():
        ap.error(f"no scenario file {args.scenario}")
    if args.link:
        try:
            parse_connection(args.link)
        except ValueError as e:
            ap.error(str(e))


def _write_fc_vehicle(ap: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    """--write-fc-vehicle: the vehicle the FC should know in this world, written to the file."""
    import yaml

    from sim_bridge.world import world_documents

    try:
        docs = world_documents(args.scenario, parse_world_items(args.world))
    except (ValueError, FileNotFoundError) as e:
        ap.error(str(e))
    Path(args.write_fc_vehicle).parent.mkdir(parents=True, exist_ok=True)
    Path(args.write_fc_vehicle).write_text(yaml.safe_dump(docs["fc_vehicle"], sort_keys=False))
    return EXIT_OK


def _open_bridge(args: argparse.Namespace) -> Bridge | int:
    """The bridge bound to its link, or the exit code of why not (one stderr line)."""
    try:
        return Bridge(options_from_args(args))
    except (ValueError, FileNotFoundError) as e:
        print(f"navig8-bridge: {e}", file=sys.stderr)
        return EXIT_USAGE
    except PortInUseError as e:
        print(f"navig8-bridge: {e.proto} {e.host}:{e.port} is in use by another process; choose another with "
              + ("--link" if args.link else "--bridge-port (0: any free port) or --instance"), file=sys.stderr)
        return EXIT_USAGE
    except OSError as e:
        where = args.link or f"{args.host}:{args.bridge_port or BASE_BRIDGE_PORT + 2 * args.instance}"
        print(f"navig8-bridge: cannot open {where}: {e}", file=sys.stderr)
        return EXIT_START


def main(argv: list[str] | None = None) -> int:
    ap = build_arg_parser()
    args = ap.parse_args(argv)
    _check_args(ap, args)
    limit_to_one_thread()  # navig8_fc/blas.py: why
    if args.write_fc_vehicle:
        return _write_fc_vehicle(ap, args)
    signal.signal(signal.SIGINT, _raise_shutdown)
    signal.signal(signal.SIGTERM, _raise_shutdown)
    bridge: Bridge | None = None
    try:
        opened = _open_bridge(args)
        if isinstance(opened, int):
            return opened
        bridge = opened
        bridge.run()
        print(bridge.summary_line(), file=sys.stderr)
        return EXIT_OK
    except _Shutdown as e:
        if bridge is not None:
            print(f"navig8-bridge: {e}, stopping; " + bridge.summary_line().removeprefix("navig8-bridge: "),
                  file=sys.stderr)
        return EXIT_OK
    except BridgeStalled as e:
        print(str(e), file=sys.stderr)
        if bridge is not None:
            print(bridge.summary_line(), file=sys.stderr)
        return EXIT_STALL
    except PlantDivergedError as e:
        print(f"navig8-bridge: plant diverged: {e}", file=sys.stderr)
        return EXIT_DIVERGED
    finally:
        if bridge is not None:
            bridge.close()
        # a second signal during shutdown (the terminal's Ctrl-C and navig8-sitl's forward) must neither print a
        # traceback nor kill us on the way out
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["build_arg_parser", "main", "options_from_args"]
