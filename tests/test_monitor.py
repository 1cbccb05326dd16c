"""`frictiond monitor`: the model, the rendered screen, --json, and the real thing under tmux."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

from frictiond.busio import LogWriter
from frictiond.codec import InputCodec, OutputCodec, load_databases
from frictiond.frames import Frame
from frictiond.monitor import FrameClock, LogPlayer, LogSource, MonitorModel, RateTracker
from frictiond.monitor_tui import big_text, render, sparkline
from frictiond.samples import FrictionEstimate, PhysicalSample, Status

from .conftest import REPO

PERIOD = 0.01
T0 = 100.0
N_UPDATES = 150
FINAL_MU = 0.8123
SLIPS = (0.05, 0.06, 0.03, 0.04)
MU_USED = (0.4, 0.41, 0.3, 0.31)
LOADS = (4000.0, 4100.0, 3000.0, 3100.0)
WHEEL_MU = (0.81, 0.82, 0.79, 0.80)


def codecs(config):
    inp = InputCodec(load_databases(config.can.dbc), config.signals, config.vehicle.wheel_radius)
    out = OutputCodec(load_databases([config.can.output_dbc]))
    return inp, out


def expected_estimate(k: int) -> FrictionEstimate:
    status = Status.INIT if k < 10 else Status.CONVERGING if k < 100 else Status.VALID
    mu = 0.0 if k < 10 else FINAL_MU + 0.3 * max(0.0, (99 - k) / 90)
    return FrictionEstimate(T0 + k * PERIOD, status, mu, 0.125, 1.5, 0.9 if k >= 100 else 0.3, WHEEL_MU, 0.01)


def known_frames(config) -> tuple[list[Frame], list[FrictionEstimate]]:
    """Inputs at 100 Hz (wheel speeds, accelerations), then frictiond's answer: estimate + 4 wheels."""
    inp, out = codecs(config)
    frames, estimates = [], []
    for k in range(N_UPDATES):
        t = T0 + k * PERIOD
        (ws,) = inp.encode_input("WHEEL_SPEEDS", {f"wheel_speed_{w}": 80.0 for w in ("fl", "fr", "rl", "rr")})
        (acc,) = inp.encode_input("ACCELERATIONS", {"accel_long": -3.0, "accel_lat": 0.0, "yaw_rate": 0.0})
        frames += [Frame(t, 0x0B0, ws), Frame(t + 0.002, 0x0C0, acc)]
        est = expected_estimate(k)
        sample = PhysicalSample(t, 25.0, SLIPS, MU_USED, LOADS, (0.0,) * 4, (True,) * 4, True)
        frames.append(Frame(t + 0.004, out.estimate_id, out.encode_estimate(est)))
        frames += [Frame(t + 0.004, out.wheel_id, p) for p in out.encode_wheels(est, sample)]
        estimates.append(est)
    return frames, estimates


@pytest.fixture
def known_log(tmp_path, default_config):
    frames, estimates = known_frames(default_config)
    path = tmp_path / "known.log"
    with LogWriter(path) as writer:
        writer.write_all(frames)
    return path, estimates


# ------------------------------------------------------------------------------------- model
def test_model_decodes_estimate_wheels_and_rates(default_config):
    inp, out = codecs(default_config)
    frames, estimates = known_frames(default_config)
    model = MonitorModel(out, inp)
    objs = list(model.feed_all(frames))
    assert len(objs) == N_UPDATES
    snap = model.snapshot(frames[-1].time_s + 0.005)
    assert snap.estimate.status == "VALID"
    assert snap.estimate.mu_max == pytest.approx(FINAL_MU, abs=1e-4)
    assert snap.estimate.confidence == pytest.approx(0.9, abs=0.005)
    assert snap.estimate.slip_at_mu_max == pytest.approx(0.125, abs=1e-3)
    for i, w in enumerate(snap.wheels):
        assert w.slip == pytest.approx(SLIPS[i], abs=5e-4)
        assert w.mu_used == pytest.approx(MU_USED[i], abs=1e-3)
        assert w.mu_max_wheel == pytest.approx(WHEEL_MU[i], abs=5e-4)
        assert w.normal_force == pytest.approx(LOADS[i], abs=5)
        assert w.e2e == "ok"
    assert len(snap.history) == N_UPDATES and snap.history[-1] == pytest.approx(FINAL_MU, abs=1e-4)
    rows = {r.name: r for r in snap.inputs}
    assert rows["WHEEL_SPEEDS"].rate_hz == pytest.approx(100.0, rel=0.03)
    assert rows["WHEEL_SPEEDS"].age_s == pytest.approx(0.005 + 0.004, abs=1e-6)
    assert not rows["WHEEL_SPEEDS"].stale
    assert rows["BRAKE_PRESSURES"].age_s is None and rows["BRAKE_PRESSURES"].stale
    outs = {r.name: r for r in snap.outputs}
    assert outs["FRICTION_WHEEL"].rate_hz == pytest.approx(400.0, rel=0.03)
    assert snap.e2e == {"ok": N_UPDATES * 5, "crc_failures": 0, "counter_jumps": 0, "frames_lost": 0, "repeated": 0}
    assert snap.undecodable_total == 0 and snap.other_frames == 0


def test_model_counts_e2e_faults_undecodable_and_other_frames(default_config):
    inp, out = codecs(default_config)
    frames, _ = known_frames(default_config)
    est_frames = [i for i, f in enumerate(frames) if f.can_id == out.estimate_id]
    bad = list(frames)
    i = est_frames[20]
    bad[i] = bad[i]._replace(data=bytes([bad[i].data[0] ^ 0xFF]) + bad[i].data[1:])   # CRC failure
    del bad[est_frames[40]]                                                             # one lost frame
    bad.append(Frame(T0 + 2.0, 0x0B0, b"\x01\x02"))                                    # input, wrong length
    bad.append(Frame(T0 + 2.0, out.estimate_id, b"\x00"))                              # output, wrong length
    bad.append(Frame(T0 + 2.0, 0x123, b"\x00" * 8))                                     # someone else's
    bad.append(Frame(T0 + 2.0, 0, b"", is_error=True))
    model = MonitorModel(out, inp)
    objs = list(model.feed_all(bad))
    verdicts = [o["e2e"] for o in objs]
    # the frame after the corrupt one, and the one after the missing one, see a counter jump
    assert verdicts.count("crc") == 1 and verdicts.count("jump") == 2
    snap = model.snapshot()
    assert snap.e2e["crc_failures"] == 2  # the corrupt CRC and the short frame
    assert snap.e2e["counter_jumps"] == 2 and snap.e2e["frames_lost"] == 2
    assert snap.undecodable == {"WHEEL_SPEEDS: wrong length": 1, "FRICTION_ESTIMATE: wrong length": 1}
    assert snap.other_frames == 1 and snap.error_frames == 1
    model.reset_counters()
    snap = model.snapshot()
    assert snap.e2e["crc_failures"] == 0 and snap.undecodable_total == 0 and snap.frames_total == 0
    assert snap.estimate is not None and snap.history  # values stay, counters go
    assert {r.name: r for r in snap.inputs}["WHEEL_SPEEDS"].age_s is not None


def test_rate_tracker_falls_to_zero_when_frames_stop():
    tr = RateTracker("X", 1, 0.01)
    for k in range(300):
        tr.seen(k * 0.01)
    assert tr.rate(2.99) == pytest.approx(100, rel=0.02)
    assert tr.rate(10.0) == 0.0
    assert tr.is_stale(10.0) and not tr.is_stale(2.995)


def test_log_player_paces_against_a_wall_clock():
    frames = [Frame(50.0 + 0.1 * k, 1, b"") for k in range(11)]   # 1 s of log
    player = LogPlayer(frames, speed=4.0)
    assert len(player.due_frames(10.0)) == 1                      # the first is due at once
    assert len(player.due_frames(10.11)) == 4                     # 0.11 s wall = 0.44 s log
    player.pause(10.11)
    assert player.due_frames(20.0) == []
    player.resume(20.0)                                           # 9.89 s paused
    assert len(player.due_frames(20.0)) == 0                      # log time stood still
    assert len(player.due_frames(20.2)) == 6
    assert player.seconds_to_next(20.2) is None and player.finished
    fast = LogPlayer(frames, speed=0)
    assert len(fast.due_frames(0.0)) == 11


def test_frame_clock_extrapolates_in_the_frames_time_base():
    clock = FrameClock(speed=2.0)
    assert clock.now(5.0) is None
    clock.observe(1000.0, 5.0)
    assert clock.now(5.5) == pytest.approx(1001.0)
    clock.frozen = True
    assert clock.now(9.0) == 1000.0


class FakeWall:
    def __init__(self) -> None:
        self.t = 0.0

    def monotonic(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.t += s


def test_log_source_finishes_and_freezes_its_clock(default_config):
    frames, _ = known_frames(default_config)
    source = LogSource(frames, speed=0, description="log x")
    wall = FakeWall()
    got = []
    while not source.finished:
        got += source.poll(0.05, wall)
    assert len(got) == len(frames)
    assert source.now(wall.t + 100) == frames[-1].time_s


# ------------------------------------------------------------------------------------ render
def _text(lines) -> str:
    return "\n".join("".join(t for t, _ in line) for line in lines)


def test_render_shows_the_values_and_fits_any_size(default_config):
    inp, out = codecs(default_config)
    frames, _ = known_frames(default_config)
    model = MonitorModel(out, inp)
    for f in frames:
        model.feed(f)
    snap = model.snapshot(source="log known.log")
    text = _text(render(snap, 100, 30, unicode=False))
    assert "MuMax 0.812" in text and "VALID" in text and "confidence 0.90" in text
    assert "slip at peak 0.125" in text and "FL       0.0500" in text and "WHEEL_SPEEDS" in text
    assert "CRC failures 0" in text and "undecodable 0" in text
    assert "#" in text  # big digits
    for width, height in ((20, 5), (1, 1), (0, 0), (300, 3), (40, 80)):
        lines = render(snap, width, height, paused=True)
        assert len(lines) <= max(height, 0)
    small = _text(render(snap, 80, 12))
    assert "MuMax 0.812" in small and "VALID" in small


def test_render_without_frames_says_what_it_waits_for(default_config):
    _, out = codecs(default_config)
    snap = MonitorModel(out).snapshot(source="socketcan vcan0")
    assert "waiting for frames on vcan0" in _text(render(snap, 80, 24, waiting_on="vcan0"))


def test_big_digits_and_sparkline():
    rows = big_text("0.81", unicode=False)
    assert len(rows) == 5 and rows[0].startswith("###")
    assert sparkline([0.0, 0.5, 1.0], 10, 0.0, 1.0, unicode=True) == "▁▅█"
    assert sparkline([1.0] * 50, 8, 0.0, 1.0) == "█" * 8
    assert sparkline([], 8, 0, 1) == ""


# -------------------------------------------------------------------------------------- json
def _monitor_cmd(*args: str) -> list[str]:
    return [sys.executable, "-m", "frictiond.cli.monitor", *args]


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def test_json_lines_match_the_frames(known_log):
    path, estimates = known_log
    proc = subprocess.run(_monitor_cmd("--log", str(path), "--speed", "0", "--json"), capture_output=True,
                          text=True, timeout=60, cwd=REPO, env=_env())
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    objs = [json.loads(line) for line in proc.stdout.splitlines()]
    assert len(objs) == len(estimates)
    for obj, est in zip(objs, estimates):
        assert obj["time_s"] == pytest.approx(est.time_s + 0.004, abs=1e-6)
        assert obj["status"] == est.status.name
        assert obj["MuMax"] == pytest.approx(est.mu_max, abs=1e-4)
        assert obj["Confidence"] == pytest.approx(est.confidence, abs=0.005)
        assert obj["SlipAtMuMax"] == pytest.approx(est.slip_at_mu_max, abs=1e-3)
        assert obj["e2e"] == "ok"
        for i, w in enumerate(("FL", "FR", "RL", "RR")):
            wheel = obj["wheels"][w]
            assert wheel["time_s"] == obj["time_s"]   # the wheel frames of the same update
            assert wheel["Slip"] == pytest.approx(SLIPS[i], abs=5e-4)
            assert wheel["MuUsed"] == pytest.approx(MU_USED[i], abs=1e-3)
            assert wheel["MuMaxWheel"] == pytest.approx(WHEEL_MU[i], abs=5e-4)
            assert wheel["NormalForce"] == pytest.approx(LOADS[i], abs=5)


def test_json_stops_quietly_on_a_closed_pipe(known_log):
    path, _ = known_log
    proc = subprocess.Popen(_monitor_cmd("--log", str(path), "--json"), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, cwd=REPO, env=_env())
    first = proc.stdout.readline()
    assert json.loads(first)["status"] == "INIT"
    proc.stdout.close()                       # like `| head -1`
    rc = proc.wait(timeout=30)
    err = proc.stderr.read().decode()
    proc.stderr.close()
    assert rc == 0 and err == ""


def test_monitor_refuses_a_screen_without_a_terminal_and_bad_options(known_log):
    path, _ = known_log
    proc = subprocess.run(_monitor_cmd("--log", str(path)), capture_output=True, text=True, timeout=60,
                          cwd=REPO, env=_env(), stdin=subprocess.DEVNULL)
    assert proc.returncode == 2 and "--json" in proc.stderr
    proc = subprocess.run(_monitor_cmd("--log", str(path), "--channel", "vcan0", "--json"), capture_output=True,
                          text=True, timeout=60, cwd=REPO, env=_env())
    assert proc.returncode == 2
    proc = subprocess.run(_monitor_cmd("--log", str(path) + ".missing.log", "--json"), capture_output=True,
                          text=True, timeout=60, cwd=REPO, env=_env())
    assert proc.returncode == 66


# -------------------------------------------------------------------------------- under tmux
needs_tmux = pytest.mark.skipif(shutil.which("tmux") is None, reason="tmux not installed")


class Tmux:
    """One private tmux server (its own socket) running one command in a pseudo-terminal."""

    def __init__(self, tmp_path: Path, command: list[str], width: int, height: int) -> None:
        self.socket = f"frictiond-test-{uuid.uuid4().hex[:10]}"
        self.rc_file = tmp_path / f"{self.socket}.rc"
        self.err_file = tmp_path / f"{self.socket}.err"
        inner = " ".join(_quote(c) for c in command)
        shell = f"{inner} 2>{_quote(str(self.err_file))}; echo $? > {_quote(str(self.rc_file))}; sleep 60"
        env = " ".join(f"{k}={_quote(v)}" for k, v in (("PYTHONPATH", str(REPO)), ("LANG", "C.UTF-8")))
        self._tmux("new-session", "-d", "-s", "m", "-x", str(width), "-y", str(height),
                   f"cd {_quote(str(REPO))} && env {env} sh -c {_quote(shell)}")

    def _tmux(self, *args: str) -> str:
        env = dict(os.environ, LANG="C.UTF-8")
        return subprocess.run(["tmux", "-L", self.socket, "-f", os.devnull, *args], capture_output=True,
                              text=True, timeout=20, check=True, env=env).stdout

    def capture(self) -> str:
        return self._tmux("capture-pane", "-p", "-t", "m")

    def wait_for(self, text: str, timeout: float = 20.0) -> str:
        deadline = time.monotonic() + timeout
        screen = ""
        while time.monotonic() < deadline:
            screen = self.capture()
            if text in screen:
                return screen
            if self.rc_file.exists():
                break
            time.sleep(0.1)
        raise AssertionError(f"{text!r} not on screen:\n{screen}\nstderr: {self.stderr()}")

    def keys(self, *keys: str) -> None:
        self._tmux("send-keys", "-t", "m", *keys)

    def resize(self, width: int, height: int) -> None:
        self._tmux("resize-window", "-t", "m", "-x", str(width), "-y", str(height))

    def exit_code(self, timeout: float = 20.0) -> int:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.rc_file.exists() and self.rc_file.read_text().strip():
                return int(self.rc_file.read_text())
            time.sleep(0.1)
        raise AssertionError(f"monitor did not exit:\n{self.capture()}")

    def stderr(self) -> str:
        return self.err_file.read_text() if self.err_file.exists() else ""

    def close(self) -> None:
        try:
            socket_path = self._tmux("display-message", "-p", "#{socket_path}").strip()
        except subprocess.SubprocessError:
            socket_path = ""
        subprocess.run(["tmux", "-L", self.socket, "kill-server"], capture_output=True, timeout=20)
        if socket_path and Path(socket_path).name == self.socket:
            Path(socket_path).unlink(missing_ok=True)


def _quote(s: str) -> str:
    return "'" + s.replace("'", "'\\''") + "'"


@pytest.fixture
def tmux_session(tmp_path):
    sessions = []

    def start(command: list[str], width: int, height: int) -> Tmux:
        session = Tmux(tmp_path, command, width, height)
        sessions.append(session)
        return session

    yield start
    for s in sessions:
        s.close()


@needs_tmux
def test_screen_in_a_real_terminal_shows_the_known_log(known_log, tmux_session):
    path, _ = known_log
    term = tmux_session(_monitor_cmd("--log", str(path), "--speed", "0"), 100, 30)
    term.wait_for("END OF LOG")
    # Each fragment waited for in turn: a capture can land in the middle of a redraw.
    for fragment in ("MuMax 0.812", "VALID", "confidence 0.90", "slip at peak 0.125",
                     "FL       0.0500    0.400      0.8100       4000 N  ok", "WHEEL_SPEEDS", "100.0 Hz",
                     "CRC failures 0"):
        term.wait_for(fragment)
    term.keys("p")
    term.wait_for("PAUSED")
    term.keys("r")
    term.wait_for("E2E ok 0   CRC failures 0")
    term.keys("q")
    assert term.exit_code() == 0
    assert term.stderr() == ""


@needs_tmux
def test_screen_copes_with_a_tiny_and_resized_terminal(known_log, tmux_session):
    path, _ = known_log
    term = tmux_session(_monitor_cmd("--log", str(path), "--speed", "2"), 20, 5)
    term.wait_for("MuMax 0.812")
    term.resize(12, 3)
    time.sleep(0.3)
    term.resize(90, 14)
    term.wait_for("END OF LOG")
    term.resize(20, 5)
    time.sleep(0.3)
    term.keys("q")
    assert term.exit_code() == 0
    assert term.stderr() == ""


@needs_tmux
def test_screen_without_frames_says_it_is_waiting(tmux_session):
    term = tmux_session(_monitor_cmd("--interface", "virtual", "--channel", "vcan0"), 80, 24)
    term.wait_for("waiting for frames on vcan0")
    term.keys("q")
    assert term.exit_code() == 0


def test_bus_source_feeds_the_model_from_a_virtual_bus(default_config):
    from frictiond.busio import frame_to_message, message_to_frame, open_bus
    from frictiond.monitor import BusSource

    inp, out = codecs(default_config)
    frames, _ = known_frames(default_config)
    channel = f"monitor-test-{uuid.uuid4().hex[:8]}"
    listener = open_bus("virtual", channel, None, preserve_timestamps=True)
    sender = open_bus("virtual", channel, None, preserve_timestamps=True)
    try:
        source = BusSource(listener, message_to_frame, description=f"virtual {channel}")
        model = MonitorModel(out, inp)
        for f in frames:
            sender.send(frame_to_message(f))
        got = []
        deadline = time.monotonic() + 10
        while len(got) < len(frames) and time.monotonic() < deadline:
            got += source.poll(0.05, time)
        objs = [o for o in (model.feed(f) for f in got) if o is not None]
    finally:
        sender.shutdown()
        listener.shutdown()
    assert len(got) == len(frames)
    assert len(objs) == N_UPDATES and objs[-1]["status"] == "VALID"
    assert objs[-1]["MuMax"] == pytest.approx(FINAL_MU, abs=1e-4)
    assert source.now(time.monotonic()) >= frames[-1].time_s
