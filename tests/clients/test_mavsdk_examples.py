"""MAVSDK-Python's own examples (tests/clients/mavsdk_examples, the MAVSDK-Python repository at the commit its
README names, BSD-3-Clause) run unmodified but for the connection address against `navig8-fc --autopilot px4`,
each against a fresh pair (example_runner.py). Each case says what the example must show: its exit code, a line of
its output, and for the flying ones that the vehicle flew (the FC's own LOCAL_POSITION_NED in the log).

The examples that end with an error end exactly as against PX4 SITL (AS_PX4_SITL: a vehicle without that hardware,
or a file only PX4 hardware has) or are gaps (NOT_YET); both are pinned with the reason (strict: one that starts
passing, or fails otherwise, fails here until it is moved); docs/gcs.md "Client examples" has the table."""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest
from example_runner import PX4_HOME_E7, ExampleRun, run_example
from mcap.reader import make_reader

from navig8_fc.shell.mcap_log import read_mcap


@dataclass(frozen=True)
class Case:
    timeout_s: float
    until: str | None = None  # stop when the output matches (streaming examples never end)
    exits: bool = True  # must end by itself with exit code 0
    climbs_m: float = 0.0  # the vehicle rose at least this high above its start (m)
    expect: str = ""  # a line the output must contain
    orbits: tuple[float, float, float] | None = None  # (lat, lon, radius m): a full turn within ORBIT_TOL_M of it
    rolls_deg: float = 0.0  # the body rolled at least this far right and this far left (ATTITUDE)
    sideways_m: float = 0.0  # and moved at least this far east of its start, then back west by as much
    check: Callable[[ExampleRun], None] | None = None  # evidence the FC did it, beyond the output
    argv: tuple[str, ...] = ()  # the example's arguments ("{address}": the pair's API address)
    files: tuple[Path, ...] = ()  # copied beside the example


def _downloaded_logs_read(r: ExampleRun) -> None:
    """logfile_download wrote the FC's own log (MCAP, whatever the example names it): the library's reader reads it
    with its defaults, and it is the run's (its `run` metadata, the FC's first records)."""
    (log,) = sorted(r.work.glob("log-*.ulog"))
    assert log.read_bytes()[:8] == b"\x89MCAP0\r\n", log
    with log.open("rb") as fh:
        reader = make_reader(fh)
        assert [m.name for m in reader.iter_metadata()][:2] == ["run", "params"]
    with log.open("rb") as fh:
        assert sum(1 for _ in make_reader(fh).iter_messages()) > 100
    assert r.fc_log.read_bytes()[:1000] == log.read_bytes()[:1000]


def _gps_failure_landed(r: ExampleRun) -> None:
    """failure_injection: the GPS failure was injected (GPS_RAW_INT without a fix, the FC's STATUSTEXT) and the
    vehicle, at ~20 m when it came, was landing: at least 10 m lower at the end."""
    texts = [d["text"] for _, _, d in read_mcap(r.fc_log, ["/mavlink/api/out/STATUSTEXT"])]
    assert any("GPS lost (failure injected): landing" in t for t in texts), texts[-20:]
    assert 1 in {d["fix_type"] for _, _, d in read_mcap(r.fc_log, ["/mavlink/api/out/GPS_RAW_INT"])}
    z = [d["z"] for _, _, d in read_mcap(r.fc_log, ["/mavlink/api/out/LOCAL_POSITION_NED"])]
    assert z[-1] - min(z) >= 10.0, (min(z), z[-1])


def _params_set(r: ExampleRun) -> None:
    """upload_params: the file's three parameters of this FC are in force (the FC's parameter log)."""
    got = {d["name"]: d["value"] for _, _, d in read_mcap(r.fc_log, ["/fc/param_change"]) if d["accepted"]}
    assert got == {"MIS_TAKEOFF_ALT": 3.0, "RTL_RETURN_ALT": 4.0, "SYS_FAILURE_EN": 1}, got


PARAMS_FILE = Path(__file__).resolve().parent / "upload_params_example.params"
CASES: dict[str, Case] = {
    "takeoff_and_land": Case(60, climbs_m=2.0, expect="-- Landing"),
    # thrust 0.7 climbs, roll +30 then -30 deg at 0.6 moves right then left (the body rolls to make it), as on PX4
    "offboard_attitude": Case(60, climbs_m=1.0, expect="-- Stopping offboard", rolls_deg=5.0, sideways_m=1.0),
    "offboard_position_ned": Case(120, climbs_m=1.5, expect="-- Stopping offboard"),
    "offboard_velocity_ned": Case(120, climbs_m=1.5, expect="-- Stopping offboard"),
    "offboard_velocity_body": Case(120, climbs_m=1.5, expect="-- Stopping offboard"),
    "offboard_position_velocity_ned": Case(120, climbs_m=1.5, expect="-- Stopping offboard"),
    "mission_raw": Case(30),
    "mission": Case(150, climbs_m=20.0, expect="Mission progress: 3/3"),
    "goto": Case(90, until=r"Staying connected", exits=False, climbs_m=1.0),
    "gripper": Case(30, until=r"Staying connected", exits=False, expect="-- Gripper Release"),
    "firmware_version": Case(30, expect="flight_sw_major: 1"),
    "all_params": Case(60, expect="INDI_K_MIN"),
    "tune": Case(30),
    "telemetry": Case(30, until=r"num_satellites: 10", exits=False),
    "telemetry_flight_mode": Case(30, until=r"FlightMode: READY", exits=False),
    "telemetry_is_armed_is_in_air": Case(30, until=r"Is_armed: False", exits=False),
    "telemetry_status_text": Case(20, until=r"-- Connected to drone!", exits=False),
    "highres_imu": Case(30, until=r"Z Acceleration \(m/s\^2\): -(9|10)\.", exits=False),
    "manual_control": Case(60, until=r"-- Starting manual control", exits=False, climbs_m=1.0),
    "mission_import": Case(30, expect="Mission uploaded"),  # 2 rally points (MAV_MISSION_TYPE_RALLY) too
    "telemetry_takeoff_and_land": Case(90, climbs_m=9.0, expect="Altitude: 10"),  # MIS_TAKEOFF_ALT 10 m
    # DO_ORBIT 10 m, 2 m/s about a point 55 m from home, 10 m up: the approach, then about 3 turns in its 60 s
    "do_orbit": Case(150, climbs_m=9.0, expect="--- Landing", orbits=(47.398036222362471, 8.5450146439425509, 10.0)),
    "ftp_list_dir": Case(30, expect="directory list ListDirectoryData: [entries: [<"),  # "/": the metadata folder
    "logfile_download": Case(90, expect="Downloading: log 0", check=_downloaded_logs_read),
    "failure_injection": Case(120, climbs_m=15.0, expect="-- Disabling failure injection", check=_gps_failure_landed),
    "upload_params": Case(60, expect="Params uploaded!", check=_params_set, argv=("{address}", PARAMS_FILE.name),
                          files=(PARAMS_FILE,)),
}
AS_PX4_SITL = {  # example: (how it ends, on this FC and on PX4 SITL, why)
    "ftp_download_file": ("FtpError: FILE_DOES_NOT_EXIST", "/etc/extras/px4_io-v2_default.bin is the IO "
                          "coprocessor's firmware of PX4 boards that have one; PX4 SITL has no such file either"),
    "calibration": ("CalibrationError: FAILED: 'Failed'; origin: calibrate_accelerometer()",
                    "the gyro calibration runs and ends done; the accelerometer's needs six orientations and a "
                    "vehicle standing on the ground shows one: PX4's 'timeout: no motion' (its SITL ends the same)"),
}
PASSED_FIRST = {"calibration": "-- Gyroscope calibration finished"}  # what a pinned example did before its end
NOT_YET = {  # example: (how it fails today, why; whose the gap is)
    "geofence": ("GeofenceError: INVALID_ARGUMENT", "the client refuses the example's empty circle (radius 0) "
                 "before sending anything: MAVSDK 4.0.5, no MAVLink on the wire, the same against any autopilot"),
}
# In `make test` (each about 10 s with its pair): a flight, the gripper, telemetry, the IMU stream, the version, a
# mission upload and a MAVFTP listing (the runner's own mavsdk_server). The rest (the offboard and mission flights run
# 30-80 s on their own sleeps, and the pinned ends) run in `make test-clients`: all of them would add about 6 min to a
# suite kept under 10 (docs/gcs.md).
QUICK = frozenset({"takeoff_and_land", "gripper", "telemetry", "highres_imu", "firmware_version", "mission_raw",
                   "ftp_list_dir"})
STOP_ON = r"Traceback \(most recent call last\)"  # a failed example stays alive (its mavsdk_server): stop it
ORBIT_TOL_M = 2.0  # an orbit counts while the vehicle stays this close to its radius
EARTH_RADIUS_M = 6_371_000.0  # the FC's flat-earth projection about the origin the runner sets (docs/gcs.md)


def _rise_m(log: Path) -> float:
    z = [d["z"] for _, _, d in read_mcap(log, ["/mavlink/api/out/LOCAL_POSITION_NED"])]
    return -min(z) + z[0] if z else 0.0


def _orbit_turn_deg(log: Path, lat_deg: float, lon_deg: float, radius_m: float) -> float:
    """The largest angle (deg) the vehicle swept about the centre while staying within ORBIT_TOL_M of the radius (the
    FC's own LOCAL_POSITION_NED about the origin the runner set: PX4's home)."""
    lat0, lon0 = PX4_HOME_E7[0] * 1e-7, PX4_HOME_E7[1] * 1e-7
    cn = math.radians(lat_deg - lat0) * EARTH_RADIUS_M
    ce = math.radians(lon_deg - lon0) * EARTH_RADIUS_M * math.cos(math.radians(lat0))
    best = swept = 0.0
    last = None
    for _, _, d in read_mcap(log, ["/mavlink/api/out/LOCAL_POSITION_NED"]):
        dn, de = d["x"] - cn, d["y"] - ce
        if abs(math.hypot(dn, de) - radius_m) > ORBIT_TOL_M:
            swept, last = 0.0, None
            continue
        b = math.atan2(de, dn)
        if last is not None:
            swept += (b - last + math.pi) % (2.0 * math.pi) - math.pi
            best = max(best, abs(swept))
        last = b
    return math.degrees(best)


def _roll_and_sideways(log: Path) -> tuple[float, float, float, float]:
    """(the largest roll right, the largest roll left (deg), how far east of the start the vehicle went, how far back
    west from there (m)), from the FC's ATTITUDE and LOCAL_POSITION_NED."""
    rolls = [math.degrees(d["roll"]) for _, _, d in read_mcap(log, ["/mavlink/api/out/ATTITUDE"])]
    ys = [d["y"] for _, _, d in read_mcap(log, ["/mavlink/api/out/LOCAL_POSITION_NED"])]
    i = max(range(len(ys)), key=ys.__getitem__)
    return max(rolls), -min(rolls), ys[i] - ys[0], ys[i] - min(ys[i:])


def _judge(r: ExampleRun, case: Case) -> None:
    tail = r.output[-3000:]
    assert "Traceback" not in r.output, tail
    if case.exits:
        assert r.returncode == 0, f"{r.name} exit {r.returncode} after {r.wall_s:.0f} s:\n{tail}"
    else:
        assert case.until is not None and re.search(case.until, r.output), tail
    assert case.expect in r.output, tail
    if case.climbs_m > 0.0:
        assert _rise_m(r.fc_log) >= case.climbs_m, (_rise_m(r.fc_log), tail)
    if case.rolls_deg > 0.0:
        right, left, east, back = _roll_and_sideways(r.fc_log)
        print(f"{r.name}: rolled {right:.1f} deg right, {left:.1f} deg left; {east:.2f} m east, {back:.2f} m back")
        assert min(right, left) >= case.rolls_deg and min(east, back) >= case.sideways_m, (right, left, east, back)
    if case.orbits is not None:
        turn = _orbit_turn_deg(r.fc_log, *case.orbits)
        print(f"{r.name}: {turn:.0f} deg within {ORBIT_TOL_M:g} m of the {case.orbits[2]:g} m circle")
        assert turn >= 360.0, (turn, tail)
    if case.check is not None:
        case.check(r)


def _params(names: object) -> list:
    return [pytest.param(n, marks=() if n in QUICK else pytest.mark.clients_all) for n in sorted(names)]


@pytest.mark.parametrize("name", _params(CASES))
def test_example_runs_unmodified(name: str, tmp_path: Path) -> None:
    case = CASES[name]
    until = f"{case.until}|{STOP_ON}" if case.until else STOP_ON
    r = run_example(name, tmp_path, case.timeout_s, until, case.argv, case.files)
    print(f"\n{name}: exit {r.returncode}, {r.wall_s:.1f} s wall")
    _judge(r, case)


@pytest.mark.parametrize("name", _params({**NOT_YET, **AS_PX4_SITL}))
def test_example_fails_as_documented(name: str, tmp_path: Path) -> None:
    """The ends pinned: each fails exactly the documented way (one that passes, or fails otherwise, fails here):
    as against PX4 SITL (AS_PX4_SITL) or a gap (NOT_YET)."""
    error, why = {**NOT_YET, **AS_PX4_SITL}[name]
    r = run_example(name, tmp_path, 60.0, STOP_ON)
    assert error in r.output, f"{name} no longer fails with {error!r} ({why}):\n{r.output[-3000:]}"
    assert PASSED_FIRST.get(name, "") in r.output, r.output[-3000:]


# The same examples against the generic identity (`navig8-fc` without `--autopilot`, MAV_AUTOPILOT_GENERIC): MAVSDK
# flies it as PX4 (it decodes modes the PX4 way for every non-ArduPilot autopilot). What differs (docs/gcs.md, "Client
# examples", "The generic identity"): flight commands keep the long-running protocol (IN_PROGRESS, then the final
# ACK at the end of the climb or the flight), so `takeoff()` and `goto_location()` return when the vehicle gets
# there; AUTOPILOT_VERSION says this FC's own version (0.1.0), not PX4's.
GENERIC_ENDS = {  # example: (how it ends against the generic identity, why)
    "do_orbit": ("ActionError: COMMAND_DENIED", "MAVSDK sends the orbit's altitude AMSL (498 m) in a "
                 "GLOBAL_RELATIVE_ALT frame; PX4, and the PX4 identity, read z as AMSL whatever the frame; the generic "
                 "identity reads the frame: 498 m above home, outside the operating volume (VOL_ALT_MAX)"),
}
GENERIC_CASES: dict[str, Case] = {**{n: c for n, c in CASES.items() if n not in GENERIC_ENDS},
                                  "firmware_version": Case(30, expect="flight_sw_major: 0")}
GENERIC_QUICK = frozenset({"takeoff_and_land"})  # one flight in `make test`; the rest in `make test-clients`


@pytest.mark.parametrize("name", [pytest.param(n, marks=() if n in GENERIC_QUICK else pytest.mark.clients_all)
                                  for n in sorted(GENERIC_CASES)])
def test_example_runs_unmodified_against_the_generic_identity(name: str, tmp_path: Path) -> None:
    case = GENERIC_CASES[name]
    until = f"{case.until}|{STOP_ON}" if case.until else STOP_ON
    r = run_example(name, tmp_path, case.timeout_s, until, case.argv, case.files, autopilot="generic")
    print(f"\n{name} (generic): exit {r.returncode}, {r.wall_s:.1f} s wall")
    _judge(r, case)


@pytest.mark.clients_all
@pytest.mark.parametrize("name", sorted(GENERIC_ENDS))
def test_example_ends_as_documented_against_the_generic_identity(name: str, tmp_path: Path) -> None:
    error, why = GENERIC_ENDS[name]
    r = run_example(name, tmp_path, 90.0, STOP_ON, autopilot="generic")
    assert error in r.output, f"{name} (generic) no longer ends with {error!r} ({why}):\n{r.output[-3000:]}"
