"""The daemon's config and what follows from it (`DaemonReload`, a part of `daemon.Daemon`; its
state is the daemon's): the files it names (the persisted estimator state, the estimate log) and
its reload on SIGHUP, which swaps the pipeline keeping the learnt state and reopens only what
changed."""
from __future__ import annotations

import logging
import math

from .config import ConfigError
from .daemon_bus import FIRST_BACKOFF_S, StartupError
from .estimate_log import EstimateLog
from .pipeline import Pipeline
from .state import StateFile

log = logging.getLogger("frictiond.daemon")


class DaemonReload:
    """Config, state file, estimate log and reload of the live loop."""

    def _open_state(self) -> None:
        path = self.config.daemon.state_file
        self.state_file = StateFile(path) if path is not None else None
        if self.state_file is not None:
            self._state_loaded = self.state_file.load_into(self.pipeline.estimator)

    def _open_estimate_log(self) -> EstimateLog | None:
        out = self.config.output
        if out.estimate_log is None:
            return None
        try:
            return EstimateLog(out.estimate_log, out.estimate_log_max_bytes, out.estimate_log_backups,
                               channel=self.config.can.channel)
        except (OSError, ValueError) as exc:
            raise StartupError(f"output.estimate_log: cannot open {out.estimate_log}: {exc}") from None

    def save_state(self) -> None:
        if self.state_file is not None:
            self.state_file.save(self.pipeline.estimator.state(), self._clock())
            self._updates_saved = self.pipeline.stats.updates

    def _reload(self) -> None:
        self._reload_requested = False
        self.stats.reloads += 1
        self.notifier.reloading()
        try:
            new = self.overrides.apply(self._config_loader(self.config_path))
            pipeline = Pipeline(new)
        except (ConfigError, OSError, ValueError) as exc:
            self.stats.reload_failures += 1
            log.error("config reload failed, keeping the running config: %s", exc)
            self.notifier.ready(self.status_text())
            return
        old = self.config
        try:
            pipeline.estimator.load_state(self.pipeline.estimator.state())
        except (ValueError, TypeError, KeyError):
            log.info("estimator changed with the reload: starting from its nominal prior")
        bus_changed = (new.can.interface, new.can.channel, new.can.bitrate) != (
            old.can.interface, old.can.channel, old.can.bitrate) or (
            (pipeline.input_codec.input_ids, pipeline.input_codec.extended_input_ids, pipeline.input_codec.fd)
            != (self.pipeline.input_codec.input_ids, self.pipeline.input_codec.extended_input_ids,
                self.pipeline.input_codec.fd))
        log_changed = (new.output.estimate_log, new.output.estimate_log_max_bytes, new.output.estimate_log_backups) != (
            old.output.estimate_log, old.output.estimate_log_max_bytes, old.output.estimate_log_backups)
        self.save_state()
        self.config = new
        self.pipeline = pipeline
        self._period_warned = False
        self._set_rates()
        self._updates_saved = 0
        if new.daemon.state_file != old.daemon.state_file:
            self.state_file = StateFile(new.daemon.state_file) if new.daemon.state_file is not None else None
        if log_changed:
            if self.estimate_log is not None:
                self.estimate_log.close()
            try:
                self.estimate_log = self._open_estimate_log()
            except StartupError as exc:
                log.error("%s; estimate log disabled", exc)
                self.estimate_log = None
        if bus_changed:
            self._close_bus()
            self.bus_down = False
            self._backoff = FIRST_BACKOFF_S
            try:
                self._open_bus(first=True)
            except StartupError as exc:
                log.error("%s; waiting for a usable config", exc)
                self._next_open = math.inf
        log.warning("config reloaded from %s", self.config_path or "the built-in default")
        self.notifier.ready(self.status_text())
