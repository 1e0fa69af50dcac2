"""A fleet of gates calibrated in parallel on Dask: one task per gate's field record, one
results table (gate, gap, 95 % interval, verdict, wall time, error). A gate whose record is
refused or whose calibration fails is a row with its error; the other gates go on.

    pip install ./python "dask[distributed]" pandas
    python python/examples/fleet_dask.py --records 8 --workers 2 --compare

On a real cluster, pass the scheduler's address (`--scheduler tcp://host:8786`): the tasks
are the same. Each task gets the gate itself (a `bamudi.Gate` pickles as its TOML and is
rebuilt on the worker) and the record's path, so the workers need the package and the files.

The fleet here is simulated: gates of the default design whose true bottom gaps differ
(60-130 in), each with a month of hourly lockages; one gate's gauge SG4 is stuck at a
constant reading, which the calibration refuses (a row with the error).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np
import pandas as pd
from dask.distributed import Client, LocalCluster

import bamudi

CONFIG = {
    "gap_prior": [40.0, 200.0],
    "calibration": {"estimator": {"kind": "exact_linear"}, "sampling": {"noise_sd": 1.0}},
}
# Rows per calibration, evenly thinned in time (the close loop's calibrator default is 240).
MAX_ROWS = 120


def simulate_fleet(gate: bamudi.Gate, n: int, directory: str, days: float) -> list[dict]:
    """`n` gates' records as CSV files; the gate at index 2 gets a stuck gauge."""
    jobs = []
    for i in range(n):
        true_gap = 60.0 + 70.0 * i / max(n - 1, 1)
        rec = bamudi.simulate_field(gate, days=days, gap=true_gap, seed=100 + i)
        text = rec.csv
        if i == 2:
            frame = pd.read_csv(pd.io.common.StringIO(text))
            frame["SG4"] = 12.5  # a stuck gauge: the same reading in every row
            text = frame.to_csv(index=False)
        path = os.path.join(directory, f"gate-{i + 1:02d}.csv")
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)
        jobs.append({"gate": f"gate-{i + 1:02d}", "record": path, "true_gap_in": true_gap})
    return jobs


def calibrate_record(gate: bamudi.Gate, job: dict) -> dict:
    """One task: the record's rows (thinned to MAX_ROWS) calibrated; never raises."""
    start = time.perf_counter()
    row = {"gate": job["gate"], "true_gap_in": job["true_gap_in"]}
    try:
        frame = pd.read_csv(job["record"])
        columns = ["h_up", "h_down", *gate.gauge_names]
        frame = frame[columns].dropna()
        frame = frame[(frame["h_up"] - frame["h_down"]).abs() > 1.0]  # gate closed
        if frame.empty:
            raise ValueError(f"{job['record']}: no complete row with the gate closed")
        keep = np.unique(np.linspace(0, len(frame) - 1, MAX_ROWS).round().astype(int))
        cal = bamudi.calibrate(gate, frame.iloc[keep], CONFIG, seed=7, label=job["record"])
        lo, hi = cal.theta_ci95
        row.update(gap_in=cal.theta_mean, ci95_lo_in=lo, ci95_hi_in=hi, verdict=cal.verdict, error="")
    except Exception as e:  # noqa: BLE001 - one gate's failure is a row, never the fleet's end
        row.update(gap_in=np.nan, ci95_lo_in=np.nan, ci95_hi_in=np.nan, verdict="failed", error=str(e))
    row["seconds"] = time.perf_counter() - start
    return row


def run_fleet(client: Client, gate: bamudi.Gate, jobs: list[dict]) -> pd.DataFrame:
    """All tasks at once; the table in the jobs' order."""
    shared = client.scatter(gate, broadcast=True)  # one copy per worker, not per task
    futures = [client.submit(calibrate_record, shared, job, pure=False) for job in jobs]
    return pd.DataFrame(client.gather(futures))


def timed_run(gate, jobs, workers: int, scheduler: str | None):
    """The fleet on `workers` single-threaded local worker processes (or on `scheduler`)."""
    if scheduler:
        with Client(scheduler) as client:
            start = time.perf_counter()
            return run_fleet(client, gate, jobs), time.perf_counter() - start
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        client.run(lambda: os.environ.__setitem__("RAYON_NUM_THREADS", "1"))
        start = time.perf_counter()
        table = run_fleet(client, gate, jobs)
        return table, time.perf_counter() - start


def main(argv=None) -> pd.DataFrame:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--records", type=int, default=8)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--element-size", type=float, default=24.0, help="mesh (in)")
    p.add_argument("--days", type=float, default=30.0)
    p.add_argument("--scheduler", help="address of an existing Dask scheduler")
    p.add_argument("--compare", action="store_true", help="also run on one worker")
    a = p.parse_args(argv)
    gate = bamudi.Gate(element_size=a.element_size)
    with tempfile.TemporaryDirectory() as d:
        jobs = simulate_fleet(gate, a.records, d, a.days)
        table, wall = timed_run(gate, jobs, a.workers, a.scheduler)
        print(table.to_string(index=False, float_format=lambda v: f"{v:.2f}"))
        print(f"{len(jobs)} records on {a.workers} worker(s): {wall:.1f} s wall")
        if a.compare and not a.scheduler:
            _, one = timed_run(gate, jobs, 1, None)
            print(f"on 1 worker: {one:.1f} s wall; speed-up {one / wall:.2f}x")
    return table


if __name__ == "__main__":
    main()
