"""Generate docs/params.md from params/fc_params.yaml (`make docs`; a test fails when it is stale)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from navig8_fc.params.registry import ParamRegistry


def _fmt(v: float, ptype: str) -> str:
    return str(int(v)) if ptype == "INT32" else f"{v:g}"


def render() -> str:
    reg = ParamRegistry.from_defaults(check_stability=False)
    lines = [
        "# Flight-controller parameters",
        "",
        "Generated from `params/fc_params.yaml` by `make docs` (`navig8-params-doc --write docs/params.md`).",
        "Do not edit by hand: a test compares this page with the definitions.",
        "",
        "The index is the MAVLink `param_index`. REAL32 values are stored as float32, as MAVLink carries them.",
        "Cross-parameter rules: `INDI_K_MIN <= INDI_K_MAX`; the stability floor refuses any K bound, actuator,",
        "sampling or filter value that lets an eigenvalue of Ĝ·G⁻¹ fall to the critical eigenvalue of H(s)",
        "(Eq. 9-13) anywhere in the arm workspace, or lets the largest eigenvalue reach the upper end of H(s)'s",
        "stable range (finite only for lightly damped actuators with long delays); `INDI_LAMBDA_MIN` must exceed",
        "the critical eigenvalue.",
        "Gains have a positive minimum (a zero gain is never flyable). \"Armed\" says whether a value may be set",
        "while armed: \"no\" marks parameters that change the control loop itself (rate, filters, actuator model,",
        "estimator structure, origin); PARAM_SET refuses them in flight with the old value and a STATUSTEXT.",
        "",
        "| index | name | type | default | min | max | units | armed | description |",
        "|---:|---|---|---:|---:|---:|---|---|---|",
    ]
    for d in reg.definitions:
        desc = d.description.replace("|", "\\|")
        lines.append(
            f"| {d.index} | `{d.name}` | {d.type} | {_fmt(d.default, d.type)} | {_fmt(d.min, d.type)} "
            f"| {_fmt(d.max, d.type)} | {d.units} | {'no' if d.not_armed else 'yes'} | {desc} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--write", type=Path, help="write to this file instead of stdout")
    args = ap.parse_args(argv)
    text = render()
    if args.write:
        args.write.write_text(text)
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
