"""The Foxglove channels of a navig8-sim log (docs/foxglove.md): every foxglove.* channel validates against
Foxglove's published JSON schema, and the transform chain puts the gripper where the arm's forward kinematics
does (1e-6 m). The same checks on a SITL (navig8-fc) log: tests/sitl/test_sitl_foxglove.py."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from foxglove_oracle import check_log, validate

from navig8_fc.core.vehicle import VehicleConfig
from navig8_fc.shell.foxglove_out import TOPICS
from navig8_fc.viz import VehicleViz, log_record, packaged_uav_size_m
from navig8_tools.sim import run


@pytest.fixture(scope="module")
def sim_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("fox") / "paper.mcap"
    run("paper", duration_s=2.0, log_path=path)  # the arm moves from q = 0 towards Pose 1 from the start
    return path


def test_sim_log_foxglove_channels_validate_and_transforms_match_kinematics(sim_log: Path) -> None:
    cfg = VehicleConfig.load()
    counts = check_log(sim_log, cfg, {"/foxglove/tf": 18, "/foxglove/scene": 9, "/foxglove/pose": 18,
                                      "/foxglove/path": 4, "/foxglove/mission": 4})
    assert set(counts) >= set(TOPICS) - {"/foxglove/log"}
    # display rates on sim time: 10 Hz transforms, 5 Hz scene over 2 s (both ends included)
    assert counts["/foxglove/tf"] == 21 and counts["/foxglove/scene"] == 11


def test_log_record_levels_and_object_sphere_volume() -> None:
    # MAV_SEVERITY 0..7 -> Foxglove LogLevel: EMERGENCY..CRITICAL fatal, ERROR, WARNING, NOTICE/INFO info, DEBUG
    levels = [log_record(0, s, "x", "fc")["level"] for s in range(8)]
    assert levels == [5, 5, 5, 4, 3, 2, 2, 1]
    validate("foxglove.Log", log_record(1_500_000_000, 4, "Low battery", "navig8-fc"))
    v = VehicleViz(VehicleConfig.load(), packaged_uav_size_m())
    for m in (0.5, 1.0, 2.0):  # sphere volume = m / density
        d = v.object_diameter_m(m)
        assert np.isclose(np.pi * d**3 / 6 * v.d.object_density_kg_m3, m, rtol=1e-12)
    assert v.object_diameter_m(0.0) == 0.0
    scene = v.scene_update(0, (1000.0, -200.0, 1000.0), 0.0, None)
    validate("foxglove.SceneUpdate", scene)
    obj = next(e for e in scene["entities"] if e["id"] == "object")
    assert obj["spheres"] == []  # nothing held: nothing drawn
    tail = next(e for e in scene["entities"] if e["id"] == "tail")
    # reversed tail speed: thrust along +z of the tail frame, the arrow (its +x) turned onto +z
    (arrow,) = tail["arrows"]
    q = arrow["pose"]["orientation"]
    x_axis_z = 2 * (q["x"] * q["z"] - q["w"] * q["y"])
    assert np.isclose(x_axis_z, 1.0)
    assert np.isclose(arrow["shaft_length"] + arrow["head_length"],
                      v.cfg.k_thrust_tail * 200.0**2 * v.d.thrust_arrow_m_per_n)


def test_enu_pose_is_the_product_with_q_enu_from_ned() -> None:
    # the written-out product equals quat_mul (the project's quaternion product) of the normalised input
    from navig8_fc.core.rotation import quat_mul
    from navig8_fc.viz import Q_ENU_FROM_NED, enu_pose

    rng = np.random.default_rng(3)
    for _ in range(100):
        q = rng.normal(size=4)
        p, q_enu = enu_pose((1.0, 2.0, -3.0), tuple(q * 1.001))
        assert p == (2.0, 1.0, 3.0)
        assert np.allclose(q_enu, quat_mul(Q_ENU_FROM_NED, tuple(q / np.linalg.norm(q))), atol=1e-12)


def _resolve(rec: object, path: str) -> object:
    """A Foxglove message path's value in a record: fields by name, [i] by index."""
    import re

    for name, index in re.findall(r"\.?([A-Za-z_0-9]+)|\[(\d+)\]", path):
        rec = rec[int(index)] if index else rec[name]  # type: ignore[index]
    return rec


def test_layout_is_current_and_every_plot_path_resolves_in_a_log(sim_log: Path) -> None:
    from foxglove_oracle import read_log

    from navig8_tools.foxglove_layout import LAYOUT_PATH, layout, main

    assert main(["--check"]) == 0, f"{LAYOUT_PATH} is stale"
    cfg = layout()["configById"]
    _, msgs = read_log(sim_log)
    last = {topic: rec for topic, _t, rec in msgs}
    n = 0
    for panel_id, panel in cfg.items():
        if panel_id.startswith("Plot!"):
            for p in panel["paths"]:
                topic, _, field = p["value"].partition(".")
                value = _resolve(last[topic], field)
                assert isinstance(value, (int, float)) and not isinstance(value, bool), (p["value"], value)
                n += 1
    assert n >= 40
    three_d = cfg["3D!navig8"]
    assert set(three_d["topics"]) <= set(last)  # the 3D panel's topics are in the log
    assert cfg["RosOut!log"]["topicToRender"] == "/foxglove/log"
