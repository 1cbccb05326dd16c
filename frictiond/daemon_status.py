"""The daemon's status reporting (`DaemonStatus`, a part of `daemon.Daemon`; its state is the
daemon's): the one-line status systemd shows (sd_notify STATUS=), its frames/s, a log line when
the estimate's status changes, and the warnings for a trigger message off its DBC cycle time, for
cycle times measured and for brake-pressure sensors too noisy for the usual ABS-release threshold."""
from __future__ import annotations

import logging

log = logging.getLogger("frictiond.daemon")


class DaemonStatus:
    """Status reporting of the live loop."""

    def status_text(self) -> str:
        est = self.pipeline.last_estimate
        name = est.status.name if est is not None else "WAITING"
        mu = f"MuMax {est.mu_max:.3f}" if est is not None else "MuMax -"
        reason = self.pipeline.not_valid_reason
        parts = [f"{name} {mu}" + (f" ({reason})" if reason else ""), f"{self._fps:.0f} frames/s"]
        if self.bus_down or self.bus is None:
            parts.append("bus down, reconnecting")
        if self.bus_off:
            parts.append("bus-off")
        st = self.stats
        if st.flood_dropped:
            parts.append(f"{st.flood_dropped} flood frames dropped")
        if st.tx_dropped:
            parts.append(f"{st.tx_dropped} tx dropped")
        join = self.pipeline.wheel_join
        if join is not None and join.dropped:
            silent, _n = join.dropped_by.most_common(1)[0]
            parts.append(f"{join.dropped} wheel-speed frames without {silent or 'the other wheel speeds'}")
        if self.pipeline.stats.error_frames:
            parts.append(f"{self.pipeline.stats.error_frames} error frames")
        return ", ".join(parts)

    def _update_status(self, now: float) -> None:
        measured = self.pipeline.measured_cycle_times
        if measured and not self._cycles_told:
            self._cycles_told = True
            log.warning("the DBC gives no GenMsgCycleTime for %s: measured from the first frames and used "
                        "(100 Hz was assumed until then); give it in the DBC",
                        ", ".join(f"{k} ({1e3 * v:.0f} ms)" for k, v in sorted(measured.items())))
        fe = self.pipeline.front_end
        if not self._period_warned and fe.period_mismatch():
            self._period_warned = True
            log.warning("%s arrives every %.1f ms but its DBC cycle time is %.1f ms: the derivative filter "
                        "and the staleness limits are sized from the DBC; fix its GenMsgCycleTime",
                        fe.trigger_message, 1e3 * (fe.measured_period_s or 0.0),
                        1e3 * fe.declared_period_s)
        if not self._noise_told:
            note = fe.pressure_noise_note()
            if note is not None:
                self._noise_told = True
                log.warning("%s", note)
        dt = now - self._status_at
        if dt > 0:
            self._fps = (self.stats.rx_frames - self._status_rx) / dt
        self._status_at = now
        self._status_rx = self.stats.rx_frames
        text = self.status_text()
        if text != self._last_status_text:
            self._last_status_text = text
            self.notifier.status(text)
        est = self.pipeline.last_estimate
        name = est.status.name if est is not None else "WAITING"
        if name != self._last_status_name:
            self._last_status_name = name
            log.info("status %s", text)
