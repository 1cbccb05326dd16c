"""The per-log task of a fleet replay and the loop that drives it over an executor.

`replay_one` runs in a worker (a Dask worker process, or this process for the sequential path):
the same `Pipeline` + `replay.replay_log` as `frictiond replay`, recorded to find the braking
stops, and returns plain rows. Whatever goes wrong with one log (unreadable, not a log, a reader
or pipeline exception) becomes that log's error row; the run goes on.

`run_fleet` submits tasks to any `concurrent.futures.Executor` (or runs them in a loop without
one), writes finished logs to the result set in batches, and skips the logs already done.
"""
from __future__ import annotations

import concurrent.futures
import functools
import hashlib
import os
import shlex
import socket
import sys
import time
import traceback
import uuid
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable

from .. import __version__
from ..samples import Status
from . import results as rs
from .stops import AlignedRecorder, Stop, find_stops

BATCH_LOGS = 64          # logs per part-file: few files, little lost when a run is killed
BATCH_SECONDS = 30.0     # ... or this long since the last write, whichever comes first
MAX_IN_FLIGHT = 512      # tasks submitted ahead of the results (bounds the driver's memory)


@dataclass(frozen=True)
class LogTask:
    """One log to replay: everything a worker needs, picklable."""

    path: str                     # absolute
    config: str | None            # config file, None for the built-in default
    config_hash: str
    key: str
    size_bytes: int
    mtime_ns: int
    label: str | None = None


@dataclass
class LogResult:
    log_row: dict[str, Any]
    stop_rows: list[dict[str, Any]] = field(default_factory=list)

    @property
    def failed(self) -> bool:
        return self.log_row.get("error_kind") is not None


def config_hash(config_path: str | None) -> str:
    """sha256 (16 hex digits) of a config file and the DBC files it names: what the results depend
    on besides the code. Raises `ConfigError` for an unusable config."""
    from ..config import default_config_path, load_config

    path = Path(config_path) if config_path else default_config_path()
    config = load_config(path)
    digest = hashlib.sha256(path.read_bytes())
    for dbc in (*config.can.dbc, config.can.output_dbc):
        digest.update(Path(dbc).read_bytes())
    return digest.hexdigest()[:16]


def make_task(path: Path, config: str | None, hash_of_config: str, label: str | None = None) -> LogTask:
    """The task for a log file as it is now (its size and mtime enter the key)."""
    absolute = path.resolve()
    stat = absolute.stat()
    key_text = f"{absolute}\0{stat.st_size}\0{stat.st_mtime_ns}\0{hash_of_config}"
    return LogTask(str(absolute), config, hash_of_config, hashlib.sha256(key_text.encode()).hexdigest()[:24],
                   stat.st_size, stat.st_mtime_ns, label)


@functools.lru_cache(maxsize=16)
def _load_config(config_path: str | None, hash_of_config: str) -> Any:
    # Cached per worker process: a fleet has a few configs and thousands of logs. The hash is in
    # the key so that a config edited between two runs is read again.
    from ..config import default_config_path, load_config

    return load_config(Path(config_path) if config_path else default_config_path())


def replay_one(task: LogTask) -> LogResult:
    """Replay one log as `frictiond replay` does; never raises for a bad log (error row instead)."""
    from ..busio import LogFormatError
    from ..pipeline import Pipeline
    from ..replay import replay_log

    started, started_cpu = time.perf_counter(), time.process_time()
    row = _base_row(task)
    row.update(size_bytes=task.size_bytes, mtime_ns=task.mtime_ns,
               worker=f"{socket.gethostname()}:{os.getpid()}")
    try:
        config = _load_config(task.config, task.config_hash)
        row["estimator"] = config.estimator.kind
        pipeline = Pipeline(config)
        recorder = AlignedRecorder()
        summary = replay_log(pipeline, task.path, None, recorder)
        stops = find_stops(recorder)
    except Exception as exc:  # noqa: BLE001 - one bad log must not stop a fleet run
        kind = ("format" if isinstance(exc, LogFormatError) else
                "unreadable" if isinstance(exc, OSError) else "crash")
        row.update(error_kind=kind, error_message=_describe(exc), task_s=time.perf_counter() - started,
                   task_cpu_s=time.process_time() - started_cpu)
        return LogResult(row)
    row.update(_summary_columns(summary))
    row["stops"] = len(stops)
    first_s = summary.first_time_s or 0.0
    stop_rows = [_stop_row(task, k, stop, first_s, row["estimator"]) for k, stop in enumerate(stops)]
    row.update(task_s=time.perf_counter() - started, task_cpu_s=time.process_time() - started_cpu)
    return LogResult(row, stop_rows)


def _describe(exc: BaseException) -> str:
    """The exception and where it was raised (file:line), for an error row."""
    where = traceback.extract_tb(exc.__traceback__)[-1] if exc.__traceback__ else None
    at = f" (at {Path(where.filename).name}:{where.lineno})" if where else ""
    return f"{type(exc).__name__}: {exc}{at}"[:2000]


def _base_row(task: LogTask) -> dict[str, Any]:
    return {"path": task.path, "key": task.key, "config": task.config, "config_hash": task.config_hash,
            "frictiond_version": __version__, "estimator": None, "label": task.label}


def _summary_columns(summary: Any) -> dict[str, Any]:
    stats = summary.stats
    seconds = summary.status_seconds()
    span = (summary.last_time_s - summary.first_time_s) if summary.first_time_s is not None else 0.0
    final = summary.final
    columns: dict[str, Any] = {
        "frames": stats.frames_read, "input_frames": stats.input_frames, "updates": stats.updates,
        "duration_s": span, "faults": dict(stats.faults), "faults_total": sum(stats.faults.values()),
        "undecodable": stats.undecodable_total, "counter_jumps": summary.counter_jumps,
        "final_status": Status(final.status).name if final is not None else None,
        "final_mu_max": final.mu_max if final is not None else None,
    }
    for status, name in zip(Status, rs.STATUS_COLUMNS):
        columns[name] = seconds.get(status.name, 0.0)
    return columns


def replay_command(task: LogTask, stop_index: int) -> str:
    """The command that replays the stop's log and draws it (the estimate at a stop depends on the
    drive before it, so the whole log is replayed; the stop's span is in its row)."""
    config = f" --config {shlex.quote(task.config)}" if task.config else ""
    plot = f"{Path(task.path).stem}-stop{stop_index}.png"
    return f"frictiond replay {shlex.quote(task.path)}{config} --plot {shlex.quote(plot)}"


def _stop_row(task: LogTask, index: int, stop: Stop, first_s: float, estimator: str) -> dict[str, Any]:
    row = _base_row(task)
    row.update(estimator=estimator, stop_index=index, start_s=stop.start_s, start_offset_s=stop.start_s - first_s, end_s=stop.end_s,
               duration_s=stop.duration_s, speed_start_mps=stop.speed_start_mps, speed_end_mps=stop.speed_end_mps,
               final_status=stop.final_status, mu_max_valid=stop.mu_max_valid, confidence=stop.confidence,
               time_to_valid_s=stop.time_to_valid_s, valid_share=stop.valid_share,
               replay_command=replay_command(task, index))
    return row


def replay_many(tasks: list[LogTask]) -> list[LogResult]:
    """Several logs in one task (`--chunk`): fewer round trips to the scheduler per log."""
    return [replay_one(t) for t in tasks]


@dataclass
class RunReport:
    total: int = 0          # logs given
    skipped: int = 0        # already done in the result set
    replayed: int = 0       # replayed in this run, failed ones included
    failed: int = 0
    stops: int = 0
    wall_s: float = 0.0
    task_s: float = 0.0     # sum of the replays' own times (inside the workers)
    task_cpu_s: float = 0.0  # ... their CPU time
    drive_s: float = 0.0    # sum of the replayed logs' durations
    failures: list[tuple[str, str, str]] = field(default_factory=list)   # (path, kind, message)


Progress = Callable[[RunReport], None]


def pending_tasks(folder: Path, tasks: list[LogTask]) -> tuple[list[LogTask], int]:
    """The tasks not done yet in the result set, and how many were. A log whose path is recorded
    under another key (the file changed, or another config) loses its old rows: one row per log."""
    done = rs.done_keys(folder)
    todo = [t for t in tasks if t.key not in done]
    stale = set(done.values()) & {t.path for t in todo}
    rs.drop_logs(folder, stale)
    return todo, len(tasks) - len(todo)


def run_fleet(tasks: list[LogTask], folder: Path, executor: concurrent.futures.Executor | None = None,
              chunk: int = 1, progress: Progress | None = None) -> RunReport:
    """Replay the tasks not yet done into the result set at folder (created if new).

    With an executor, chunks of `chunk` logs are submitted as `replay_many` calls, at most
    MAX_IN_FLIGHT ahead of the results; without one they run here, one after the other (the
    sequential path: same task, same writing). Results are written every BATCH_LOGS logs or
    BATCH_SECONDS, so a killed run loses at most one batch.
    """
    started = time.perf_counter()
    rs.init_results(folder)
    rs.clean_partial(folder)
    todo, skipped = pending_tasks(folder, tasks)
    report = RunReport(total=len(tasks), skipped=skipped)
    writer = _BatchWriter(folder)
    chunks = [todo[k:k + max(1, chunk)] for k in range(0, len(todo), max(1, chunk))]
    try:
        for results in _results(chunks, executor):
            for result in results:
                _count(report, result)
                writer.add(result)
            report.wall_s = time.perf_counter() - started
            if progress is not None:
                progress(report)
    finally:
        writer.flush()
    report.wall_s = time.perf_counter() - started
    return report


def _results(chunks: list[list[LogTask]], executor: concurrent.futures.Executor | None) -> Iterable[list[LogResult]]:
    """Each chunk's results as they finish (completion order with an executor)."""
    if executor is None:
        for tasks in chunks:
            yield replay_many(tasks)
        return
    waiting: deque[list[LogTask]] = deque(chunks)
    running: dict[concurrent.futures.Future, list[LogTask]] = {}
    try:
        while waiting or running:
            while waiting and len(running) < MAX_IN_FLIGHT:
                tasks = waiting.popleft()
                running[executor.submit(replay_many, tasks)] = tasks
            done, _ = concurrent.futures.wait(running, return_when=concurrent.futures.FIRST_COMPLETED)
            for future in done:
                tasks = running.pop(future)
                yield _outcome(future, tasks)
    finally:
        for future in running:
            future.cancel()


def _outcome(future: concurrent.futures.Future, tasks: list[LogTask]) -> list[LogResult]:
    """A finished future's results; a task that died with its worker (a crash of the process
    itself, which `replay_one` cannot catch) becomes error rows."""
    try:
        return future.result()
    except Exception as exc:  # noqa: BLE001 - e.g. distributed.KilledWorker
        rows = []
        for task in tasks:
            row = _base_row(task)
            row.update(size_bytes=task.size_bytes, mtime_ns=task.mtime_ns, error_kind="worker",
                       error_message=_describe(exc))
            rows.append(LogResult(row))
        return rows


def _count(report: RunReport, result: LogResult) -> None:
    report.replayed += 1
    report.stops += len(result.stop_rows)
    report.task_s += result.log_row.get("task_s") or 0.0
    report.task_cpu_s += result.log_row.get("task_cpu_s") or 0.0
    report.drive_s += result.log_row.get("duration_s") or 0.0
    if result.failed:
        report.failed += 1
        row = result.log_row
        report.failures.append((row["path"], row["error_kind"], row["error_message"]))


class _BatchWriter:
    """Collects finished logs and writes them as one part per batch (see `results`)."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        # Unique per run: two runs in the same second (or a resumed one) must not overwrite parts.
        self.run_id = f"{time.strftime('%Y%m%dT%H%M%S', time.gmtime())}-{uuid.uuid4().hex[:8]}"
        self.parts = 0
        self.logs: list[dict[str, Any]] = []
        self.stops: list[dict[str, Any]] = []
        self.last_write_s = time.monotonic()

    def add(self, result: LogResult) -> None:
        self.logs.append(result.log_row)
        self.stops.extend(result.stop_rows)
        if len(self.logs) >= BATCH_LOGS or time.monotonic() - self.last_write_s >= BATCH_SECONDS:
            self.flush()

    def flush(self) -> None:
        if self.logs:
            rs.write_batch(self.folder, f"part-{self.run_id}-{self.parts:05d}.parquet", self.logs, self.stops)
            self.parts += 1
        self.logs, self.stops = [], []
        self.last_write_s = time.monotonic()


def progress_printer(stream: Any = None) -> Progress:
    """A one-line counter on stderr, redrawn in place on a terminal; silent otherwise (the command
    prints its final line itself)."""
    out = stream if stream is not None else sys.stderr
    if not out.isatty():
        return lambda report: None
    last = [0.0]

    def show(report: RunReport) -> None:
        now = time.monotonic()
        todo = report.total - report.skipped
        if now - last[0] < 0.2 and report.replayed < todo:
            return
        last[0] = now
        rate = report.replayed / report.wall_s if report.wall_s > 0 else 0.0
        eta = f", {((todo - report.replayed) / rate):.0f} s left" if rate > 0 and report.replayed < todo else ""
        width = 30
        filled = int(width * report.replayed / todo) if todo else width
        out.write(f"\r[{'#' * filled}{'.' * (width - filled)}] {report.replayed}/{todo} logs, "
                  f"{report.failed} failed, {rate:.1f} logs/s{eta}   ")
        if report.replayed >= todo:
            out.write("\n")
        out.flush()

    return show
