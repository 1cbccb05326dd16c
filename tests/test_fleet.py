"""Fleet replay (issue 23): a generated corpus on a 2-worker local Dask cluster, bad logs,
resumed runs, and the stop-by-stop diff of two result sets."""
from __future__ import annotations

import math
import shutil
import sys
from pathlib import Path

import pytest
import yaml

pytest.importorskip("distributed")
pa = pytest.importorskip("pyarrow")
import pyarrow.parquet as pq  # noqa: E402

from frictiond.cli.main import main  # noqa: E402
from frictiond.config import default_config_path  # noqa: E402
from frictiond.fleet import results as rs  # noqa: E402
from frictiond.fleet.corpus import write_corpus  # noqa: E402
from frictiond.fleet.run import config_hash, make_task, replay_one, run_fleet  # noqa: E402

CORPUS_LOGS = 50
LOG_SECONDS = 2.6


@pytest.fixture(scope="session")
def corpus(tmp_path_factory) -> Path:
    """50 short generated drives (.log/.asc/.blf in turn), one ABS stop each, plus a garbage .blf
    that crashes python-can's reader."""
    folder = tmp_path_factory.mktemp("fleet-corpus")
    write_corpus(folder, CORPUS_LOGS, LOG_SECONDS, seed=3)
    (folder / "zz-garbage.blf").write_bytes(bytes(range(256)) * 20)
    return folder


def _configs(folder: Path) -> tuple[Path, Path]:
    """The default config (DBC path made absolute) and the same with the RLS baseline estimator."""
    data = yaml.safe_load(default_config_path().read_text())
    data["can"]["dbc"] = str(default_config_path().parent / "frictiond.dbc")
    a = folder / "lugre.yaml"
    a.write_text(yaml.safe_dump(data))
    data["estimator"] = {"kind": "burckhardt-rls"}
    b = folder / "rls.yaml"
    b.write_text(yaml.safe_dump(data))
    return a, b


def _tasks(logs, config=None):
    h = config_hash(str(config) if config else None)
    return [make_task(p, str(config) if config else None, h) for p in logs]


def _by_path(folder: Path, table: str) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = {}
    for row in rs.read_table(folder, table).to_pylist():
        out.setdefault(row["path"], []).append(row)
    return out


@pytest.fixture(scope="session")
def sequential(corpus, tmp_path_factory) -> Path:
    """The corpus replayed without Dask: the reference of the cluster run."""
    out = tmp_path_factory.mktemp("fleet-seq") / "results"
    logs = sorted(corpus.glob("drive-*"))
    report = run_fleet(_tasks(logs), out)
    assert report.replayed == CORPUS_LOGS and report.failed == 0
    return out


def test_cluster_of_two_workers_matches_the_sequential_path(corpus, sequential, tmp_path, capsys):
    out = tmp_path / "results"
    code = main(["fleet", "replay", str(corpus), "--output", str(out), "--workers", "2"])
    captured = capsys.readouterr()
    assert code == 65, captured.err           # the garbage log failed, the run went on
    assert "zz-garbage.blf: crash: BLFParseError" in captured.err
    logs = _by_path(out, "logs")
    hours = sum(r[0]["duration_s"] or 0.0 for r in logs.values()) / 3600
    assert f"{CORPUS_LOGS + 1} logs, 0 already done, {CORPUS_LOGS + 1} replayed ({hours:.2f} h of driving)" in captured.out
    assert len(logs) == CORPUS_LOGS + 1
    garbage = logs[str((corpus / "zz-garbage.blf").resolve())][0]
    assert garbage["error_kind"] == "crash" and "BLFParseError" in garbage["error_message"]
    # Both worker processes took part.
    assert len({r[0]["worker"] for r in logs.values()}) == 2

    reference_logs = _by_path(sequential, "logs")
    reference_stops = _by_path(sequential, "stops")
    stops = _by_path(out, "stops")
    assert reference_stops.keys() == stops.keys()
    assert sum(len(v) for v in stops.values()) >= CORPUS_LOGS - 2   # one stop per drive (almost all)
    for path, ref in reference_logs.items():
        row = logs[path][0]
        assert row["error_kind"] is None
        for column in ("frames", "updates", "duration_s", "valid_s", "not_excited_s", "stops", "faults_total"):
            assert row[column] == ref[0][column], (path, column)
        # The simulator ends a run once the car is below 2 m/s: on a grippy road before LOG_SECONDS.
        assert row["frames"] > 700 and 1.9 < row["duration_s"] <= LOG_SECONDS + 0.05
        assert sum(row[c] for c in rs.STATUS_COLUMNS) == pytest.approx(row["duration_s"], abs=0.2)
    for path, ref in reference_stops.items():
        for mine, theirs in zip(stops[path], ref):
            for column in ("start_s", "end_s", "final_status", "mu_max_valid", "time_to_valid_s", "confidence"):
                a, b = mine[column], theirs[column]
                assert a == b or (isinstance(a, float) and math.isnan(a) and math.isnan(b)), (path, column)


def test_stops_are_the_simulated_abs_stops(sequential):
    stops = [r for rows in _by_path(sequential, "stops").values() for r in rows]
    logs = _by_path(sequential, "logs")
    assert all(logs[path][0]["stops"] == len(rows) for path, rows in _by_path(sequential, "stops").items())
    for stop in stops:
        # Free rolling first (at least 1 s), then the stop from 12 m/s to the log's end.
        assert 0.9 <= stop["start_offset_s"] <= LOG_SECONDS - 0.8
        assert stop["speed_start_mps"] == pytest.approx(12.0, abs=0.5)
        assert stop["speed_end_mps"] < stop["speed_start_mps"] - 2.0
        assert stop["replay_command"].startswith(f"frictiond replay {stop['path']} --plot ")
    valid = [s for s in stops if s["final_status"] == "VALID"]
    assert len(valid) >= 0.8 * len(stops)
    assert all(0.0 < s["mu_max_valid"] < 1.3 and 0.0 < s["time_to_valid_s"] < 1.0 for s in valid)
    assert {r["frictiond_version"] for r in stops} == {__import__("frictiond").__version__}
    assert {r["config_hash"] for r in stops} == {config_hash(None)}


def test_bad_logs_become_error_rows_and_the_rest_replays(corpus, tmp_path):
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "truncated.log").write_text("(1.000000) can0 123#00\n(oops\n")
    (bad / "empty.asc").write_text("")
    (bad / "notes.txt").write_text("not a log")
    missing = bad / "vanished.log"
    missing.write_text("")
    tasks = _tasks([*sorted(bad.iterdir()), corpus / "drive-00000.log"])
    missing.unlink()     # gone between listing and replay
    report = run_fleet(tasks, tmp_path / "results")
    kinds = {Path(p).name: k for p, k, _ in report.failures}
    assert kinds == {"truncated.log": "crash", "notes.txt": "format", "vanished.log": "unreadable"}
    logs = _by_path(tmp_path / "results", "logs")
    assert logs[str((bad / "empty.asc").resolve())][0]["frames"] == 0    # empty is not an error
    good = logs[str((corpus / "drive-00000.log").resolve())][0]
    assert good["error_kind"] is None and good["stops"] == 1


def test_a_resumed_run_skips_done_logs_and_redoes_a_lost_part(corpus, tmp_path, monkeypatch):
    monkeypatch.setattr("frictiond.fleet.run.BATCH_LOGS", 5)
    logs = sorted(corpus.glob("drive-*"))[:12]
    out = tmp_path / "results"
    first = run_fleet(_tasks(logs), out)
    assert (first.replayed, first.skipped) == (12, 0)
    parts = sorted((out / "logs").glob("part-*.parquet"))
    assert len(parts) == 3                      # batches of 5, 5 and 2
    calls = []
    monkeypatch.setattr("frictiond.fleet.run.replay_one", lambda task: calls.append(task.path) or replay_one(task))
    again = run_fleet(_tasks(logs), out)
    assert (again.replayed, again.skipped, calls) == (0, 12, [])

    # A run killed between writing a batch's stops and its logs part: the logs are not done.
    lost = pq.read_table(parts[1]).column("path").to_pylist()
    parts[1].unlink()
    (out / "logs" / "part-x.parquet.tmp").write_bytes(b"half written")
    resumed = run_fleet(_tasks(logs), out)
    assert (resumed.replayed, resumed.skipped) == (5, 7)
    assert sorted(calls) == sorted(lost)
    assert not list((out / "logs").glob("*.tmp"))
    rows = _by_path(out, "logs")
    stops = _by_path(out, "stops")
    assert len(rows) == 12 and all(len(v) == 1 for v in rows.values())
    assert all(len(v) == rows[p][0]["stops"] for p, v in stops.items())   # no orphan stops left twice

    # A log that changed since (new mtime) is replayed again, and its old row replaced.
    logs[0].touch()
    import os
    os.utime(logs[0], ns=(1, 1))
    changed = run_fleet(_tasks(logs), out)
    assert changed.replayed == 1
    assert len(_by_path(out, "logs")[str(logs[0].resolve())]) == 1


def test_diff_of_two_configs_lists_the_changed_stops_and_exits_1(sequential, corpus, tmp_path, capsys):
    lugre, rls = _configs(tmp_path)
    logs = sorted(corpus.glob("drive-*"))[:18]
    for name, config in (("a", lugre), ("b", rls)):
        assert main(["fleet", "replay", *map(str, logs), "-o", str(tmp_path / name), "-c", str(config),
                     "--no-cluster"]) == 0
    capsys.readouterr()
    assert main(["fleet", "diff", str(tmp_path / "a"), str(tmp_path / "b"), "--limit", "0"]) == 1
    out = capsys.readouterr().out
    changed = [line for line in out.splitlines() if line.startswith("changed")]
    assert changed and "0 added, 0 missing" in out
    commands = [line.strip() for line in out.splitlines() if line.startswith("         frictiond replay")]
    assert len(commands) == len(changed) and all(f"--config {rls}" in c for c in commands)
    # Sorted by size: status changes first, then by |ΔMuMax| (all tolerances at defaults).
    deltas = [abs(float(line.split("(")[-1].rstrip(")"))) for line in changed if "status" not in line
              and "VALID " not in line and "time to VALID" not in line]
    assert deltas == sorted(deltas, reverse=True)
    assert all(d > 0.02 for d in deltas)

    # The same config twice: nothing changed.
    assert main(["fleet", "diff", str(tmp_path / "a"), str(tmp_path / "a")]) == 0
    # Against the default config's run (same estimator, same logs; extra logs in `sequential`).
    assert main(["fleet", "diff", str(tmp_path / "a"), str(sequential), "--limit", "0"]) == 1
    out = capsys.readouterr().out
    assert out.count("log replayed in B only") == CORPUS_LOGS - 18 and "changed  " not in out


def test_diff_changes_beyond_the_tolerance_only(sequential, tmp_path, capsys):
    # A copy of the results with one stop's MuMax moved: caught at 0.02, not at 0.1.
    copy = tmp_path / "copy"
    shutil.copytree(sequential, copy)
    part = sorted((copy / "stops").glob("*.parquet"))[0]
    table = pq.read_table(part)
    mu = table.column("mu_max_valid").to_pylist()
    k = next(i for i, v in enumerate(mu) if not math.isnan(v))
    mu[k] += 0.05
    pq.write_table(table.set_column(table.schema.get_field_index("mu_max_valid"), "mu_max_valid",
                                    pa.array(mu, pa.float64())), part)
    assert main(["fleet", "diff", str(sequential), str(copy)]) == 1
    assert "(+0.050)" in capsys.readouterr().out
    assert main(["fleet", "diff", str(sequential), str(copy), "--tolerance", "0.1"]) == 0


def test_diff_and_replay_reject_bad_input(sequential, corpus, tmp_path, capsys):
    assert main(["fleet", "diff", str(sequential), str(tmp_path / "nope")]) == 2
    assert "no such folder" in capsys.readouterr().err
    assert main(["fleet", "diff", str(sequential), str(tmp_path)]) == 2
    assert "not a fleet result set" in capsys.readouterr().err
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "x").write_text("")
    log = str(corpus / "drive-00000.log")
    assert main(["fleet", "replay", log, "-o", str(tmp_path / "other"), "--no-cluster"]) == 2
    assert "not a fleet result set" in capsys.readouterr().err
    assert main(["fleet", "replay", str(sequential), "-o", str(tmp_path / "r"), "--no-cluster"]) == 66
    assert "no logs found" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exited:
        main(["fleet", "replay", log, "-o", str(tmp_path / "r"), "-c", str(tmp_path / "none.yaml")])
    assert exited.value.code == 78 and "no such config file" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exited:
        main(["fleet", "replay", str(tmp_path / "*.nothing"), "-o", str(tmp_path / "r")])
    assert exited.value.code == 66 and "no file matches" in capsys.readouterr().err


def test_manifest_maps_logs_to_configs(corpus, tmp_path):
    lugre, rls = _configs(tmp_path)
    manifest = tmp_path / "fleet.yaml"
    manifest.write_text(yaml.safe_dump([{"match": str(corpus / "*.blf"), "config": rls.name},
                                        {"match": str(corpus / "*"), "config": str(lugre)}]))
    logs = [corpus / "drive-00000.log", corpus / "drive-00002.blf"]
    assert main(["fleet", "replay", *map(str, logs), "-o", str(tmp_path / "r"), "--manifest", str(manifest),
                 "--no-cluster"]) == 0
    rows = {Path(p).name: r[0] for p, r in _by_path(tmp_path / "r", "logs").items()}
    assert rows["drive-00002.blf"]["config"] == str(rls) and rows["drive-00002.blf"]["estimator"] == "burckhardt-rls"
    assert rows["drive-00000.log"]["config"] == str(lugre) and rows["drive-00000.log"]["estimator"] == "lugre-tr"
    assert rows["drive-00000.log"]["config_hash"] != rows["drive-00002.blf"]["config_hash"]


def test_fleet_without_the_extra_says_how_to_install_it(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "distributed", None)
    assert main(["fleet", "diff", "a", "b"]) == 69
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "pip install 'frictiond[fleet]'" in err


def test_open_executor_runs_plain_callables():
    from frictiond.fleet.cluster import open_executor

    with open_executor(workers=1) as executor:
        assert list(executor.map(math.sqrt, [4.0, 9.0])) == [2.0, 3.0]
        assert executor.submit(pow, 2, 10).result() == 1024


def test_replay_on_an_existing_scheduler(corpus, sequential, tmp_path, capsys):
    from distributed import LocalCluster

    logs = [str(corpus / f"drive-0000{k}{ext}") for k, ext in ((0, ".log"), (1, ".asc"), (2, ".blf"))]
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        code = main(["fleet", "replay", *logs, "-o", str(tmp_path / "r"), "--scheduler", cluster.scheduler_address])
    assert code == 0, capsys.readouterr().err
    rows = _by_path(tmp_path / "r", "stops")
    reference = _by_path(sequential, "stops")
    assert {p: [r["mu_max_valid"] for r in v] for p, v in rows.items()} == \
        {p: [r["mu_max_valid"] for r in reference[p]] for p in rows}


def test_progress_bar_on_a_terminal_only():
    import io

    from frictiond.fleet.run import RunReport, progress_printer

    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    tty, pipe = Terminal(), io.StringIO()
    for done in (1, 4):
        report = RunReport(total=5, skipped=1, replayed=done, failed=1, wall_s=2.0)
        progress_printer(tty)(report)
        progress_printer(pipe)(report)
    assert pipe.getvalue() == ""
    assert "\r[" in tty.getvalue() and "4/4 logs, 1 failed" in tty.getvalue() and tty.getvalue().endswith("\n")
