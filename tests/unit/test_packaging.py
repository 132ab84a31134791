"""The Docker image runs the same steps as `make` (no Docker engine here, so the steps are checked)."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_dockerfile_uses_make_install_and_valid_sitl_options() -> None:
    text = (ROOT / "Dockerfile").read_text()
    runs = re.findall(r"^RUN (.*?)(?<!\\)$", text, flags=re.M | re.S)
    assert any("make install" in r for r in runs), "the image must install exactly as `make install` does"
    cmd = re.search(r'^CMD \["sh", "-c", "(.*)"\]$', text, flags=re.M).group(1).replace('\\"', '"')
    argv = shlex.split(cmd.replace('"$NAVIG8_GCS_HOST"', "gcs.example"))
    assert argv[0].endswith("navig8-sitl")
    from navig8_fc.shell.sitl import build_arg_parser

    args = build_arg_parser().parse_args(argv[1:])
    assert args.speed == 1.0 and args.bind_host == "0.0.0.0" and args.gcs_host == "gcs.example"
    # The documented `docker run` publishes the FC's own ports, never the host GCS ports it sends to
    # (docker-proxy would hold host 14550/14540 and QGroundControl / MAVSDK could not bind them).
    readme = (ROOT / "README.md").read_text()
    for doc in (text, readme):
        run = re.search(r"docker run (.*?)navig8-sitl", doc, flags=re.S).group(1)
        published = set(re.findall(r"-p (\d+):\d+/udp", run))
        assert published == {"18570", "14580"}, published
    assert re.search(r"^EXPOSE 18570/udp 14580/udp$", text, flags=re.M)
    from navig8_fc.shell.fc_options import FcOptions, options_from_args
    from navig8_fc.shell.fc_options import build_arg_parser as fc_arg_parser

    opts: FcOptions = options_from_args(fc_arg_parser().parse_args([]))
    assert {str(opts.port("gcs_bind")), str(opts.port("api_bind"))} == {"18570", "14580"}


def test_makefile_targets_and_ci_entry() -> None:
    mk = (ROOT / "Makefile").read_text()
    for target in ("demo:", "test:", "bench:", "install:"):
        assert target in mk
    ci = ROOT / ".ci" / "run"
    assert ci.stat().st_mode & 0o111 and "make test" in ci.read_text()
