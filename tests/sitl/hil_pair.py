"""Run `make test-hil` against a bridge + FC pair started here as plain processes (not by pytest): the FC's GCS
link served on TCP, its API link on UDP, the sim link over TCP (sitl_helpers.external_pair). Shows that the
MAVLink-only SITL tests pass against an FC elsewhere, through connection strings only (docs/hil.md).

    .venv/bin/python tests/sitl/hil_pair.py [--speed 1] [extra pytest args, e.g. -x]

Exit status: make's (pytest's)."""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

from sitl_helpers import external_pair

ROOT = Path(__file__).resolve().parents[2]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--speed", type=float, default=1.0, help="the bridge's lockstep speed (default 1: real time)")
    args, extra = ap.parse_known_args()
    with tempfile.TemporaryDirectory(prefix="navig8-hil-") as tmp, external_pair(Path(tmp), args.speed) as ext:
        print(f"pair: GCS {ext['fc_gcs']}, API {ext['fc_api']}, sim {ext['bridge']}", flush=True)
        cmd = ["make", "-s", "test-hil", f"FC_GCS={ext['fc_gcs']}", f"FC_API={ext['fc_api']}",
               f"BRIDGE={ext['bridge']}", f"PYTEST_ARGS={' '.join(extra)}"]
        return subprocess.call(cmd, cwd=ROOT)


if __name__ == "__main__":
    sys.exit(main())
