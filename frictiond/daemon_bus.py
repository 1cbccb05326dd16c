"""The daemon's side of the CAN bus (`DaemonBus`, a part of `daemon.Daemon`; its state is the
daemon's): opening and closing the bus, a failure and the backoff before the next try, each
received frame into the pipeline (error frames: bus-off and restart), the output frames sent
without blocking."""
from __future__ import annotations

import errno
import logging
from typing import Any

import can

from .busio import direct_io, frame_to_message, message_to_frame
from .frames import Frame

log = logging.getLogger("frictiond.daemon")

# linux/can/error.h: error class bits in the ID of an error frame, controller detail in data[1]
CAN_ERR_CRTL = 0x004
CAN_ERR_BUSOFF = 0x040
CAN_ERR_RESTARTED = 0x100
CAN_ERR_CRTL_ACTIVE = 0x40

# errno values of a send/recv that mean "the interface is gone or down", not "queue full"
LINK_ERRNOS = frozenset({errno.ENETDOWN, errno.ENODEV, errno.ENXIO, errno.EBADF, errno.ENETUNREACH})
FIRST_BACKOFF_S = 0.1


class StartupError(Exception):
    """The daemon cannot start with this configuration (exit 78)."""


def _errno_of(exc: BaseException) -> int | None:
    code = getattr(exc, "error_code", None)
    if isinstance(code, int):
        return code
    code = getattr(exc, "errno", None)
    if isinstance(code, int):
        return code
    cause = exc.__cause__
    return getattr(cause, "errno", None) if cause is not None else None


class DaemonBus:
    """Bus I/O of the live loop."""

    def _open_bus(self, first: bool = False) -> None:
        cfg = self.config.can
        kwargs = {"bitrate": cfg.bitrate} if cfg.bitrate else {}
        try:
            codec = self.pipeline.input_codec
            if codec.fd:
                kwargs["fd"] = True
            if codec.extended_input_ids:
                kwargs["extended_ids"] = codec.extended_input_ids
            self.bus = self._bus_factory(cfg.interface, cfg.channel, codec.input_ids, **kwargs)
        except (NotImplementedError, ImportError, TypeError) as exc:   # incl. CanInterfaceNotImplementedError
            raise StartupError(f"can.interface: cannot use {cfg.interface!r}: {exc}") from None
        except (can.CanError, OSError, ValueError) as exc:
            self._bus_failed(exc, "open")
            return
        self._direct = direct_io(self.bus)
        self.stats.bus_opens += 1
        if first:
            log.info("listening on %s %s for IDs %s", cfg.interface, cfg.channel,
                     ", ".join(f"0x{i:X}" for i in sorted(self.pipeline.input_codec.input_ids)))

    def _close_bus(self) -> None:
        self._direct = None
        bus, self.bus = self.bus, None
        if bus is not None:
            try:
                bus.shutdown()
            except Exception as exc:  # noqa: BLE001 - closing a broken bus must not fail the loop
                log.debug("closing bus: %s", exc)

    def _bus_failed(self, exc: BaseException, what: str) -> None:
        cfg = self.config.can
        if not self.bus_down:
            self.bus_down = True
            self.stats.bus_failures += 1
            log.warning("CAN %s %s: %s failed (%s); retrying with backoff up to %g s",
                        cfg.interface, cfg.channel, what, exc, self.config.daemon.reconnect_max_backoff)
        else:
            log.debug("CAN %s still failing: %s", what, exc)
        self._close_bus()
        self._next_open = self._mono() + self._backoff
        self._backoff = min(self._backoff * 2.0, self.config.daemon.reconnect_max_backoff)

    def _bus_ok(self) -> None:
        if self.bus_down:
            self.bus_down = False
            cfg = self.config.can
            log.warning("CAN %s %s is back; resuming", cfg.interface, cfg.channel)
        self._backoff = FIRST_BACKOFF_S

    # ------------------------------------------------------------------------------ frames
    def _handle(self, msg: Any) -> None:
        frame = message_to_frame(msg)
        if frame.is_error:
            self._on_error_frame(frame)
        else:
            self.stats.rx_frames += 1
            self._last_rx_time = frame.time_s
            self._last_rx_mono = self._mono()
            if frame.can_id == self.trigger_id and frame.is_extended == self.trigger_extended and not frame.is_remote:
                if not self.guard.allow(frame.time_s):
                    self.stats.flood_dropped += 1
                    if self.stats.flood_dropped == 1:
                        log.warning("trigger frames arrive faster than daemon.max_update_rate (%g Hz): "
                                    "dropping the excess", self.config.daemon.max_update_rate)
                    return
        try:
            out = self.pipeline.process(frame)
        except Exception:  # noqa: BLE001 - one poisoned frame must not take the daemon down
            self.stats.internal_errors += 1
            if self.stats.internal_errors == 1:
                log.exception("internal error processing a frame (dropped; further ones counted)")
            return
        if out:
            self._send(out)

    def _on_error_frame(self, frame: Frame) -> None:
        st = self.stats
        st.error_frames += 1
        cls = frame.can_id & 0x1FFFFFFF
        st.error_classes[cls] = st.error_classes.get(cls, 0) + 1
        if cls & CAN_ERR_BUSOFF:
            if not self.bus_off:
                st.bus_off_events += 1
                log.warning("CAN controller is bus-off (error frame class 0x%X)", cls)
            self.bus_off = True
        elif self.bus_off and (cls & CAN_ERR_RESTARTED or (
                cls & CAN_ERR_CRTL and len(frame.data) > 1 and frame.data[1] & CAN_ERR_CRTL_ACTIVE)):
            self.bus_off = False
            log.warning("CAN controller restarted after bus-off")

    def _send(self, frames: list[Frame]) -> None:
        direct = self._direct
        for i, frame in enumerate(frames):
            bus = self.bus
            if bus is None:
                self.stats.tx_dropped += len(frames) - i
                return
            try:
                if direct is not None:
                    direct.send(frame_to_message(frame))
                else:
                    bus.send(frame_to_message(frame), timeout=0)
            except (can.CanError, OSError) as exc:
                if _errno_of(exc) in LINK_ERRNOS:
                    self.stats.tx_dropped += len(frames) - i
                    self._bus_failed(exc, "send")
                    return
                self.stats.tx_dropped += 1
                now = self._mono()
                if now - self._last_tx_drop_log > 10.0:
                    self._last_tx_drop_log = now
                    log.warning("transmit queue full: dropping output frames (%d so far)", self.stats.tx_dropped)
                continue
            self.stats.tx_frames += 1
            if self.estimate_log is not None:
                self.estimate_log.write(frame)
