"""`frictiond run`: the live loop on a CAN bus, as a systemd `Type=notify` service.

One thread owns everything: it receives with a short timeout (python-can's Notifier is avoided on
purpose: it spins on a lasting error), feeds the pipeline, sends the output frames at once with
`send(timeout=0)` (a full transmit queue drops and counts, it never blocks the estimator), and in
between does the housekeeping: stale-input ticks, sd_notify STATUS/WATCHDOG, periodic state
saves, estimate-log flushes, and the bus reconnect with exponential backoff.

Signals only set flags: SIGTERM/SIGINT stop cleanly (state written, `STOPPING=1`, exit 0),
SIGHUP reloads the config (an invalid new config is reported in one line and the old one kept).

`Daemon` is assembled from parts in their own modules: `daemon_bus` (the bus), `daemon_reload`
(the state file, the estimate log, the reload) and `daemon_status` (the status line).
"""
from __future__ import annotations

import dataclasses
import gc
import logging
import math
import signal
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import can

from .busio import open_bus
from .config import Config
from .daemon_bus import FIRST_BACKOFF_S, DaemonBus
from .daemon_bus import StartupError  # noqa: F401 (re-exported: `cli.run` catches it from here)
from .daemon_reload import DaemonReload
from .daemon_status import DaemonStatus
from .estimate_log import EstimateLog
from .pipeline import Pipeline
from .sdnotify import SdNotifier
from .state import StateFile

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Overrides:
    """Command-line settings that win over the config file, also across reloads."""

    interface: str | None = None
    channel: str | None = None
    state_file: Path | None = None
    estimate_log: Path | None = None

    def apply(self, config: Config) -> Config:
        can_cfg = config.can
        if self.interface or self.channel:
            can_cfg = dataclasses.replace(
                can_cfg, interface=self.interface or can_cfg.interface, channel=self.channel or can_cfg.channel
            )
        daemon_cfg = config.daemon
        if self.state_file is not None:
            daemon_cfg = dataclasses.replace(daemon_cfg, state_file=self.state_file)
        output_cfg = config.output
        if self.estimate_log is not None:
            output_cfg = dataclasses.replace(output_cfg, estimate_log=self.estimate_log)
        return dataclasses.replace(config, can=can_cfg, daemon=daemon_cfg, output=output_cfg)


class RateGuard:
    """Token bucket on frame time: at most `rate_hz` sustained, short bursts of `burst` allowed.

    Frame time may jump (NTP steps, spliced logs): a backwards step refills nothing, a forward
    jump refills at most `burst`.
    """

    def __init__(self, rate_hz: float, burst: float | None = None) -> None:
        self.rate_hz = float(rate_hz)
        self.burst = float(burst) if burst is not None else max(2.0, 0.05 * self.rate_hz)
        self.tokens = self.burst
        self._last: float | None = None
        self.dropped = 0

    def allow(self, time_s: float) -> bool:
        last = self._last
        self._last = time_s
        if last is not None and time_s > last:
            self.tokens = min(self.burst, self.tokens + (time_s - last) * self.rate_hz)
        if self.tokens >= 1.0:
            self.tokens -= 1.0
            return True
        self.dropped += 1
        return False


@dataclass
class DaemonStats:
    rx_frames: int = 0            # data frames received (error frames not included)
    tx_frames: int = 0
    tx_dropped: int = 0           # transmit queue full (or bus down) when sending
    flood_dropped: int = 0        # trigger frames beyond max_update_rate, never given to the estimator
    internal_errors: int = 0
    bus_failures: int = 0         # times the bus went away
    bus_opens: int = 0
    bus_off_events: int = 0
    error_frames: int = 0
    reloads: int = 0
    reload_failures: int = 0
    error_classes: dict[int, int] = field(default_factory=dict)


class Daemon(DaemonBus, DaemonReload, DaemonStatus):
    """The live loop. `run()` blocks until `request_stop()` (or SIGTERM/SIGINT) and returns 0."""

    def __init__(
        self,
        config: Config,
        *,
        config_path: Path | None = None,
        overrides: Overrides = Overrides(),
        notifier: SdNotifier | None = None,
        bus_factory: Callable[..., Any] = open_bus,
        config_loader: Callable[[Path | None], Config] | None = None,
        clock: Callable[[], float] = time.time,
        monotonic: Callable[[], float] = time.monotonic,
        install_signals: bool = True,
    ) -> None:
        self.overrides = overrides
        self.config = overrides.apply(config)
        self.config_path = config_path
        self.notifier = notifier if notifier is not None else SdNotifier()
        self._bus_factory = bus_factory
        self._config_loader = config_loader or _load_and_validate
        self._clock = clock
        self._mono = monotonic
        self._install_signals = install_signals
        self.stats = DaemonStats()
        self.pipeline = Pipeline(self.config)
        self._set_rates()
        self.bus: Any = None
        self._direct = None          # SocketCAN: one system call per frame (busio.direct_io)
        self.bus_down = False          # a failure was logged and the bus has not recovered yet
        self.bus_off = False
        self._backoff = FIRST_BACKOFF_S
        self._next_open = 0.0
        self._stop = threading.Event()
        self._reload_requested = False
        self.running = threading.Event()   # set once READY=1 was sent (tests wait on it)
        self._period_warned = False
        self._cycles_told = False
        self._noise_told = False
        self.state_file: StateFile | None = None
        self.estimate_log: EstimateLog | None = None
        self._last_rx_time: float | None = None
        self._last_rx_mono = 0.0
        self._rx_backlog = False     # the last recv returned a frame: more may be queued behind it
        self._last_status_text = ""
        self._last_status_name = ""
        self._updates_saved = 0
        self._state_loaded = False
        self._last_tx_drop_log = -math.inf

    # ------------------------------------------------------------------------------ control
    def request_stop(self) -> None:
        self._stop.set()

    def request_reload(self) -> None:
        self._reload_requested = True

    def _on_signal(self, signum: int, _frame: Any) -> None:
        if signum == signal.SIGHUP:
            self._reload_requested = True
        else:
            self._stop.set()

    # ------------------------------------------------------------------------------ set-up
    def _set_rates(self) -> None:
        cfg = self.config
        pipeline = self.pipeline
        self.trigger_id = pipeline.input_codec.trigger_id
        self.trigger_extended = pipeline.input_codec.trigger_extended
        self.guard = RateGuard(cfg.daemon.max_update_rate)
        period = pipeline.front_end.period_of(pipeline.trigger_message)
        self.tick_interval_s = max(0.005, min(period / 2.0, 0.05))

    def frame_now(self) -> float:
        """"Now" on the time base of the received frames (socket timestamps, or a log's)."""
        if self._last_rx_time is None:
            return self._clock()
        if self._rx_backlog:
            # Frames may still be queued with earlier times than an extrapolated "now": a tick
            # stamped later than them would put the output out of order (log, listeners).
            return self._last_rx_time
        return self._last_rx_time + (self._mono() - self._last_rx_mono)

    # ------------------------------------------------------------------------------ main loop
    def run(self) -> int:
        """Serve until stopped. Returns 0; raises `StartupError` for unusable settings."""
        previous: dict[int, Any] = {}
        if self._install_signals and threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
                previous[sig] = signal.signal(sig, self._on_signal)
        try:
            self._open_state()
            self.estimate_log = self._open_estimate_log()
            self._open_bus(first=True)
            self._serve()
        finally:
            self._shutdown()
            for sig, handler in previous.items():
                signal.signal(sig, handler)
        return 0

    def _serve(self) -> None:
        mono = self._mono
        cfg = self.config
        now = mono()
        self._fps = 0.0
        self._status_at = now
        self._status_rx = 0
        next_tick = now + self.tick_interval_s
        next_status = now + cfg.daemon.status_interval
        next_state = now + cfg.daemon.state_interval
        wd_interval = self.notifier.watchdog_interval_s
        next_wd = now
        wd_rx = 0
        # Everything built so far (codecs, databases, config) lives as long as the daemon: keep it
        # out of the cyclic collector's full passes, which would otherwise walk it in the middle
        # of a frame's handling every so often.
        gc.collect()
        gc.freeze()
        self.notifier.ready(self.status_text())
        self.running.set()
        log.info("running (watchdog %s)", f"every {wd_interval:.1f} s" if wd_interval else "off")
        stop = self._stop
        while not stop.is_set():
            if self._reload_requested:
                self._reload()
                cfg = self.config
            self._receive_one()
            # --- housekeeping (all on the monotonic clock)
            now = mono()
            if now >= next_tick:
                next_tick = now + self.tick_interval_s
                self._stale_tick()
            if wd_interval and now >= next_wd and self.stats.rx_frames > wd_rx and not self.bus_down:
                self.notifier.watchdog()
                wd_rx = self.stats.rx_frames
                next_wd = now + wd_interval
            if now >= next_status:
                next_status = now + cfg.daemon.status_interval
                self._update_status(now)
            if now >= next_state:
                next_state = now + cfg.daemon.state_interval
                if self.pipeline.stats.updates != self._updates_saved:
                    self.save_state()

    def _receive_one(self) -> None:
        """One frame off the bus and handled, waiting at most a tick for it; without a bus, open
        it again when its back-off has passed."""
        bus = self.bus
        if bus is None:
            now = self._mono()
            if now >= self._next_open:
                self._open_bus()
            else:
                self._stop.wait(min(0.1, self._next_open - now, self.tick_interval_s))
            return
        try:
            direct = self._direct
            msg = direct.recv(self.tick_interval_s) if direct is not None else bus.recv(timeout=self.tick_interval_s)
        except (can.CanError, OSError, ValueError) as exc:
            self._bus_failed(exc, "receive")
            return
        self._rx_backlog = msg is not None
        if self.bus_down:
            self._bus_ok()
        elif self._backoff != FIRST_BACKOFF_S:
            self._backoff = FIRST_BACKOFF_S
        if msg is not None:
            self._handle(msg)

    def _stale_tick(self) -> None:
        """The pipeline's tick (stale inputs said on the bus even when no frame comes) and the
        estimate log's flush, once per `tick_interval_s`."""
        if self.bus is not None:
            try:
                out = self.pipeline.tick(self.frame_now())
            except Exception:  # noqa: BLE001
                self.stats.internal_errors += 1
                out = []
                if self.stats.internal_errors == 1:
                    log.exception("internal error in the stale-input tick")
            if out:
                self._send(out)
        if self.estimate_log is not None:
            self.estimate_log.poll()

    def _shutdown(self) -> None:
        self.notifier.stopping(f"stopping: {self.status_text() if hasattr(self, '_fps') else ''}")
        if self.state_file is not None and (self.pipeline.stats.updates != self._updates_saved or not self._state_loaded):
            self.save_state()
        self._close_bus()
        if self.estimate_log is not None:
            self.estimate_log.close()
        st = self.stats
        ps = self.pipeline.stats
        log.info("stopped: %d frames in, %d updates, %d frames out, %d tx dropped, %d flood dropped, "
                 "%d error frames, %d bus failures", st.rx_frames, ps.updates, st.tx_frames, st.tx_dropped,
                 st.flood_dropped, ps.error_frames, st.bus_failures)


def _load_and_validate(path: Path | None) -> Config:
    from .codec import validate_against_dbc
    from .config import default_config_path, load_config

    config = load_config(path if path is not None else default_config_path())
    validate_against_dbc(config)
    return config
