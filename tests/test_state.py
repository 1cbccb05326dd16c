"""Nothing lost: the atomic state file and the rotating, flushed estimate log."""
from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import can
import pytest

from frictiond.estimate_log import EstimateLog, rotated_path
from frictiond.frames import Frame
from frictiond.pipeline import Pipeline
from frictiond.state import StateError, StateFile, decode_state, encode_state, write_atomic

REPO = Path(__file__).resolve().parents[1]


# ------------------------------------------------------------------------------------ state file
def test_state_round_trip_restores_the_prior(default_config, tmp_path):
    pipeline = Pipeline(default_config)
    state = pipeline.estimator.state()
    state["parameters"]["theta_fl"] = 0.5
    store = StateFile(tmp_path / "sub" / "state.json")
    assert store.save(state, now_s=123.0)
    doc = store.read()
    assert doc["format"] == 1 and doc["time"] == 123.0 and doc["estimator"]["kind"] == state["kind"]
    fresh = Pipeline(default_config)
    assert store.load_into(fresh.estimator)
    assert fresh.estimator.state()["parameters"]["theta_fl"] == pytest.approx(0.5)
    assert oct(os.stat(store.path).st_mode & 0o777) == "0o600"
    assert not (tmp_path / "sub" / "state.json.tmp").exists()


def test_non_finite_values_are_stored_as_null():
    doc = json.loads(encode_state({"kind": "x", "a": float("nan"), "b": [float("inf"), 1.0]}, 1.0))
    assert doc["estimator"] == {"kind": "x", "a": None, "b": [None, 1.0]}


@pytest.mark.parametrize(
    "content",
    [b"", b"{", b"\xff\xfe", b"[]", b'{"format": 2, "time": 1, "estimator": {}}', b'{"format": 1, "time": 1}',
     b'{"format": 1, "time": "x", "estimator": {}}', b'{"format": 1, "time": NaN, "estimator": {}}',
     b'{"format": 1, "time": 1, "estimator": {"kind": "lugre-tr", "parameters": {"theta_fl": "x"}}}',
     b'{"format": 1, "time": 1, "estimator": {"kind": "burckhardt-rls", "parameters": []}}'],
)
def test_corrupt_state_file_is_ignored_with_a_warning(default_config, tmp_path, caplog, content):
    path = tmp_path / "state.json"
    path.write_bytes(content)
    pipeline = Pipeline(default_config)
    before = pipeline.estimator.state()
    assert not StateFile(path).load_into(pipeline.estimator)
    assert pipeline.estimator.state() == before
    assert any("ignoring state file" in r.message for r in caplog.records)


def test_unreadable_state_file_is_ignored(default_config, tmp_path, caplog):
    path = tmp_path / "state.json"
    path.mkdir()   # a directory where the file should be: read fails with an OSError
    assert not StateFile(path).load_into(Pipeline(default_config).estimator)
    assert any("ignoring state file" in r.message for r in caplog.records)
    assert not StateFile(path).save({"kind": "x"})   # cannot replace a directory: logged, not raised


def test_missing_state_file_is_not_a_warning(default_config, tmp_path, caplog):
    assert not StateFile(tmp_path / "none.json").load_into(Pipeline(default_config).estimator)
    assert not [r for r in caplog.records if r.levelname == "WARNING"]


def test_decode_rejects_oversized_files():
    with pytest.raises(StateError):
        decode_state(b" " * (2 << 20))


_WRITER = r"""
import sys
from frictiond.state import StateFile
store = StateFile(sys.argv[1])
pad = "x" * 200_000          # big enough that a write spans many system calls
i = 0
print("go", flush=True)
while True:
    i += 1
    store.save({"kind": "test", "counter": i, "pad": pad})
"""


def test_kill_9_during_writes_never_leaves_a_corrupt_state_file(tmp_path):
    path = tmp_path / "state.json"
    rng = random.Random(4)
    last = 0
    kills = 0
    for _ in range(25):
        proc = subprocess.Popen([sys.executable, "-c", _WRITER, str(path)], stdout=subprocess.PIPE, cwd=REPO)
        assert proc.stdout.readline() == b"go\n"
        time.sleep(rng.uniform(0.0, 0.15))
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        proc.stdout.close()
        kills += 1
        doc = StateFile(path).read()    # raises StateError if torn
        if doc is None:
            continue
        counter = doc["estimator"]["counter"]
        assert len(doc["estimator"]["pad"]) == 200_000
        assert counter >= 1
        last = counter
    assert kills == 25 and last > 0


def test_write_atomic_replaces_existing_content(tmp_path):
    path = tmp_path / "f"
    write_atomic(path, b"one")
    write_atomic(path, b"two")
    assert path.read_bytes() == b"two"


# ------------------------------------------------------------------------------------ estimate log
def _frames(n, t0=1_700_000_000.0):
    return [Frame(t0 + 0.01 * i, 0x3E0, bytes([i % 256, 1, 2, 3, 4, 5, 6, 7])) for i in range(n)]


def _read(path):
    with can.LogReader(str(path)) as reader:
        return [(round(m.timestamp, 6), m.arbitration_id, bytes(m.data)) for m in reader]


@pytest.mark.parametrize("suffix", [".log", ".blf", ".asc"])
def test_estimate_log_writes_every_frame_in_each_format(tmp_path, suffix):
    path = tmp_path / f"estimates{suffix}"
    frames = _frames(300)
    with EstimateLog(path, max_bytes=10_000_000, backups=2) as elog:
        elog.write_all(frames)
    got = _read(path)
    assert [(g[1], g[2]) for g in got] == [(f.can_id, f.data) for f in frames]
    if suffix != ".asc":   # ASC stores times relative to its start
        assert got[0][0] == pytest.approx(1_700_000_000.0, abs=1e-3)


@pytest.mark.parametrize("suffix", [".log", ".blf"])
def test_flush_puts_buffered_frames_on_disk_without_closing(tmp_path, suffix):
    path = tmp_path / f"estimates{suffix}"
    clock = [0.0]
    elog = EstimateLog(path, flush_interval_s=1.0, clock=lambda: clock[0])
    elog.write_all(_frames(50))
    clock[0] = 0.5
    elog.poll()
    clock[0] = 1.01
    elog.poll()            # due: flushed and fsynced, file still open
    snapshot = tmp_path / f"copy{suffix}"
    snapshot.write_bytes(path.read_bytes())   # what a power cut would leave behind
    assert len(_read(snapshot)) == 50
    elog.close()


def test_estimate_log_rotates_by_size_and_keeps_the_suffix(tmp_path):
    path = tmp_path / "estimates.log"
    frames = _frames(3000)
    with EstimateLog(path, max_bytes=20_000, backups=3) as elog:
        elog.write_all(frames)
        assert elog.rotations >= 4
    files = [rotated_path(path, i) for i in range(4)]
    assert [f.name for f in files] == ["estimates.log", "estimates.1.log", "estimates.2.log", "estimates.3.log"]
    assert all(f.exists() for f in files) and not rotated_path(path, 4).exists()
    assert all(f.stat().st_size <= 20_000 + 100 for f in files)
    # newest last: the current file ends with the last frame; backups are contiguous before it
    chunks = [_read(f) for f in reversed(files)]
    joined = [x for chunk in chunks for x in chunk]
    assert joined == [(round(f.time_s, 6), f.can_id, f.data) for f in frames[-len(joined):]]


def test_an_old_log_is_rotated_away_at_start(tmp_path):
    path = tmp_path / "estimates.log"
    with EstimateLog(path) as elog:
        elog.write_all(_frames(5))
    with EstimateLog(path) as elog:
        elog.write_all(_frames(7))
    assert len(_read(path)) == 7 and len(_read(rotated_path(path, 1))) == 5


def test_rotated_names():
    assert rotated_path(Path("a/est.log"), 2) == Path("a/est.2.log")
    assert rotated_path(Path("est.log.gz"), 1) == Path("est.1.log.gz")
    assert rotated_path(Path("est.blf"), 0) == Path("est.blf")
