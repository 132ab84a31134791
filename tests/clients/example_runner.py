"""Runs one of MAVSDK-Python's examples against a fresh SITL pair: the PX4 identity (`--autopilot px4`), the origin
at PX4 SITL's home (the examples' coordinates are around it), the example copied unmodified but for its
connection address (the pair's API port; the examples say `udpin://0.0.0.0:14540`), `import mavsdk` answered by
the shim (tests/clients/shim: the pinned wrapper installs as `mavsdk_grpc`), its own mavsdk_server gRPC port.
The examples that connect to a mavsdk_server of their own (`System(mavsdk_server_address="localhost", port=50051)`
and a serial address: the MAVFTP ones) get one started here on that port (the shim maps 50051 to the example's own
port), connected to the pair; their serial address is their connection address and is replaced the same way. An
example that takes its connection and files as arguments (upload_params) gets them from `argv` ("{address}": the
pair's API address; the files named are copied beside it).
The example runs in its own process group, is killed after `timeout_s` (the streaming examples never end by
themselves) and its output is returned with its exit code."""

from __future__ import annotations

import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import mavsdk_grpc
from sitl_helpers import gcs_client, sitl, wait_for, wait_heartbeat

HERE = Path(__file__).resolve().parent
EXAMPLES = HERE / "mavsdk_examples"
SHIM = HERE / "shim"
PX4_HOME_E7 = (473977420, 85455940)  # PX4 SITL's default home (PX4_HOME_LAT/LON), 488 m AMSL
PX4_HOME_ALT_MM = 488000
EXAMPLE_ADDRESS = "udpin://0.0.0.0:14540"
SERIAL_ADDRESS = "serial:///dev/ttyACM0:57600"  # the MAVFTP examples' (with a mavsdk_server of their own)
EXTERNAL_SERVER = 'mavsdk_server_address="localhost"'
MAVSDK_SERVER = Path(mavsdk_grpc.__file__).resolve().parent / "bin" / "mavsdk_server"
SPEED = 2.0  # the pair's speed: the examples pace themselves on the wall clock, the vehicle flies twice as fast


@dataclass(frozen=True)
class ExampleRun:
    name: str
    returncode: int | None  # None: still running at the timeout (killed)
    output: str
    wall_s: float
    fc_log: Path
    work: Path  # where the example ran (the files it wrote)


def _free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _prepare(name: str, work: Path, address: str, files: tuple[Path, ...]) -> bool:
    """The example beside its files in `work`, its connection address replaced; True when it connects to a
    mavsdk_server of its own (the runner starts one)."""
    source = (EXAMPLES / f"{name}.py").read_text()
    external = EXTERNAL_SERVER in source
    if external:
        assert SERIAL_ADDRESS in source, f"{name}: its connection address is not {SERIAL_ADDRESS}"
        source = source.replace(SERIAL_ADDRESS, address)
    elif EXAMPLE_ADDRESS in source:
        source = source.replace(EXAMPLE_ADDRESS, address)
    else:
        assert "args.connection" in source, f"{name}: its connection address is not {EXAMPLE_ADDRESS}"
    (work / f"{name}.py").write_text(source)
    shutil.copy(EXAMPLES / "example-mission.plan", work)  # mission_import.py reads it from its directory
    for f in files:
        shutil.copy(f, work)
    return external


def run_example(name: str, tmp: Path, timeout_s: float, until: str | None = None, argv: tuple[str, ...] = (),
                files: tuple[Path, ...] = (), autopilot: str = "px4") -> ExampleRun:
    """`until`: a regular expression; the example is stopped as soon as its output matches (a streaming example's
    proof of work), else at `timeout_s`. `argv`: the example's arguments ("{address}" is the pair's API address);
    `files`: copied beside it. `autopilot`: the FC's identity (`navig8-fc --autopilot`)."""
    with sitl(tmp, scenario="ground", speed=SPEED, fc_args=["--autopilot", autopilot]) as run:
        gcs = gcs_client(run.gcs_port)
        try:
            assert wait_heartbeat(gcs, 20.0) is not None
            gcs.mav.set_gps_global_origin_send(1, *PX4_HOME_E7, PX4_HOME_ALT_MM)
            assert wait_for(gcs, "GPS_GLOBAL_ORIGIN", 5.0, lambda m: m.latitude == PX4_HOME_E7[0]) is not None
        finally:
            gcs.close()
        work = tmp / "example"
        work.mkdir()
        address = f"udpin://127.0.0.1:{run.api_port}"
        external = _prepare(name, work, address, files)
        grpc_port = _free_tcp_port()
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in (str(SHIM), os.environ.get("PYTHONPATH"))
                                                          if p),
                   PYTHONUNBUFFERED="1", NAVIG8_MAVSDK_GRPC_PORT=str(grpc_port))
        # in the example's directory: a download to "." (ftp_download_file) lands there, never in the checkout
        server = (subprocess.Popen([str(MAVSDK_SERVER), "-p", str(grpc_port), address], cwd=work,
                                   stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                   start_new_session=True)
                  if external else None)
        try:
            return _run(name, work, env, timeout_s, until, [a.replace("{address}", address) for a in argv], run.log)
        finally:
            if server is not None:
                os.killpg(server.pid, signal.SIGKILL)
                server.wait(timeout=10)


def _run(name: str, work: Path, env: dict[str, str], timeout_s: float, until: str | None, argv: list[str],
         fc_log: Path) -> ExampleRun:
    t0 = time.monotonic()
    proc = subprocess.Popen([sys.executable, f"{name}.py", *argv], cwd=work, env=env, stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True)
    out: list[str] = []
    try:
        pattern = re.compile(until) if until else None
        deadline = t0 + timeout_s
        os.set_blocking(proc.stdout.fileno(), False)  # type: ignore[union-attr]
        buf = b""
        while time.monotonic() < deadline and proc.poll() is None:
            chunk = proc.stdout.read()  # type: ignore[union-attr]
            if chunk:
                buf += chunk
                if pattern is not None and pattern.search(buf.decode(errors="replace")):
                    break
            else:
                time.sleep(0.05)
    finally:
        code = proc.poll()
        if code is None:
            os.killpg(proc.pid, signal.SIGKILL)  # the example and its mavsdk_server
            proc.wait(timeout=10)
        else:
            try:
                os.killpg(proc.pid, signal.SIGKILL)  # a mavsdk_server left behind by an example that ended
            except ProcessLookupError:
                pass
        rest = proc.stdout.read() or b""  # type: ignore[union-attr]
        out.append((buf + rest).decode(errors="replace"))
    return ExampleRun(name, code, "".join(out), time.monotonic() - t0, fc_log, work)
