"""The navig8 MAVLink dialect (generation, cache, wire identity) and the bridge seam's pure encode/decode."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from navig8_fc.core.vehicle import VehicleConfig
from navig8_fc.logrecords import log_truth_record
from navig8_fc.mavlink import codec, dialect, seam
from sim_bridge import ActuatorCommand, Plant, PlantParams, load_scenario

ROOT = Path(__file__).resolve().parents[2]

# (id, CRC_EXTRA, payload bytes) of every navig8 message. CRC_EXTRA changes with any edit of a field's
# name, type or order, and then the bridge and an older FC no longer understand each other: a change here
# must be deliberate (add a new message instead of editing one).
WIRE_IDENTITY = {
    "NAVIG8_ACTUATOR_STATE": (61000, 177, 40),  # 32 + the extension cmd_time_usec (CRC extra unchanged)
    "NAVIG8_ARM_STATE": (61001, 224, 37),
    "NAVIG8_TRUTH": (61002, 55, 208),
    "NAVIG8_ARM_CMD": (61010, 111, 22),
    "NAVIG8_SIM_STATUS": (61020, 116, 25),
}


@pytest.fixture(scope="module")
def d():
    return dialect.load()


@pytest.fixture(scope="module")
def vehicle() -> VehicleConfig:
    return VehicleConfig.load()


def _cls(d, name: str):
    return getattr(d, f"MAVLink_{name.lower()}_message")


def _roundtrip(rec, sysid: int = 3, compid: int = 25) -> dict:
    """A (name, values) record packed by pymavlink, decoded by the codec: its fields."""
    name, values = rec
    frame = _cls(dialect.load(), name)(*values).pack(dialect.new_mav(sysid, compid))
    counts = codec.ParseCounters()
    msgs = codec.seam_codec().parse(frame, counts)
    assert counts == codec.ParseCounters() and len(msgs) == 1
    out = msgs[0]
    assert (out.name, out.sysid, out.compid) == (name, sysid, compid)
    return out.fields


def _messages(step: int, sensors, truth, sysid: int = 1) -> list[codec.Message]:
    """The bundle's messages as the FC receives them (encode_bundle, then the codec's parse)."""
    data = seam.encode_bundle(codec.Encoder(codec.seam_codec(), sysid, 25), step, sensors, truth)
    counts = codec.ParseCounters()
    msgs = codec.seam_codec().parse(data, counts)
    assert counts == codec.ParseCounters()
    return msgs


def _f32(v) -> np.ndarray:
    return np.asarray(v, dtype=np.float64).astype(np.float32).astype(np.float64)


# ---- the dialect --------------------------------------------------------------------------------------
def test_ids_crc_extra_and_sizes_are_stable(d) -> None:
    for name, (msg_id, crc_extra, size) in WIRE_IDENTITY.items():
        c = _cls(d, name)
        assert (c.id, c.crc_extra, c.unpacker.size) == (msg_id, crc_extra, size), name
        assert 61000 <= c.id <= 61999
        assert d.mavlink_map[c.id] is c
        assert c.unpacker.size <= 255  # one MAVLink 2 frame: NAVIG8_TRUTH needs no split


def test_units_are_declared_on_si_fields(d) -> None:
    units = _cls(d, "NAVIG8_TRUTH").fieldunits_by_name
    assert units["reaction_force"] == "N" and units["pos_ned"] == "m" and units["time_usec"] == "us"
    assert _cls(d, "NAVIG8_ACTUATOR_STATE").fieldunits_by_name == {"time_usec": "us", "duct_tilt": "rad",
                                                                   "prop_speed": "rad/s", "cmd_time_usec": "us"}


def test_actuator_state_extension_is_compatible_both_ways(d) -> None:
    """cmd_time_usec is a MAVLink 2 extension: a sender that predates it (its 32-byte payload) decodes with 0, and
    a reader that predates it reads the base fields of the 40-byte frame unchanged (same CRC extra, base first)."""
    tilt, speed = (0.25, -0.125), (600.0, -50.0, 610.0)
    enc = codec.Encoder(codec.seam_codec(), 1, 25)
    stamp = 0x0102_0304_0506_0708  # no zero byte: the whole extension goes out
    new = enc.frame("NAVIG8_ACTUATOR_STATE", (10001, 1, tilt, speed, stamp))
    old = enc.frame("NAVIG8_ACTUATOR_STATE", (10001, 1, tilt, speed, 0))
    assert new[1] == 40 and old[1] == 32  # payload lengths: MAVLink 2 drops the all-zero extension
    (m_new,), (m_old,) = (codec.seam_codec().parse(f, codec.ParseCounters()) for f in (new, old))
    assert m_new.fields["cmd_time_usec"] == stamp and m_old.fields["cmd_time_usec"] == 0
    assert new[10:42] == old[10:42]  # the base payload (after the 10-byte header) is byte for byte the old one
    assert {k: v for k, v in m_new.fields.items() if k != "cmd_time_usec"} == \
        {k: v for k, v in m_old.fields.items() if k != "cmd_time_usec"}


def test_common_is_included_and_mavlink2(d) -> None:
    assert d.WIRE_PROTOCOL_VERSION == "2.0"
    assert d.MAVLINK_MSG_ID_HIL_ACTUATOR_CONTROLS == 93 and d.MAVLINK_MSG_ID_ODOMETRY == 331
    frame = d.MAVLink_heartbeat_message(2, 8, 0, 0, 0, 3).pack(dialect.new_mav(1, 25))
    assert frame[0] == 0xFD
    assert codec.Encoder(codec.seam_codec(), 1, 25).frame(*seam.announce_record())[0] == 0xFD


def test_arm_joints_command_alias(d) -> None:
    # every vendor slot 31000-31014 is named in common.xml; ours is MAV_CMD_USER_1 under a second name
    assert d.MAV_CMD_NAVIG8_ARM_JOINTS == dialect.MAV_CMD_NAVIG8_ARM_JOINTS == d.MAV_CMD_USER_1 == 31010
    entry = d.enums["MAV_CMD"][31010]
    assert "arm joint targets" in entry.description and "degrees" in entry.description
    assert entry.param[4] == "apply (0/1)"


def test_messages_roundtrip_with_float32_precision(d) -> None:
    rng = np.random.default_rng(7)

    def r(n: int) -> list[float]:
        return (rng.standard_normal(n) * 10).tolist()

    tu = 123_456_789_012
    cases = {
        "NAVIG8_ACTUATOR_STATE": dict(time_usec=tu, step=4_000_000_000, duct_tilt=r(2), prop_speed=r(3),
                                      cmd_time_usec=tu - 20_000),
        "NAVIG8_ARM_STATE": dict(time_usec=tu, step=7, joint_pos=r(3), joint_rate=r(3), gripper_closed=1),
        "NAVIG8_TRUTH": dict(time_usec=tu, step=8, pos_ned=r(3), vel_ned=r(3), quat=r(4), rate_frd=r(3),
                             accel_frd=r(3), actuators=r(5), joint_pos=r(3), joint_rate=r(3), joint_accel=r(3),
                             object_mass=2.0, mass=11.5, com_frd=r(3), inertia=r(6), reaction_force=r(3),
                             reaction_moment_mount=r(3), cmd_clamped=5, cmd_nonfinite=2**32 - 1),
        "NAVIG8_ARM_CMD": dict(time_usec=tu, joint_target=r(3), joint_target_valid=1, gripper=2),
        "NAVIG8_SIM_STATUS": dict(time_usec=tu, step=9, state=3, speed=0.0, rtf=41.25, stall_count=3),
    }
    for name, fields in cases.items():
        out = _roundtrip((name, [fields[k] for k in _cls(d, name).fieldnames]))
        for k, v in fields.items():
            got = out[k]
            if isinstance(v, list):
                np.testing.assert_array_equal(got, _f32(v), err_msg=f"{name}.{k}")
            elif isinstance(v, float):
                assert got == float(np.float32(v)), f"{name}.{k}"
            else:
                assert got == v, f"{name}.{k}"


def test_second_load_hits_the_cache(tmp_path: Path) -> None:
    """A fresh process generates once; the next one imports the cached module and its marshalled code."""
    code = (
        "import json, time; t = time.perf_counter(); from navig8_fc.mavlink import dialect; d = dialect.load(); "
        "print(json.dumps({'gen': dialect.last_generation_s, 'load': time.perf_counter() - t, "
        "'file': d.__file__}))"
    )
    env = dict(os.environ, NAVIG8_CACHE_DIR=str(tmp_path / "cache"))

    def run() -> dict:
        out = subprocess.run([sys.executable, "-c", code], env=env, cwd=ROOT, capture_output=True, text=True,
                             timeout=60, check=True)
        return json.loads(out.stdout.strip().splitlines()[-1])

    first, second = run(), run()
    assert first["gen"] is not None  # generated once ...
    assert second["gen"] is None  # ... then imported from the cache (no generation: the speed is in navig8-bench)
    assert Path(first["file"]).parent == tmp_path / "cache"
    assert Path(first["file"]).name == f"navig8_{dialect.cache_key()}.py"
    assert len(list((tmp_path / "cache").glob("navig8_*.code"))) == 1
    assert not list((tmp_path / "cache").glob(".gen-*"))  # the build directory is cleaned up


def test_concurrent_first_loads_agree(tmp_path: Path) -> None:
    """The bridge and the FC start together on a fresh machine: both generate, neither sees a partial file."""
    code = "from navig8_fc.mavlink import dialect; d = dialect.load(); print(d.MAVLink_navig8_truth_message.crc_extra)"
    env = dict(os.environ, NAVIG8_CACHE_DIR=str(tmp_path / "cache"))
    procs = [subprocess.Popen([sys.executable, "-c", code], env=env, cwd=ROOT, stdout=subprocess.PIPE, text=True)
             for _ in range(3)]
    outs = [p.communicate(timeout=60)[0].strip() for p in procs]
    assert [p.returncode for p in procs] == [0, 0, 0]
    assert outs == [str(WIRE_IDENTITY["NAVIG8_TRUTH"][1])] * 3


def test_cache_dir_falls_back_when_not_writable(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    blocker = tmp_path / "a_file"
    blocker.write_text("not a directory")
    monkeypatch.setenv("NAVIG8_CACHE_DIR", str(blocker / "cache"))
    got = dialect.cache_dir()
    assert got != blocker / "cache"
    assert os.access(got, os.W_OK)


def test_generate_reports_mavgen_errors(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    bad = tmp_path / "navig8.xml"
    bad.write_text(dialect.DIALECT_XML.read_text().replace('id="61001"', 'id="61000"'))  # duplicate id
    monkeypatch.setattr(dialect, "DIALECT_XML", bad)
    with pytest.raises(RuntimeError, match="mavgen failed"):
        dialect.generate(tmp_path / "out" / "x.py")
    assert not (tmp_path / "out" / "x.py").exists()


# ---- seam: actuator answer ---------------------------------------------------------------------------
def test_actuator_controls_normalisation_and_roundtrip(d, vehicle: VehicleConfig) -> None:
    lim = seam.ControlsScale.from_vehicle(vehicle)
    assert lim.tilt_max_abs_rad == max(abs(vehicle.tilt_min_rad), abs(vehicle.tilt_max_rad))
    assert lim.duct_speed_max_rad_s == vehicle.duct_speed_max
    assert lim.tail_speed_max_rad_s == vehicle.tail_speed_max
    cmd = ActuatorCommand((0.3, -0.2), (600.0, -123.0, 610.0))
    rec = seam.actuator_controls_record(10_001, cmd, vehicle, armed=True)
    msg = d.MAVLink_hil_actuator_controls_message(*rec[1])
    assert rec[0] == "HIL_ACTUATOR_CONTROLS"
    assert msg.time_usec == 10_001 and msg.flags == 0
    assert msg.mode == seam.MODE_FLAG_SAFETY_ARMED
    expected = [0.3 / lim.tilt_max_abs_rad, -0.2 / lim.tilt_max_abs_rad, 600.0 / lim.duct_speed_max_rad_s,
                -123.0 / lim.tail_speed_max_rad_s, 610.0 / lim.duct_speed_max_rad_s]
    np.testing.assert_allclose(msg.controls[:5], expected, rtol=1e-15)
    assert list(msg.controls[5:]) == [0.0] * 11
    out = seam.decode_actuator_controls(_roundtrip(rec, compid=1), lim)
    assert out.time_usec == 10_001 and out.armed
    np.testing.assert_allclose(out.tilt_rad, cmd.tilt_rad, rtol=1e-7)
    np.testing.assert_allclose(out.speed_rad_s, cmd.speed_rad_s, rtol=1e-7)
    off = seam.decode_actuator_controls(_roundtrip(seam.actuator_controls_record(5, cmd, lim, armed=False)), lim)
    assert not off.armed


def test_actuator_controls_not_clipped_and_nonfinite_pass(vehicle: VehicleConfig) -> None:
    """The plant clamps and counts; clipping in the encoder would hide a bad command from its counters."""
    cmd = ActuatorCommand((5.0, float("nan")), (2000.0, 0.0, float("inf")))
    out = seam.decode_actuator_controls(_roundtrip(seam.actuator_controls_record(1, cmd, vehicle, armed=True)),
                                        vehicle)
    assert out.tilt_rad[0] == pytest.approx(5.0) and math.isnan(out.tilt_rad[1])
    assert out.speed_rad_s[0] == pytest.approx(2000.0) and math.isinf(out.speed_rad_s[2])


def test_limits_reject_nonsense() -> None:
    with pytest.raises(ValueError):
        seam.ControlsScale(0.0, 1.0, 1.0)
    with pytest.raises(ValueError):
        seam.ControlsScale(1.0, float("nan"), 1.0)


# ---- seam: the step bundle ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def plant(vehicle: VehicleConfig) -> Plant:
    p = Plant(vehicle, PlantParams.load(), load_scenario("paper"), np.random.default_rng(3))
    p.step(p.trim_command(), 0.05)
    return p


def test_bundle_roundtrip_from_the_plant(plant: Plant) -> None:
    sb, tr = plant.sense(), plant.truth()
    msgs = _messages(5, sb, tr, sysid=2)
    assert [m.name for m in msgs] == ["ODOMETRY", "NAVIG8_ACTUATOR_STATE", "NAVIG8_ARM_STATE", "NAVIG8_TRUTH",
                                      "HIL_SENSOR"]
    assert len({m.seq for m in msgs}) == 5  # the encoder advanced the sequence
    b = seam.decode_bundle(msgs)
    assert b is not None
    assert b.step == 5 and b.time_usec == sb.time_us + 1 == 50_001 and b.t_us == 50_000
    assert b.t_s == sb.time_us * 1e-6  # exactly what the in-process runner feeds the FC
    for got, want in [(b.gyro_frd_rad_s, sb.gyro_frd_rad_s), (b.accel_frd_m_s2, sb.accel_frd_m_s2), (b.pos_ned_m,
                                                                                                     sb.pos_ned_m),
                      (b.vel_ned_m_s, sb.vel_ned_m_s), (b.quat_wxyz, sb.quat_wxyz), (b.duct_tilt_rad, sb.duct_tilt_rad),
                      (b.prop_speed_rad_s, sb.prop_speed_rad_s), (b.joint_pos_rad, sb.joint_pos_rad),
                      (b.joint_rate_rad_s, sb.joint_rate_rad_s)]:
        np.testing.assert_array_equal(got, _f32(want))
    assert b.gripper_closed is True and b.imu_fresh
    odom = msgs[0].fields
    assert odom["frame_id"] == odom["child_frame_id"] == 1  # MAV_FRAME_LOCAL_NED: velocity in NED
    assert math.isnan(odom["pose_covariance"][0]) and math.isnan(odom["velocity_covariance"][0])
    np.testing.assert_array_equal([odom["rollspeed"], odom["pitchspeed"], odom["yawspeed"]], _f32(sb.gyro_frd_rad_s))
    hil = msgs[-1].fields
    assert hil["fields_updated"] == 0b111111 and hil["id"] == 0
    t = b.truth  # decoded into the plant's Truth vocabulary (seam.TruthFloats)
    np.testing.assert_array_equal(t.reaction_force_frd_n, _f32(tr.reaction_force_frd_n))
    np.testing.assert_array_equal(t.actuator_pos, _f32(tr.actuator_pos))
    np.testing.assert_array_equal(t.inertia_com_kgm2, _f32(tr.inertia_com_kgm2))  # symmetric: six entries sent
    assert t.mass_kg == pytest.approx(tr.mass_kg, rel=1e-7) and t.object_mass_kg == 1.0
    assert t.time_us == tr.time_us and t.ang_accel_frd_rad_s2 is None  # not on the wire


def test_fc_sensors_and_truth_record(plant: Plant) -> None:
    sb, tr = plant.sense(), plant.truth()
    msgs = _messages(9, sb, tr)
    # the parts in any order before the trigger (HIL_SENSOR) work as well as the datagram's order
    b = seam.decode_bundle([*reversed(msgs[:-1]), msgs[-1]])
    assert b is not None
    s = b.fc_sensors()
    assert s.t_s == sb.time_us * 1e-6
    np.testing.assert_array_equal(s.pos_ned_m, _f32(sb.pos_ned_m))
    np.testing.assert_array_equal(s.duct_tilt_rad, _f32(sb.duct_tilt_rad))
    assert s.gripper_closed == sb.gripper_closed  # NAVIG8_ARM_STATE's gripper reaches the FC (telemetry)
    rec = log_truth_record(b.truth)
    for key in ("pos_ned_m", "quat_wxyz", "euler_rad", "reaction_force_frd_n", "reaction_moment_mount_frd_nm",
                "joint_rate_rad_s", "joint_accel_rad_s2", "duct_tilt_rad", "prop_speed_rad_s", "inertia_diag_kgm2"):
        assert key in rec
    np.testing.assert_allclose(rec["euler_rad"], tr.euler_rad, atol=1e-6)
    assert seam.decode_bundle([m for m in msgs if m.name != "NAVIG8_ARM_STATE"]) is None  # incomplete


def test_assembler_never_mixes_steps(plant: Plant) -> None:
    sb, tr = plant.sense(), plant.truth()
    msgs = _messages(1, sb, tr)
    asm = seam.BundleAssembler()
    for m in msgs[:-1]:
        assert asm.add(m) is None
    hil_other = _messages(1, sb._replace(time_us=sb.time_us + 10_000), None)[-1]
    assert asm.add(hil_other) is None and asm.incomplete == 1
    for m in msgs:
        out = asm.add(m)
    assert out is not None and out.time_usec == sb.time_us + 1
    assert list(asm.completed) == ["ODOMETRY", "NAVIG8_ACTUATOR_STATE", "NAVIG8_ARM_STATE", "NAVIG8_TRUTH",
                                   "HIL_SENSOR"]
    assert all(asm.completed[m.name] is m for m in msgs)
    assert seam.decode_bundle(msgs[1:]) is None  # ODOMETRY missing
    no_truth = seam.decode_bundle([m for m in msgs if m.name != "NAVIG8_TRUTH"])
    assert no_truth is not None and no_truth.truth is None


def test_parse_counts_bad_input_and_never_raises(plant: Plant, d) -> None:
    c = codec.seam_codec()
    good = codec.Encoder(c, 1, 25).frame(*seam.encode_sim_status(seam.SimStatus(1, 0, 0, 1.0, 0.0, 0)))

    def parse(data: bytes) -> tuple[list, codec.ParseCounters]:
        counts = codec.ParseCounters()
        return c.parse(data, counts), counts

    assert parse(good)[1] == codec.ParseCounters()
    msgs, counts = parse(b"\x00\x01garbage" + good)
    assert len(msgs) == 1 and counts == codec.ParseCounters(garbage_bytes=9)
    corrupt = bytearray(good)
    corrupt[12] ^= 0xFF  # payload byte: bad CRC
    assert parse(bytes(corrupt)) == ([], codec.ParseCounters(bad_crc=1))
    # a truncated frame at the end of one datagram must not swallow the next datagram
    assert parse(good[:-5]) == ([], codec.ParseCounters(truncated=1))
    assert len(parse(good)[0]) == 1
    unknown = bytearray(good)
    unknown[7:10] = (60999).to_bytes(3, "little")
    assert parse(bytes(unknown)) == ([], codec.ParseCounters(unknown_id=1))
    rng = np.random.default_rng(0)
    for _ in range(300):
        parse(rng.integers(0, 256, int(rng.integers(0, 600)), dtype=np.uint8).tobytes())
    assert len(parse(good)[0]) == 1


# ---- seam: arm command and status ---------------------------------------------------------------------
def test_arm_command_roundtrip_and_gcs_degrees() -> None:
    cmd = seam.ArmCommand(77, (0.1, -0.2, 0.3), seam.GRIPPER_GRAB)
    out = seam.decode_arm_cmd(_roundtrip(seam.encode_arm_cmd(cmd), compid=1))
    assert out.time_usec == 77 and out.gripper == seam.GRIPPER_GRAB
    np.testing.assert_allclose(out.joint_target_rad, cmd.joint_target_rad, rtol=1e-7)
    grip_only = seam.decode_arm_cmd(_roundtrip(seam.encode_arm_cmd(seam.ArmCommand(5, None, seam.GRIPPER_RELEASE))))
    assert grip_only.joint_target_rad is None and grip_only.gripper == seam.GRIPPER_RELEASE
    with pytest.raises(ValueError):
        seam.ArmCommand(1, None, 3)
    g = seam.arm_command_from_mav_cmd(9, [20.0, -20.0, 90.0, 1.0, 0.0, 0.0, 0.0])
    assert g is not None and g.gripper == seam.GRIPPER_NONE
    np.testing.assert_allclose(g.joint_target_rad, np.radians([20.0, -20.0, 90.0]))
    assert seam.arm_command_from_mav_cmd(9, [20.0, 0.0, 0.0, 0.0]) is None
    with pytest.raises(ValueError):
        seam.arm_command_from_mav_cmd(9, [float("nan"), 0.0, 0.0, 1.0])
    with pytest.raises(ValueError):
        seam.arm_command_from_mav_cmd(9, [0.0, 0.0, 0.0, 2.0])


def test_sim_status_roundtrip() -> None:
    st = seam.SimStatus(1_000_001, 100, seam.SIM_STATE_DONE, 0.0, 37.5, 2)
    assert seam.decode_sim_status(_roundtrip(seam.encode_sim_status(st))) == st


def test_time_stamps_are_never_zero() -> None:
    assert seam.time_usec_from_sim_us(0) == 1
    assert seam.sim_us_from_time_usec(seam.time_usec_from_sim_us(123_450_000)) == 123_450_000


def test_cache_dir_is_never_a_directory_someone_else_owns_or_shares(tmp_path: Path,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """The cache holds code the process runs: a planted <tmp>/navig8-<uid> (another owner) or a symlink is refused; a
    directory of ours that others may write is tightened to 0700 before use."""
    if not hasattr(os, "getuid"):
        pytest.skip("ownership is a POSIX notion")
    planted = tmp_path / "planted"
    planted.mkdir(mode=0o777)
    os.chmod(planted, 0o777)
    (planted / "evil.code").write_bytes(b"planted")
    monkeypatch.setenv("NAVIG8_CACHE_DIR", str(planted))
    monkeypatch.setattr(dialect.os, "getuid", lambda: os.stat(planted).st_uid + 1)  # as if another user owned it
    assert dialect.cache_dir() != planted
    monkeypatch.undo()
    link = tmp_path / "link"
    link.symlink_to(planted)
    monkeypatch.setenv("NAVIG8_CACHE_DIR", str(link))
    assert dialect.cache_dir() != link
    monkeypatch.setenv("NAVIG8_CACHE_DIR", str(planted))  # ours after all, but world-writable: tightened, then used
    assert dialect.cache_dir() == planted and os.stat(planted).st_mode & 0o777 == 0o700


@pytest.mark.parametrize(("cmd_time_usec", "want_t_s"), [(40_001, 0.04), (30_001, 0.03), (0, None), (50_001, None),
                                                          (90_001, None)])
def test_the_flown_commands_stamp_reaches_the_fc_only_when_older_than_the_sample(
        plant: Plant, cmd_time_usec: int, want_t_s: float | None) -> None:
    """NAVIG8_ACTUATOR_STATE.cmd_time_usec through the wire to the FC's sensors: an earlier sample's stamp is that
    sample's time (the command the actuators flew); none (0), the sample's own stamp or a later one (a bridge's bug,
    a forged frame) is unknown: the FC then flies its last command, as in lockstep."""
    sb, tr = plant.sense(), plant.truth()
    data = seam.encode_bundle(codec.Encoder(codec.seam_codec(), 1, 25), 5, sb, tr, cmd_time_usec)
    b = seam.decode_bundle(codec.seam_codec().parse(data, codec.ParseCounters()))
    assert b is not None and b.time_usec == 50_001 and b.cmd_time_usec == cmd_time_usec
    assert b.fc_sensors().cmd_applied_t_s == want_t_s
