"""frictiond over real SocketCAN: canplayer in, candump out, cangen flood, link down/up, stale input.

One harness run (tests/vcan/harness.py) does all live scenarios: on the host's vcan0 if there is
one, else in a user-mode Linux guest. The verdicts are drawn here, on the host, against
`frictiond replay` of the same logs. Set FRICTIOND_VCAN_RESULTS=DIR to re-check a finished run.
"""
from __future__ import annotations

import bisect
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

from frictiond.busio import LogWriter, read_log
from frictiond.codec import output_codec_for
from frictiond.config import default_config_path, load_config
from frictiond.daemon import RateGuard

from .vcan import harness

pytestmark = pytest.mark.vcan

ESTIMATE_ID, TRIGGER_ID, PRESSURE_ID = 0x3E0, 0xB0, 0xD0
INPUT_IDS = {0xB0, 0xC0, 0xD0, 0xE0, 0xF0}
PERIOD_S = 0.01
MU_TOL = 0.01


@pytest.fixture(scope="module")
def vcan(tmp_path_factory):
    reuse = os.environ.get("FRICTIOND_VCAN_RESULTS")
    if reuse:
        out = Path(reuse)
        results = json.loads((out / "results.json").read_text())
        results["out"] = str(out)
    else:
        out = tmp_path_factory.mktemp("vcan")
        results = harness.run_suite(out)
    print(f"\nvcan suite: {results.get('mode', 'reused')}, {results.get('elapsed_s', 0):.1f} s, "
          f"inputs {results.get('prepared', {})}")
    return out, results


@pytest.fixture(scope="module")
def codec():
    return output_codec_for([default_config_path().parent / "frictiond.dbc"])


def scenario(vcan, name):
    out, results = vcan
    s = results["scenarios"][name]
    assert "error" not in s, s["error"]
    return out, s


def frictiond_replay(out: Path, log: Path, config: str = "frictiond.yaml") -> list:
    """`frictiond replay LOG --output ...` (the CLI itself), its output frames."""
    target = out / f"{log.stem}.replayed.log"
    proc = subprocess.run(
        [sys.executable, "-m", "frictiond.cli.main", "replay", str(log), "--config", str(out / config),
         "--output", str(target), "--quiet"],
        capture_output=True, text=True, timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    return list(read_log(target))


def estimates(codec, frames):
    """(time, status, MuMax) of the FRICTION_ESTIMATE frames, E2E checked."""
    out = []
    for f in frames:
        if f.can_id == ESTIMATE_ID:
            d = codec.decode_output(f)
            assert d["e2e"] in ("ok", "repeated", "jump"), d
            out.append((round(f.time_s, 6), d["EstimatorStatus"], d["MuMax"]))
    return out


def trigger_caused(est_log_estimates, capture, replay_answered=None):
    """The daemon's estimates caused by a trigger frame (not by its stale-input tick).

    The estimate log carries the trigger's socket time, which the daemon reads on candump's
    microsecond grid: the same number as candump's (2 µs of slack for a peer logging otherwise).
    A tick while frames are still queued is stamped with the last frame's time (`frame_now`):
    when that frame is a trigger the replay gives no output for (after a stall, the gate reads
    the gap as a clock step), an INPUT_STALE there is the tick's, which the replay has no loop for.
    """
    trigger_times = sorted(f.time_s for f in capture if f.can_id == TRIGGER_ID)
    caused, ticks = [], []
    for t, status, mu in est_log_estimates:
        i = bisect.bisect_left(trigger_times, t - 2e-6)
        at_trigger = i < len(trigger_times) and abs(trigger_times[i] - t) <= 2e-6
        if at_trigger and not (replay_answered is not None and status == "INPUT_STALE"
                               and round(trigger_times[i], 6) not in replay_answered):
            caused.append((round(trigger_times[i], 6), status, mu))
        else:
            ticks.append((t, status, mu))
    return caused, ticks


def compressed(statuses):
    seq = []
    for s in statuses:
        if not seq or seq[-1] != s:
            seq.append(s)
    return seq


def stale_gaps(frames, periods: float = 3.0) -> set:
    """(ID, index of the gap) where a message's interval exceeds the daemon's stale limit: three
    of its median periods."""
    times: dict[int, list[float]] = {}
    for f in frames:
        times.setdefault(f.can_id, []).append(f.time_s)
    gaps = set()
    for can_id, ts in times.items():
        intervals = [b - a for a, b in zip(ts, ts[1:])]
        if not intervals:
            continue
        limit = periods * sorted(intervals)[len(intervals) // 2]
        gaps |= {(can_id, i) for i, d in enumerate(intervals) if d > limit}
    return gaps


def wheel_speed_bursts(frames) -> int:
    """Wheel-speed frames that came less than a quarter period after the previous one: a sender
    catching up after a stall, which the front end refuses as a second sender's frames."""
    ts = [f.time_s for f in frames if f.can_id == TRIGGER_ID]
    return sum(1 for a, b in zip(ts, ts[1:]) if b - a < PERIOD_S / 4)


def past_rate_guard(out: Path, name: str) -> tuple[Path, int]:
    """The capture as the daemon's trigger rate guard let it through (`RateGuard` at the config's
    `max_update_rate`, on the frames' bus times): a log of the frames the daemon processed, and
    how many trigger frames the guard dropped."""
    guard = RateGuard(load_config(out / "frictiond.yaml").daemon.max_update_rate)
    frames = list(read_log(out / f"{name}-capture.log"))
    kept = [f for f in frames if f.can_id != TRIGGER_ID or f.is_extended or f.is_remote or guard.allow(f.time_s)]
    path = out / f"{name}-processed.log"
    with LogWriter(path) as writer:
        writer.write_all(kept)
    return path, len(frames) - len(kept)


def check_live_equals_replay(out: Path, name: str, codec, original: Path, against_log: bool = True,
                             config: str = "frictiond.yaml") -> dict:
    full_capture = list(read_log(out / f"{name}-capture.log"))
    # (replayed: the frames the daemon processed, which are all of them unless canplayer, after a
    # stall, sent more wheel-speed frames back to back than the rate guard lets through)
    processed, _ = past_rate_guard(out, name)
    capture = list(read_log(processed))
    live = estimates(codec, read_log(out / f"{name}-est.log"))
    from_capture = estimates(codec, frictiond_replay(out, processed, config))
    caused, ticks = trigger_caused(live, capture, {t for t, _, _ in from_capture})
    inputs_seen = [f for f in full_capture if f.can_id in INPUT_IDS]
    played = [f for f in read_log(original) if f.can_id in INPUT_IDS]
    assert len(inputs_seen) == len(played), "candump missed input frames"
    # every frame the daemon sent is on the bus
    on_bus = [f for f in full_capture if f.can_id == ESTIMATE_ID]
    assert len(on_bus) == len(live)
    # 1. the frames as they were on the bus (candump) through `frictiond replay`: the same status and
    # MuMax for every update, as the daemon reads frame times on candump's microsecond grid. Unless
    # the live loop ticked inside an input gap: it said INPUT_STALE before the next frame came, which
    # the replay, having no loop, does not, and the updates while the filter warms up after the gap
    # then repeat different statuses.
    assert [t for t, _, _ in caused] == [t for t, _, _ in from_capture]      # one estimate per trigger
    agree_capture = sum(a[1] == b[1] for a, b in zip(caused, from_capture)) / len(caused)
    identical = sum(a[1:] == b[1:] for a, b in zip(caused, from_capture)) / len(caused)
    gap_ticks = [t for t, _, _ in ticks if caused[0][0] < t < caused[-1][0]]
    assert identical == 1.0 or (gap_ticks and agree_capture >= 0.98), (identical, agree_capture, gap_ticks)
    assert compressed(s for _, s, _ in caused)[:3] == compressed(s for _, s, _ in from_capture)[:3]
    # (no VALID at all when canplayer's bursts were refused throughout; check 2 then does not apply)
    worst_capture = max((abs(a[2] - b[2]) for a, b in zip(caused, from_capture) if a[1] == b[1] == "VALID"),
                        default=math.nan)
    assert not worst_capture > MU_TOL, worst_capture
    # 2. the played log through `frictiond replay` (the log's own timestamps). canplayer reproduces
    # the timing only to a few milliseconds in the slow guest (over 10 ms with a flood hogging its
    # one CPU), and the estimator's transient depends on the timestamps: statuses mostly agree, the
    # final estimate agrees within tolerance; the per-update differences are reported.
    from_log = estimates(codec, frictiond_replay(out, original, config))
    # (Under the flood canplayer, starved of the guest's CPU, also sends some wheel-speed frames in
    # bursts 50 µs apart, which the front end skips as a gateway's repeats: a few updates fewer than
    # the log gives, the same as `frictiond replay` of the capture, which check 1 compares.)
    agree = sum(a[1] == b[1] for a, b in zip(caused, from_log)) / len(from_log)
    settled = int(1.0 / PERIOD_S)
    worst_settled = max(abs(a[2] - b[2]) for a, b in zip(caused[-settled:], from_log[-settled:]))
    worst = max((abs(a[2] - b[2]) for a, b in zip(caused, from_log) if a[1] == b[1] == "VALID"), default=math.nan)
    # canplayer in the guest sometimes stalls for longer than the daemon's stale limit (seen at the
    # start of a CI run): then the bus carried an input gap the log does not have, the daemon rightly
    # said INPUT_STALE, and check 1 is the comparison that applies; this one is reported. The same
    # when it caught up after a stall by sending wheel-speed frames back to back (seen in CI too).
    playback_gaps = stale_gaps(inputs_seen) - stale_gaps(played)
    if playback_gaps:
        assert "INPUT_STALE" in (s for _, s, _ in caused + ticks)
    playback_bursts = wheel_speed_bursts(inputs_seen) - wheel_speed_bursts(played)
    # ... and when the frames as they were on the bus, replayed, went INPUT_STALE where the log
    # does not: canplayer catching up sent frames of a message 3-5 ms apart (seen in CI), the
    # input gate refused some as a second source's, and the frames it kept left a gap past the
    # stale limit, though no interval on the bus passes the one above.
    stale_on_bus = "INPUT_STALE" in {s for _, s, _ in from_capture} - {s for _, s, _ in from_log}
    if against_log and not playback_gaps and not playback_bursts and not stale_on_bus:
        assert len(caused) == len(from_log)
        assert not math.isnan(worst_capture)
        assert caused[-1][1] == "VALID"
        assert agree >= 0.9, agree
        assert compressed(s for _, s, _ in caused)[:3] == compressed(s for _, s, _ in from_log)[:3]
        assert from_log[-1][1] == "VALID"
        assert abs(caused[-1][2] - from_log[-1][2]) <= MU_TOL
    capture_inputs = [f.time_s for f in capture if f.can_id == TRIGGER_ID]
    log_inputs = [f.time_s for f in played if f.can_id == TRIGGER_ID]
    jitter = max(abs((a - capture_inputs[0]) - (b - log_inputs[0])) for a, b in zip(capture_inputs, log_inputs))
    assert all(s == "INPUT_STALE" for _, s, _ in ticks)
    return {"updates": len(caused), "ticks": len(ticks), "ticks_in_input_gaps": len(gap_ticks),
            "status_agreement_vs_capture": round(agree_capture, 4),
            "max_valid_mu_diff_vs_capture": round(worst_capture, 4), "status_agreement_vs_log": round(agree, 4),
            "max_valid_mu_diff_vs_log": round(worst, 4), "max_settled_mu_diff_vs_log": round(worst_settled, 4),
            "max_playback_timing_error_s": round(jitter, 4), "playback_gaps_not_in_log": sorted(playback_gaps),
            "playback_bursts_not_in_log": playback_bursts, "stale_on_bus_not_in_log": stale_on_bus,
            "final": caused[-1], "final_replay_of_log": from_log[-1]}


def test_live_estimates_equal_frictiond_replay(vcan, codec):
    out, s = scenario(vcan, "replay")
    assert s["rc"] == 0
    assert s["notify"][0].startswith("READY=1") and s["notify"][-1].startswith("STOPPING=1")
    report = check_live_equals_replay(out, "replay", codec, out / "braking.log")
    print("replay:", report)


def test_flood_on_other_ids_does_not_change_the_estimate(vcan, codec):
    out, s = scenario(vcan, "flood")
    assert s["rc"] == 0
    played_inputs = sum(1 for f in read_log(out / "braking.log") if f.can_id in INPUT_IDS)
    flood_frames = s["link_after"]["tx_packets"] - s["link_before"]["tx_packets"] - played_inputs
    # Several times the input traffic (over 5x on an idle host; the nice-19 flood gets less CPU on a busy one).
    assert flood_frames >= 2 * played_inputs, flood_frames
    err = (out / "flood-daemon.err").read_text()
    assert f"stopped: {played_inputs} frames in," in err       # exactly the inputs: the kernel filtered the flood
    # The flood takes the guest's one CPU from canplayer, whose timing then drifts from the log by
    # tens of ms, and after a stall (0.29 s seen in CI) it sends the wheel-speed frames it owes
    # back to back: past the rate guard's burst those are dropped, as a flood on the trigger ID
    # would be. The daemon drops exactly what its guard does on the bus's own times of the inputs,
    # and nothing for the flood on another ID.
    _, dropped = past_rate_guard(out, "flood")
    assert f" {dropped} flood dropped," in err
    # frictiond under the flood equals `frictiond replay` of what it processed off the bus (check 1
    # inside); the inputs themselves differ from the log, so that comparison is only reported.
    report = check_live_equals_replay(out, "flood", codec, out / "braking.log", against_log=False)
    print("flood:", flood_frames, "frames of ID 0x123;", dropped, "bursting wheel-speed frames dropped;", report)


def test_link_down_and_up_mid_run_frictiond_survives_and_resumes(vcan, codec):
    out, s = scenario(vcan, "linkdown")
    assert s["alive_while_down"] and s["alive_after"] and s["rc"] == 0
    err = (out / "linkdown-daemon.err").read_text().splitlines()
    assert len([l for l in err if "retrying with backoff" in l]) == 1     # logged once
    assert len([l for l in err if "is back; resuming" in l]) == 1
    after = [f for f in read_log(out / "linkdown-capture.log") if f.time_s > s["up_at"]]
    sent_after = [f for f in after if f.can_id == ESTIMATE_ID]
    triggers_after = [f for f in after if f.can_id == TRIGGER_ID]
    assert triggers_after and len(sent_after) >= len(triggers_after)      # one estimate per trigger
    assert all(codec.decode_output(f)["e2e"] in ("ok", "repeated", "jump") for f in sent_after)


def test_stopping_an_input_yields_input_stale_within_three_periods(vcan, codec):
    out, s = scenario(vcan, "stale")
    assert s["rc"] == 0
    capture = list(read_log(out / "stale-capture.log"))
    live = estimates(codec, read_log(out / "stale-est.log"))
    last_pressure = max(f.time_s for f in capture if f.can_id == PRESSURE_ID)
    after = [e for e in live if e[0] > last_pressure + 1e-6]
    first_stale = next(e for e in after if e[1] == "INPUT_STALE")
    assert first_stale[0] - last_pressure <= 3 * PERIOD_S + PERIOD_S + 2e-3   # stale after 3 periods, at the next trigger
    assert all(e[1] == "INPUT_STALE" for e in after if e[0] >= first_stale[0])
    # then the trigger itself stops (end of the log): the loop's tick reports it
    last_trigger = max(f.time_s for f in capture if f.can_id == TRIGGER_ID)
    ticks = [e for e in live if e[0] > last_trigger + 1e-6]
    assert ticks and ticks[0][1] == "INPUT_STALE"
    assert ticks[0][0] - last_trigger <= 3 * PERIOD_S + 0.03, ticks[0][0] - last_trigger
    print(f"stale: pressure stop -> INPUT_STALE after {first_stale[0] - last_pressure:.3f} s, "
          f"trigger stop -> tick INPUT_STALE after {ticks[0][0] - last_trigger:.3f} s")


def test_can_fd_and_29_bit_inputs_live_equal_frictiond_replay(vcan, codec):
    """Wheel speeds as 16-byte CAN FD frames and accelerations on a 29-bit ID: the daemon opens its
    socket for FD and filters the 29-bit ID (else it would receive none of either) and gives what
    `frictiond replay` gives."""
    out, s = scenario(vcan, "fd")
    if "skipped" in s:
        pytest.skip(s["skipped"])
    assert s["rc"] == 0
    capture = list(read_log(out / "fd-capture.log"))
    triggers = [f for f in capture if f.can_id == TRIGGER_ID]
    assert triggers and all(len(f.data) == 16 for f in triggers)      # FD frames were on the bus
    assert all(f.is_extended for f in capture if f.can_id == 0xC0)   # ... and 29-bit ones
    report = check_live_equals_replay(out, "fd", codec, out / "fd.log", config="fd.yaml")
    assert report["updates"] >= 0.95 * len(triggers)
    print("fd:", report)


def test_rear_wheel_speeds_apart_live_equal_frictiond_replay(vcan, codec):
    """The rear wheel speeds in a message of their own, at their own phase: each update waits for
    the rear message's next frame and is sent then. Live, the daemon sends what `frictiond replay`
    of the capture sends, at the same frame times; the loop's INPUT_STALE ticks apart."""
    out, s = scenario(vcan, "split")
    assert s["rc"] == 0
    capture = out / "split-capture.log"
    frames = list(read_log(capture))
    triggers = [f.time_s for f in frames if f.can_id == TRIGGER_ID]
    rears = [f.time_s for f in frames if f.can_id == 0xB1]
    assert triggers and abs(len(rears) - len(triggers)) <= 0.02 * len(triggers) and not set(rears) & set(triggers)
    live = estimates(codec, read_log(out / "split-est.log"))
    replayed = estimates(codec, frictiond_replay(out, capture, "split.yaml"))
    ticks = [e for e in live if e[1] == "INPUT_STALE" and e not in replayed]
    assert [e for e in live if e not in ticks] == replayed
    assert len(replayed) >= len(triggers) - 3 and replayed[-1][1] == "VALID"
    # (each update comes with the rear frame that completed it, not with its wheel-speed frame)
    assert {t for t, _, _ in replayed} <= {round(t, 6) for t in rears}
    print("split:", len(replayed), "updates,", len(ticks), "ticks; final", replayed[-1])


def test_suite_stays_within_its_time_budget(vcan):
    _, results = vcan
    if "elapsed_s" in results:
        assert results["elapsed_s"] < 300
