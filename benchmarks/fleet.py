"""Fleet replay: a sequential loop against the local Dask cluster over the same generated logs.

    .venv/bin/python benchmarks/fleet.py [--logs 1000] [--seconds 18] [--workers N] [--corpus DIR]

Generates (or reuses, with --corpus) `--logs` drives of about `--seconds` each (free rolling,
one ABS stop; .log/.asc/.blf in turn), then in this one run replays them all
1. sequentially: `run_fleet` without an executor, in this process (the same task, the same
   Parquet writing), and
2. on an embedded local cluster (`open_executor`, one single-threaded worker process per core),
3. on a plain `concurrent.futures.ProcessPoolExecutor` of as many processes: what this machine
   gives two processes at the moment, without Dask (the VM's cores are shared with other jobs),
then measures the scheduler's own cost per task with empty tasks, and extrapolates to 100,000
logs on 32 workers from the per-log cost and that overhead (the formula is printed).
"""
from __future__ import annotations

import argparse
import concurrent.futures
import os
import sys
import tempfile
import time
from pathlib import Path

from frictiond.fleet.cluster import open_client, worker_count
from frictiond.fleet.corpus import write_corpus
from frictiond.fleet.run import RunReport, config_hash, make_task, run_fleet


def _noop(k: int) -> int:
    return k


def corpus(folder: Path, logs: int, seconds: float, workers: int) -> list[Path]:
    started = time.perf_counter()
    existing = len(list(folder.glob("drive-*"))) if folder.exists() else 0
    with open_client(workers=workers) as client:
        paths = write_corpus(folder, logs, seconds, seed=7, executor=client.get_executor())
    total = sum(p.stat().st_size for p in paths)
    print(f"corpus: {logs} logs in {folder} ({total / 1e6:.0f} MB), ready in {time.perf_counter() - started:.0f} s"
          + (f" ({min(existing, logs)} reused)" if existing else ""))
    return paths


def scheduler_cost(client, tasks: int = 2000) -> float:
    """Seconds per task of empty tasks kept in flight through the executor: the scheduler's and
    the driver's cost per task, which no number of workers removes."""
    executor = client.get_executor()
    list(executor.map(_noop, range(50)))            # warm: connections, function pickled once
    started = time.perf_counter()
    list(executor.map(_noop, range(tasks)))
    return (time.perf_counter() - started) / tasks


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--logs", type=int, default=1000)
    parser.add_argument("--seconds", type=float, default=18.0, help="length of each generated log")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--corpus", type=Path, help="keep the generated logs here and reuse them next time")
    parser.add_argument("--chunk", type=int, default=1, help="logs per Dask task")
    args = parser.parse_args(argv)

    with tempfile.TemporaryDirectory(prefix="frictiond-fleet-") as tmp:
        folder = args.corpus or Path(tmp) / "corpus"
        logs = corpus(folder, args.logs, args.seconds, args.workers)
        h = config_hash(None)
        tasks = [make_task(p, None, h) for p in logs]

        seq = run_fleet(tasks, Path(tmp) / "sequential")
        n = seq.replayed
        print(f"sequential: {n} logs in {seq.wall_s:.1f} s ({seq.failed} failed, {seq.stops} stops); "
              f"per log {1e3 * seq.wall_s / n:.1f} ms, of which the replay {1e3 * seq.task_s / n:.1f} ms")

        started = time.perf_counter()
        with open_client(workers=args.workers) as client:
            workers = worker_count(client)
            startup_s = time.perf_counter() - started
            par = run_fleet(tasks, Path(tmp) / "dask", client.get_executor(), chunk=args.chunk)
            per_task_s = scheduler_cost(client)
        total_s = time.perf_counter() - started
        with concurrent.futures.ProcessPoolExecutor(workers) as pool:
            list(pool.map(_noop, range(workers)))     # processes started before the clock
            plain = run_fleet(tasks, Path(tmp) / "pool", pool, chunk=args.chunk)
        report(args, seq, par, workers, startup_s, total_s, per_task_s)
        print(f"plain ProcessPoolExecutor({workers}), no Dask: {plain.replayed} logs in {plain.wall_s:.1f} s, "
              f"ratio sequential / pool {seq.wall_s / plain.wall_s:.2f}x; inside its processes a log took "
              f"{1e3 * plain.task_s / plain.replayed:.1f} ms ({1e3 * plain.task_cpu_s / plain.replayed:.1f} ms CPU)")
        print(f"Dask / plain pool wall time: {par.wall_s / plain.wall_s:.3f}")
    return 0


def report(args: argparse.Namespace, seq: RunReport, par: RunReport, workers: int, startup_s: float,
           total_s: float, per_task_s: float) -> None:
    n = par.replayed
    hours = par.drive_s / 3600
    print(f"dask local cluster: {workers} workers up in {startup_s:.1f} s; {n} logs ({hours:.2f} h of driving) "
          f"in {par.wall_s:.1f} s "
          f"({par.failed} failed, {par.stops} stops); with start-up and shut-down {total_s:.1f} s")
    ratio = seq.wall_s / par.wall_s
    print(f"ratio sequential / cluster: {ratio:.2f}x on {workers} workers (target >= 1.8x on 2 cores); "
          f"with the cluster's start-up: {seq.wall_s / (par.wall_s + startup_s):.2f}x")
    busy = par.task_s / (par.wall_s * workers)
    cost_seq = seq.task_s / n
    cost_worker = par.task_s / n
    overhead = (par.wall_s * workers - par.task_s) / n
    print(f"per-log cost: {1e3 * cost_seq:.1f} ms replaying here ({1e3 * seq.task_cpu_s / n:.1f} ms CPU), "
          f"{1e3 * cost_worker:.1f} ms inside a worker ({1e3 * par.task_cpu_s / n:.1f} ms CPU: the rest is waiting "
          f"for a core this VM shares with other jobs)")
    print(f"dask per-log overhead: (wall x workers - sum of task times) / logs = {1e3 * overhead:.2f} ms "
          f"= {100 * overhead / cost_worker:.1f} % of a log's replay (target <= 5 %); workers busy {100 * busy:.0f} %")
    print(f"scheduler cost per task (empty tasks in flight): {1e3 * per_task_s:.2f} ms "
          f"= {100 * per_task_s / cost_worker:.1f} % of a log's replay"
          + (f"; with --chunk {args.chunk} per log {1e3 * per_task_s / args.chunk:.2f} ms" if args.chunk > 1 else ""))
    big_n, big_w = 100_000, 32
    # Wall ≈ start-up + N × max(c × (1 + f) / W, s / k): the workers' share of the work, each log
    # costing c plus Dask's measured overhead fraction f, unless the one scheduler, at s per task
    # for tasks of k logs, is the slower of the two.
    f = max(0.0, overhead / cost_worker)
    per_log_s = max(cost_seq * (1 + f) / big_w, per_task_s / args.chunk)
    estimate = startup_s + big_n * per_log_s
    print(f"estimate for {big_n:,} logs on {big_w} workers: T = t_start + N x max(c x (1 + f) / W, s / k) "
          f"= {startup_s:.1f} + {big_n} x max({1e3 * cost_seq:.1f} ms x {1 + f:.3f} / {big_w}, "
          f"{1e3 * per_task_s:.2f} ms / {args.chunk}) = {estimate:.0f} s ({estimate / 60:.1f} min)")
    print("  (c: per-log cost measured sequentially here, f: Dask's per-log overhead fraction, s: the scheduler's "
          "cost per task, k: logs per task; assumes workers as fast as this VM's cores and the logs on storage "
          "that keeps up: ~" f"{big_w / max(cost_seq, 1e-9):.0f} logs/s)")


if __name__ == "__main__":
    sys.exit(main())
