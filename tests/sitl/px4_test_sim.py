"""A small simulator that speaks only PX4's simulator messages, driving the real plant (sim_bridge.plant).

    python tests/sitl/px4_test_sim.py --ports-file P [--scenario ground] [--speed 1] [--seed 1]

Like PX4's simulators (Gazebo's mavlink_interface, jMAVSim) it listens on TCP (here a free port, written to the
ports file as {"sim": port}; PX4 uses 4560) and, in lockstep, each step sends HIL_STATE_QUATERNION, HIL_GPS
(10 Hz) and HIL_SENSOR (id 0, last: the step's trigger), then waits for the HIL_ACTUATOR_CONTROLS answering that
HIL_SENSOR's time_usec and holds it for one step. Nothing private crosses the link: no ODOMETRY, no NAVIG8_*
(what it receives besides HIL_ACTUATOR_CONTROLS is counted and ignored). pymavlink packs and parses, not the
FC's codec. On SIGINT/SIGTERM it prints a JSON summary line on stdout and exits 0.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import socket
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import common as m2  # noqa: E402

from navig8_fc.mavlink import seam  # noqa: E402
from navig8_fc.mission.geo import GeoOrigin  # noqa: E402
from sim_bridge.messages import ActuatorCommand  # noqa: E402
from sim_bridge.plant import Plant  # noqa: E402
from sim_bridge.world import load_world  # noqa: E402

DT_US = 10_000
GPS_EVERY = 10  # steps (10 Hz)
STEP_TIMEOUT_S = 2.0


def _write_ports(path: str, port: int) -> None:
    tmp = Path(path + ".tmp")
    tmp.write_text(json.dumps({"sim": port}))
    os.replace(tmp, path)  # whole or not at all, as the processes' --ports-file


def _step_frames(mav: Any, s: Any, stamp: int, origin: GeoOrigin, with_gps: bool) -> bytes:
    """One step as PX4's simulator sends it: HIL_STATE_QUATERNION, HIL_GPS every GPS_EVERY steps, HIL_SENSOR."""
    n, e, d = s.pos_ned_m
    lat, lon, alt = origin.to_global((n, e, d))
    vn, ve, vd = (round(v * 100) for v in s.vel_ned_m_s)
    out = mav.hil_state_quaternion_encode(
        stamp, s.quat_wxyz, *s.gyro_frd_rad_s, round(lat * 1e7), round(lon * 1e7), round(alt * 1000), vn, ve, vd,
        0, 0, *(round(x / 9.80665 * 1000) for x in s.accel_frd_m_s2)).pack(mav)
    if with_gps:
        out += mav.hil_gps_encode(stamp, 3, round(lat * 1e7), round(lon * 1e7), round(alt * 1000), 30, 30,
                                  round(math.hypot(vn, ve)), vn, ve, vd, 65535, 12).pack(mav)
    return out + mav.hil_sensor_encode(stamp, *s.accel_frd_m_s2, *s.gyro_frd_rad_s, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                                       0b111111, 0).pack(mav)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--ports-file", required=True)
    ap.add_argument("--scenario", default="ground")
    ap.add_argument("--speed", type=float, default=1.0)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args(argv)
    w = load_world(a.scenario, {})
    plant = Plant(w.vehicle, w.plant, w.scenario, np.random.default_rng(a.seed))
    limits = seam.ControlsScale.from_vehicle(w.vehicle)
    origin = GeoOrigin()  # the FC's default ORIGIN_* parameters: both ends must agree on it
    stop = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.append(1))

    srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    _write_ports(a.ports_file, srv.getsockname()[1])
    srv.settimeout(0.2)
    conn = None
    while conn is None and not stop:
        try:
            conn, _ = srv.accept()
        except TimeoutError:
            continue
    counts = {"steps": 0, "answers": 0, "other": 0, "resends": 0}
    if conn is None:
        print(json.dumps(counts))
        return 0
    conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    conn.settimeout(0.05)
    mav = m2.MAVLink(None, srcSystem=1, srcComponent=51)
    cmd = ActuatorCommand((0.0, 0.0), (0.0, 0.0, 0.0), None)
    wall0 = time.monotonic()
    max_alt = 0.0
    while not stop:
        stamp = seam.time_usec_from_sim_us(plant.t_us)
        out = _step_frames(mav, plant.sense_wire(), stamp, origin, counts["steps"] % GPS_EVERY == 0)
        conn.sendall(out)
        sent = time.monotonic()
        answered = False
        while not answered and not stop:
            try:
                data = conn.recv(4096)
            except TimeoutError:
                data = None
            except OSError:  # reset: the FC went away
                data = b""
            if data == b"":
                stop.append(1)  # the FC went away
                break
            for m in mav.parse_buffer(data) or [] if data else []:
                if m.get_type() == "HIL_ACTUATOR_CONTROLS" and m.time_usec == stamp:
                    ac = seam.decode_actuator_controls(m.to_dict(), limits)
                    cmd = ActuatorCommand(ac.tilt_rad, ac.speed_rad_s, None)
                    counts["answers"] += 1
                    answered = True
                else:
                    counts["other"] += 1
            if not answered and time.monotonic() - sent > STEP_TIMEOUT_S:
                conn.sendall(out)
                counts["resends"] += 1
                sent = time.monotonic()
        if not answered:
            break
        plant.step_us(cmd, DT_US)
        counts["steps"] += 1
        max_alt = max(max_alt, -plant.truth_floats().pos_ned_m[2])
        if a.speed > 0:  # pace: step k not before wall0 + t_k / speed
            lag = wall0 + plant.t_us * 1e-6 / a.speed - time.monotonic()
            if lag > 0:
                time.sleep(lag)
    tr = plant.truth_floats()
    print(json.dumps({**counts, "t_s": plant.t_us * 1e-6, "pos_ned_m": list(tr.pos_ned_m), "max_alt_m": max_alt}),
          flush=True)
    conn.close()
    srv.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
