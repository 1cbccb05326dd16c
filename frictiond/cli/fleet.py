"""`frictiond fleet`: many logs through one estimator version on Dask (`replay`), and two result
sets compared stop by stop (`diff`). Needs the `fleet` extra; without it only this command says so."""
from __future__ import annotations

import argparse
import fnmatch
import glob
import sys
from pathlib import Path

from .common import EXIT_CONFIG, EXIT_DATA_ERROR, EXIT_NO_INPUT, EXIT_UNAVAILABLE, add_config_argument, fail

# What a folder given to `fleet replay` is searched for (a truth CSV beside a log is no log).
FOLDER_SUFFIXES = (".log", ".asc", ".blf")


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "fleet", help="replay many logs on Dask into Parquet results, and diff two result sets",
        description="Fleet replay: every log through the same pipeline as `frictiond replay`, spread over "
        "a Dask cluster (an embedded local one by default), results as Parquet; and the stop-by-stop "
        "diff of two result sets. Needs: pip install 'frictiond[fleet]'.")
    commands = parser.add_subparsers(title="fleet commands", dest="fleet_command", metavar="COMMAND")
    _add_replay(commands)
    _add_diff(commands)
    parser.set_defaults(func=lambda args: _no_command(parser))


def _no_command(parser: argparse.ArgumentParser) -> int:
    from ..fleet.cluster import missing_extra

    problem = missing_extra()
    if problem is not None:
        return fail(problem, EXIT_UNAVAILABLE)
    parser.print_help()
    return 2


def _add_replay(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser(
        "replay", help="replay logs (files, folders, globs) into a result set",
        description="Replay every log into RESULTS (Parquet: logs/ one row per log, stops/ one row per "
        "braking stop). Logs already in RESULTS are skipped (a resumed run); a log that fails becomes "
        "an error row and the run goes on (exit status 65 if any failed).")
    parser.add_argument("logs", nargs="+", metavar="LOGS",
                        help="log files, folders (searched for .log/.asc/.blf) or glob patterns")
    parser.add_argument("--output", "-o", required=True, metavar="RESULTS", help="result set folder (new or a previous run's)")
    add_config_argument(parser)
    parser.add_argument("--manifest", metavar="FILE", help="YAML list of {match: GLOB, config: CFG}: a config per "
                        "log (first match wins; paths relative to the manifest; unmatched logs use --config)")
    parser.add_argument("--scheduler", metavar="URL", help="an existing Dask scheduler (tcp://HOST:8786); "
                        "default: an embedded local cluster")
    parser.add_argument("--workers", type=int, metavar="N", help="local cluster's worker processes (default: one per core)")
    parser.add_argument("--no-cluster", action="store_true", help="replay here, one log after the other, without Dask")
    parser.add_argument("--chunk", type=int, default=1, metavar="N", help="logs per Dask task (default 1)")
    parser.add_argument("--label", metavar="TEXT", help="stored in every row (e.g. the release candidate's name)")
    parser.set_defaults(func=_do_replay)


def _add_diff(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser(
        "diff", help="what changed per stop between two result sets (exit 1 if anything did)",
        description="Match the stops of two result sets (same log, nearby start) and list what changed beyond "
        "the tolerances, largest first, with the command that replays each stop. Exit status 1 when "
        "anything changed, 0 when nothing did, 2 for bad input.")
    parser.add_argument("a", metavar="A", help="result set (the reference, e.g. the released version)")
    parser.add_argument("b", metavar="B", help="result set (the candidate)")
    parser.add_argument("--tolerance", type=float, default=0.02, help="MuMax change allowed (default 0.02)")
    parser.add_argument("--time-tolerance", type=float, default=0.2, metavar="S",
                        help="time-to-VALID change allowed, seconds (default 0.2)")
    parser.add_argument("--start-tolerance", type=float, default=0.5, metavar="S",
                        help="stops starting this close (seconds) in the same log are the same stop (default 0.5)")
    parser.add_argument("--limit", type=int, default=50, metavar="N", help="print at most N changes (default 50; 0: all)")
    parser.set_defaults(func=_do_diff)


def expand_logs(patterns: list[str]) -> list[Path]:
    """Files as given, folders searched recursively, anything else as a glob; sorted, no repeats.
    ValueError naming an argument that matches nothing."""
    found: dict[Path, None] = {}
    for pattern in patterns:
        path = Path(pattern)
        if path.is_dir():
            hits = [p for p in sorted(path.rglob("*")) if p.is_file() and p.suffix.lower() in FOLDER_SUFFIXES]
        elif path.exists():
            hits = [path]
        else:
            hits = [Path(p) for p in sorted(glob.glob(pattern, recursive=True)) if Path(p).is_file()]
            if not hits:
                raise ValueError(f"{pattern}: no such file or folder, and no file matches it as a pattern")
        for hit in hits:
            found.setdefault(hit.resolve(), None)
    return list(found)


def read_manifest(path: Path) -> list[tuple[str, str | None]]:
    """(absolute glob, config path or None for the built-in) rules of a manifest; ValueError if bad."""
    import yaml

    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ValueError(f"{path}: cannot read manifest: {exc}") from None
    if not isinstance(data, list) or not data:
        raise ValueError(f"{path}: a manifest is a list of {{match: GLOB, config: CFG}} entries")
    base = path.resolve().parent
    rules = []
    for k, entry in enumerate(data):
        if not isinstance(entry, dict) or set(entry) - {"match", "config"} or not isinstance(entry.get("match"), str):
            raise ValueError(f"{path}: entry {k + 1}: needs match: GLOB and config: CFG (and nothing else)")
        config = entry.get("config")
        if config is not None and not isinstance(config, str):
            raise ValueError(f"{path}: entry {k + 1}: config must be a file path or null (the built-in)")
        rules.append((str(base / entry["match"]), str((base / config).resolve()) if config else None))
    return rules


def config_for(log: Path, rules: list[tuple[str, str | None]], default: str | None) -> str | None:
    for pattern, config in rules:
        if fnmatch.fnmatchcase(str(log), pattern):
            return config
    return default


def _build_tasks(args: argparse.Namespace) -> list:   # -> list[LogTask]; exits on bad input
    from ..config import ConfigError
    from ..fleet.run import config_hash, make_task
    from .common import load_config_or_exit

    try:
        logs = expand_logs(args.logs)
        rules = read_manifest(Path(args.manifest)) if args.manifest else []
    except ValueError as exc:
        raise SystemExit(fail(str(exc), EXIT_NO_INPUT)) from None
    default = str(Path(args.config).resolve()) if args.config else None
    configs = {config_for(log, rules, default) for log in logs}
    hashes = {}
    for config in sorted(configs, key=str):
        load_config_or_exit(config)       # checked once here, not once per log in the workers
        try:
            hashes[config] = config_hash(config)
        except (ConfigError, OSError) as exc:
            raise SystemExit(fail(f"config error: {exc}", EXIT_CONFIG)) from None
    tasks = []
    for log in logs:
        config = config_for(log, rules, default)
        tasks.append(make_task(log, config, hashes[config], args.label))
    return tasks


def _do_replay(args: argparse.Namespace) -> int:
    from ..fleet.cluster import missing_extra

    problem = missing_extra()
    if problem is not None:
        return fail(problem, EXIT_UNAVAILABLE)
    from ..fleet.results import NotAResultSet
    from ..fleet.run import progress_printer, run_fleet

    if args.chunk < 1 or (args.workers is not None and args.workers < 1):
        return fail("--chunk and --workers must be at least 1", 2)
    tasks = _build_tasks(args)
    if not tasks:
        return fail("no logs found in " + " ".join(args.logs), EXIT_NO_INPUT)
    output = Path(args.output)
    try:
        if args.no_cluster:
            report = run_fleet(tasks, output, None, args.chunk, progress_printer())
        else:
            from ..fleet.cluster import open_executor

            with open_executor(args.scheduler, args.workers) as executor:
                report = run_fleet(tasks, output, executor, args.chunk, progress_printer())
    except NotAResultSet as exc:
        return fail(str(exc), 2)
    except OSError as exc:
        return fail(f"fleet replay: {exc}", EXIT_UNAVAILABLE)
    for path, kind, message in report.failures[:20]:
        print(f"frictiond: {path}: {kind}: {message}", file=sys.stderr)
    if len(report.failures) > 20:
        print(f"frictiond: ... and {len(report.failures) - 20} more failed logs (error_kind in logs/)", file=sys.stderr)
    print(f"fleet: {report.total} logs, {report.skipped} already done, {report.replayed} replayed "
          f"({report.drive_s / 3600:.2f} h of driving) in {report.wall_s:.1f} s ({report.failed} failed), "
          f"{report.stops} stops -> {output}")
    return EXIT_DATA_ERROR if report.failed else 0


def _do_diff(args: argparse.Namespace) -> int:
    from ..fleet.cluster import missing_extra

    problem = missing_extra()
    if problem is not None:
        return fail(problem, EXIT_UNAVAILABLE)
    from ..fleet.diff import diff_results, format_report
    from ..fleet.results import NotAResultSet

    if args.tolerance < 0 or args.time_tolerance < 0 or args.start_tolerance < 0:
        return fail("tolerances must be >= 0", 2)
    try:
        report = diff_results(Path(args.a), Path(args.b), args.tolerance, args.time_tolerance, args.start_tolerance)
    except NotAResultSet as exc:
        return fail(str(exc), 2)
    print(format_report(report, args.tolerance, args.time_tolerance, args.limit or None))
    return 1 if report.changes else 0
