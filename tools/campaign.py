"""navig8-campaign: Monte-Carlo and test campaigns, the world varied, on a process pool or a Dask cluster.

    navig8-campaign CAMPAIGN.yaml [--out DIR] [--workers N] [--cluster local|ADDRESS] [--retry-failed]
                    [--limit N] [--no-progress] [--no-report]

A campaign file (docs/campaigns.md; params/campaigns/) names a base scenario, the controller variants and the
factors to vary (grids crossed, distributions drawn); every row is one run, fully determined by the row
(variant, factor values, seed) and reproducible alone with the `navig8-sim` / `navig8-sitl` command in its
`replay` column. Runs go to a local process pool (default, one worker per core) or, with --cluster, to Dask
distributed (`--cluster local` starts a LocalCluster for the campaign; `--cluster tcp://host:8786` uses a
running scheduler). Results stream to DIR/runs.jsonl as runs finish; a run that raises or times out is recorded
with its error and the campaign goes on; running again with the same DIR skips the rows already recorded.
At the end: DIR/results.parquet + results.csv (every factor and summary metric per run) and DIR/report.md
with PNG figures (tools/campaign_report.py).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from navig8_tools.campaign_run import AUTHORITY_COLUMNS, METRICS, MISSION_METRICS, dask_results, pool_results
from navig8_tools.campaign_spec import Campaign, Row, default_out_dir, expand, replay_command, write_scenario_files

TABLE_FILE = "results.parquet"
STREAM_FILE = "runs.jsonl"
# Columns that depend on where and when a run ran, not on its row (left out when comparing two tables).
RUN_ENV_COLUMNS = ("wall_time_s", "real_time_factor", "run_wall_s", "run_cpu_s", "worker")


# ---------------------------------------------------------------------------------------------
# The campaign: stream, resume, table
# ---------------------------------------------------------------------------------------------


def read_stream(out_dir: Path) -> dict[str, dict[str, Any]]:
    """Records of DIR/runs.jsonl by run_id (the last one wins); a torn last line (a killed campaign) is skipped."""
    recs: dict[str, dict[str, Any]] = {}
    p = out_dir / STREAM_FILE
    if not p.exists():
        return recs
    for line in p.read_text().splitlines():
        try:
            rec = json.loads(line)
        except json.JSONDecodeError:
            continue
        recs[rec["run_id"]] = rec
    return recs


def row_record(row: Row, rec: Mapping[str, Any], authority: bool | None = None) -> dict[str, Any]:
    """One table row: the row's identity and factors, then the run's record (with the authority columns when the
    row computed them or `authority` says the table has them)."""
    out: dict[str, Any] = {"index": row.index, "run_id": row.run_id, "variant": row.variant,
                           "controller": row.controller, "seed": row.seed, "sample": row.sample, **row.factors}
    for k in ("status", "error", "run_wall_s", "run_cpu_s", "worker"):
        out[k] = rec.get(k)
    for k in (*METRICS, *(MISSION_METRICS if row.plan else ()),
              *((*AUTHORITY_COLUMNS, "authority_error") if (row.authority if authority is None else authority)
                else ())):
        out[k] = rec.get(k, math.nan if k in AUTHORITY_COLUMNS else None)
    out["success"] = bool(rec.get("status") == "ok" and rec.get("lost_control") is False
                          and (not row.plan or rec.get("mission_complete") is True))
    out["replay"] = replay_command(row)
    return out


def build_table(rows: list[Row], recs: Mapping[str, Mapping[str, Any]]) -> Any:
    """The campaign's table (pandas DataFrame, campaign order) of the rows that have a record."""
    import pandas as pd

    have = [r for r in rows if r.run_id in recs]
    authority = any(r.authority for r in rows)
    # a generated campaign computes the bound on one variant's runs per draw; the others' rows share it
    shared = {r.sample: recs[r.run_id] for r in have if r.authority}
    data = []
    for r in have:
        rec = recs[r.run_id]
        if authority and not r.authority and r.sample in shared:
            rec = dict(rec) | {k: shared[r.sample].get(k) for k in (*AUTHORITY_COLUMNS, "authority_error")}
        data.append(row_record(r, rec, authority))
    return pd.DataFrame(data)


def write_table(df: Any, out_dir: Path) -> tuple[Path, Path]:
    pq, csv = out_dir / TABLE_FILE, out_dir / "results.csv"
    df.to_parquet(pq, index=False)
    df.to_csv(csv, index=False)
    return pq, csv


@dataclass(frozen=True)
class CampaignResult:
    out_dir: Path
    table: Any  # pandas DataFrame
    ran: int  # runs executed now (the others were recorded by an earlier, resumed campaign)
    failed: int  # of those, status != ok
    wall_s: float


def run_campaign(campaign: Campaign, out_dir: str | Path, workers: int | None = None, cluster: str | None = None,
                 retry_failed: bool = False, limit: int | None = None, progress: bool = True) -> CampaignResult:
    """Run the rows not yet in out_dir/runs.jsonl (also the failed ones with retry_failed), stream each record as
    it arrives, then write the table. `limit`: run at most that many of the missing rows."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = expand(campaign, out)
    write_scenario_files(rows)  # every generated row's file, also of rows recorded before: the replays read them
    recs = read_stream(out)
    todo = [r for r in rows if r.run_id not in recs or (retry_failed and recs[r.run_id]["status"] != "ok")]
    if limit is not None:
        todo = todo[:limit]
    workers = workers or os.cpu_count() or 1
    source = pool_results(todo, workers) if cluster is None else dask_results(todo, cluster, workers)
    bar = None
    if progress and todo:
        from tqdm import tqdm

        bar = tqdm(total=len(todo), unit="run", file=sys.stderr, dynamic_ncols=True, smoothing=0.1)
    failed = 0
    t0 = time.perf_counter()
    with open(out / STREAM_FILE, "a") as stream:
        for i, (row, rec) in enumerate(source, start=1):
            stream.write(json.dumps(rec, allow_nan=True) + "\n")
            stream.flush()
            recs[row.run_id] = rec
            failed += rec["status"] != "ok"
            if bar is not None:
                rate = 60.0 * i / max(time.perf_counter() - t0, 1e-9)
                bar.set_postfix_str(f"failed {failed}, {rate:.1f} runs/min", refresh=False)
                bar.update(1)
    if bar is not None:
        bar.close()
    wall = time.perf_counter() - t0
    df = build_table(rows, recs)
    write_table(df, out)
    return CampaignResult(out, df, len(todo), failed, wall)


def comparable(df: Any) -> Any:
    """The table without the columns that depend on where and when runs ran (for comparing backends)."""
    return df.drop(columns=[c for c in RUN_ENV_COLUMNS if c in df.columns]).reset_index(drop=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="navig8-campaign", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("campaign", help="campaign YAML (params/campaigns/)")
    ap.add_argument("--out", default=None, help="output directory (default out/campaigns/<name>)")
    ap.add_argument("--workers", type=int, default=None, help="pool size / LocalCluster workers (default: cores)")
    ap.add_argument("--cluster", default=None, help="'local' (a Dask LocalCluster) or a scheduler address")
    ap.add_argument("--retry-failed", action="store_true", help="also rerun recorded rows that failed")
    ap.add_argument("--limit", type=int, default=None, help="run at most N of the missing rows")
    ap.add_argument("--no-progress", action="store_true")
    ap.add_argument("--no-report", action="store_true")
    a = ap.parse_args(argv)
    c = Campaign.load(a.campaign)
    out = Path(a.out) if a.out else default_out_dir(c)
    res = run_campaign(c, out, a.workers, a.cluster, a.retry_failed, a.limit, progress=not a.no_progress)
    backend = "dask " + a.cluster if a.cluster else f"local pool of {a.workers or os.cpu_count()}"
    print(f"{res.ran} runs now ({res.failed} failed) in {res.wall_s:.1f} s on {backend}; "
          f"table: {len(res.table)} rows -> {out / TABLE_FILE}, {out / 'results.csv'}", file=sys.stderr)
    if not a.no_report:
        from navig8_tools.campaign_report import write_report

        cmd = "navig8-campaign " + " ".join(argv if argv is not None else sys.argv[1:])
        print(f"report: {write_report(c, res.table, out, cmd)}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["CampaignResult", "run_campaign", "build_table", "row_record", "read_stream", "write_table", "comparable",
           "main"]
