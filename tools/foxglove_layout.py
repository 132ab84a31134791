"""navig8-foxglove-layout: writes the Foxglove layout (tools/layouts/navig8.json): a 3D panel with the vehicle
(scene entities, both transform trees, the path, the mission, a URDF layer), plots of the stability telemetry
(eigenvalues of G_hat G^-1 against lambda_min and lambda_crit, K bounds) and of the paper's figure signals
(Fig. 10 reaction wrench, Fig. 11 joints, Fig. 12 position, Fig. 14 actuators, Fig. 15 G_I estimates), and the
log panel (foxglove.Log). `navig8-foxglove-layout --check` exits 1 when the committed file is stale.
Foxglove: Layouts -> Import from file. docs/foxglove.md.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

LAYOUT_PATH = Path(__file__).resolve().parent / "layouts" / "navig8.json"
URDF_URL = "package://navig8_params/navig8_uam.urdf"  # replace with the file's path or URL in the URDF layer


def _plot(title: str, paths: list[tuple[str, str]]) -> dict[str, Any]:
    return {"title": title, "paths": [{"value": v, "enabled": True, "timestampMethod": "logTime", "label": label}
                                      for v, label in paths],
            "showXAxisLabels": True, "showYAxisLabels": True, "showLegend": True, "legendDisplay": "floating",
            "isSynced": True, "xAxisVal": "timestamp", "sidebarDimension": 240}


def layout() -> dict[str, Any]:
    topics = {t: {"visible": True} for t in ("/foxglove/scene", "/foxglove/path", "/foxglove/mission")}
    topics["/foxglove/pose"] = {"visible": False}
    three_d = {
        "followMode": "follow-position", "followTfFrame": "base_link",
        "scene": {"transforms": {"showLabel": False, "axisScale": 0.3}},
        "transforms": {"frame:est/base_link": {"visible": True}},
        "topics": topics,
        "layers": {
            "grid": {"layerId": "foxglove.Grid", "frameId": "world", "size": 20, "divisions": 20, "visible": True},
            "urdf": {"layerId": "foxglove.Urdf", "sourceType": "url", "url": URDF_URL, "framePrefix": "",
                     "displayMode": "auto", "visible": False, "label": "Navig8-UAM URDF (set its path)"},
        },
        "cameraState": {"distance": 4.0, "perspective": True, "phi": 60.0, "thetaOffset": 45.0,
                        "targetOffset": [0, 0, 0], "target": [0, 0, 0], "targetOrientation": [0, 0, 0, 1],
                        "fovy": 45, "near": 0.01, "far": 1000},
    }
    eig = _plot("Stability: eig(G_hat G^-1) real parts vs lambda_min, lambda_crit (Fig. 16)",
                [(f"/analysis/eig.eig_real[{i}]", f"Re lambda{i + 1}") for i in range(5)]
                + [("/analysis/eig.lambda_min", "lambda_min"), ("/analysis/eig.lambda_crit", "lambda_crit")])
    gi = _plot("G_I estimates x_hat within their bounds (Fig. 15)",
               [(f"/fc/status.adapt.x_hat[{i}]", f"x_hat{i + 1}") for i in range(4)]
               + [(f"/fc/status.adapt.{b}[{i}]", f"{b}{i + 1}") for b in ("lower", "upper") for i in range(4)])
    reaction = _plot("Arm reaction on the UAV about the mount (Fig. 10)",
                     [(f"/truth.reaction_force_frd_n[{i}]", f"F{a}") for i, a in enumerate("xyz")]
                     + [(f"/truth.reaction_moment_mount_frd_nm[{i}]", f"M{a}") for i, a in enumerate("xyz")])
    joints = _plot("Joints q, q' and the FC's estimate (Fig. 11)",
                   [(f"/truth.joint_pos_rad[{i}]", f"q{i + 1}") for i in range(3)]
                   + [(f"/truth.joint_rate_rad_s[{i}]", f"q{i + 1}'") for i in range(3)]
                   + [(f"/fc/status.q_est_rad[{i}]", f"q{i + 1} est") for i in range(3)])
    position = _plot("Position (NED) and setpoint (Fig. 12)",
                     [(f"/truth.pos_ned_m[{i}]", a) for i, a in enumerate("NED")]
                     + [(f"/fc/setpoint.pos_ned_m[{i}]", f"{a} sp") for i, a in enumerate("NED")])
    actuators = _plot("Actuators: duct tilts and propeller speeds (Fig. 14)",
                      [("/truth.duct_tilt_rad[0]", "alpha1"), ("/truth.duct_tilt_rad[1]", "alpha3")]
                      + [(f"/truth.prop_speed_rad_s[{i}]", f"w{i + 1}") for i in range(3)])
    config = {
        "3D!navig8": three_d,
        "Plot!eig": eig, "Plot!gi": gi, "Plot!reaction": reaction, "Plot!joints": joints,
        "Plot!position": position, "Plot!actuators": actuators,
        "RosOut!log": {"searchTerms": [], "minLogLevel": 1, "topicToRender": "/foxglove/log"},
    }
    plots = {"direction": "column",
             "first": {"direction": "row", "first": "Plot!eig", "second": "Plot!gi"},
             "second": {"direction": "column",
                        "first": {"direction": "row", "first": "Plot!reaction", "second": "Plot!joints"},
                        "second": {"direction": "row", "first": "Plot!position", "second": "Plot!actuators"}}}
    return {
        "configById": config, "globalVariables": {}, "userNodes": {}, "playbackConfig": {"speed": 1},
        "layout": {"direction": "row", "splitPercentage": 45,
                   "first": {"direction": "column", "first": "3D!navig8", "second": "RosOut!log",
                             "splitPercentage": 75},
                   "second": plots},
    }


def render() -> str:
    return json.dumps(layout(), indent=2) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", action="store_true", help=f"write {LAYOUT_PATH}")
    ap.add_argument("--check", action="store_true", help="exit 1 when the committed layout is stale")
    args = ap.parse_args(argv)
    text = render()
    if args.write:
        LAYOUT_PATH.write_text(text)
    elif args.check:
        if not LAYOUT_PATH.exists() or LAYOUT_PATH.read_text() != text:
            print(f"{LAYOUT_PATH} is stale: run `navig8-foxglove-layout --write`", file=sys.stderr)
            return 1
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
