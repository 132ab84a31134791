"""navig8-sweep: the three controllers over several seeds on a scenario, as a markdown table + JSON.

    navig8-sweep --scenario paper --seeds 10 [--duration S] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
from pathlib import Path
from typing import Any

from navig8_tools.sim import CONTROLLERS, run

KEYS = ("lost_control", "min_eigenvalue", "max_eigenvalue", "bound_violations", "max_pos_error_m",
        "pos_rms_error_m", "max_att_error_deg", "real_time_factor")


def _settled(s: dict[str, Any]) -> int:
    return sum(1 for x in s["settle"] if x["settle_s"] is not None)


def sweep(scenario: str, seeds: list[int], duration: float | None, workdir: Path) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = {}
    for ctrl in ("proposed", "unconstrained", "fixed"):
        out[ctrl] = []
        for seed in seeds:
            s = run(scenario, ctrl, seed, duration, workdir / f"{ctrl}_{seed}.mcap").summary
            out[ctrl].append(s)
    return out


def table(results: dict[str, list[dict]]) -> str:
    lines = ["| controller | runs | lost control | steps settled | min λ (worst) | max λ (worst) | bound violations "
             "(total) | max pos err m (median) | pos RMS m (median) | max att err ° (median) |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for ctrl, runs in results.items():
        n = len(runs)
        lost = sum(1 for s in runs if s["lost_control"])
        settled = sum(_settled(s) for s in runs)
        total_steps = sum(len(s["settle"]) for s in runs)
        mins = [s["min_eigenvalue"] for s in runs if s["min_eigenvalue"] is not None]
        maxs = [s["max_eigenvalue"] for s in runs if s["max_eigenvalue"] is not None]
        lines.append(
            f"| {ctrl} | {n} | {lost} | {settled}/{total_steps} | {min(mins) if mins else float('nan'):.3f} "
            f"| {max(maxs) if maxs else float('nan'):.3f} | {sum(s['bound_violations'] for s in runs)} "
            f"| {statistics.median(s['max_pos_error_m'] for s in runs):.3f} "
            f"| {statistics.median(s['pos_rms_error_m'] for s in runs):.3f} "
            f"| {statistics.median(s['max_att_error_deg'] for s in runs):.1f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenario", default="paper")
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--duration", type=float, default=None)
    ap.add_argument("--out", default=None, help="write sweep.json here")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        res = sweep(args.scenario, list(range(1, args.seeds + 1)), args.duration, Path(tmp))
    print(table(res))
    if args.out:
        Path(args.out).mkdir(parents=True, exist_ok=True)
        (Path(args.out) / "sweep.json").write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["sweep", "table", "main", "CONTROLLERS", "KEYS"]
