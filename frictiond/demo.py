"""The built-in demo: simulator → virtual bus → live loop → virtual bus → decoded display."""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Any, TextIO

from .busio import frame_to_message, message_to_frame, open_bus
from .codec import OutputCodec, load_databases
from .config import Config
from .loop import serve
from .pipeline import Pipeline
from .sim_frames import simulate_frames


@dataclass
class DemoResult:
    scenario: str
    final_status: str
    mu_max: float
    truth_mu_max: float


@dataclass
class _Listener:
    """The demo's view of the estimate frames on the virtual channel: the newest one decoded."""

    bus: Any
    codec: OutputCodec
    last: dict[str, Any] | None = None

    def drain(self, timeout: float = 0.0) -> dict[str, Any] | None:
        """Read every estimate frame waiting (each wait up to `timeout`); the newest decoded one."""
        while (msg := self.bus.recv(timeout=timeout)) is not None:
            decoded = self.codec.decode_output(message_to_frame(msg))
            if decoded is not None:
                self.last = decoded
        return self.last


def run_demo(
    config: Config,
    scenarios: list[str],
    *,
    pace: float = 4.0,
    seed: int = 0,
    channel: str = "frictiond-demo",
    out: TextIO | None = None,
) -> list[DemoResult]:
    pipeline = Pipeline(config)
    daemon_bus = open_bus("virtual", channel, pipeline.input_codec.input_ids, preserve_timestamps=True)
    vehicle_bus = open_bus("virtual", channel, None, preserve_timestamps=True)
    listener_bus = open_bus("virtual", channel, [pipeline.output_codec.estimate_id], preserve_timestamps=True)
    listener = _Listener(listener_bus, OutputCodec(load_databases([config.can.output_dbc], strict=True)))
    stop = threading.Event()
    loop = threading.Thread(target=serve, args=(daemon_bus, pipeline, stop), name="frictiond-loop", daemon=True)
    loop.start()
    results = []
    try:
        t0 = time.time()
        for k, name in enumerate(scenarios):
            frames, sim = simulate_frames(config, name, seed=seed + k)
            if out:
                print(f"\n== {name}: {sim.scenario.description}", file=out)
                print(f"{'t [s]':>6s} {'v [m/s]':>7s} {'status':12s} {'MuMax':>6s} {'conf':>5s} {'truth':>6s}", file=out)
            _play(frames, sim.truth, vehicle_bus, listener, pace, t0 + k * 100.0, out)
            time.sleep(0.2)
            last_decoded = listener.drain(timeout=0.05)
            truth = sim.truth
            end_truth = truth.at(truth.time_s[-1] if hasattr(truth, "time_s") else 1e9)
            if last_decoded is not None:
                results.append(
                    DemoResult(name, str(last_decoded["EstimatorStatus"]), float(last_decoded["MuMax"]),
                               float(end_truth["mu_max"]))
                )
    finally:
        stop.set()
        loop.join(timeout=2.0)
        for bus in (daemon_bus, vehicle_bus, listener_bus):
            bus.shutdown()
    return results


def _play(frames: list[Any], truth: Any, vehicle_bus: Any, listener: _Listener, pace: float, t_start: float,
          out: TextIO | None) -> None:
    """Send one scenario's frames at `pace` × real time, stamped from `t_start`, printing the
    newest estimate beside the truth every 0.25 s of the scenario."""
    base = frames[0].time_s
    start_wall = time.time()
    last_print = -1.0
    for frame in frames:
        sim_t = frame.time_s - base
        delay = start_wall + sim_t / pace - time.time()
        if delay > 0:
            time.sleep(delay)
        vehicle_bus.send(frame_to_message(frame._replace(time_s=t_start + sim_t)))
        last_decoded = listener.drain()
        if last_decoded is not None and sim_t - last_print >= 0.25 and out:
            last_print = sim_t
            row = truth.at(sim_t)
            print(
                f"{sim_t:6.2f} {row['speed_mps']:7.2f} {last_decoded['EstimatorStatus']:12s} "
                f"{last_decoded['MuMax']:6.3f} {last_decoded['Confidence']:5.2f} {row['mu_max']:6.3f}",
                file=out,
                flush=True,
            )
