"""Bus and log-file I/O: the only module that imports python-can.

Log formats are chosen by file suffix through python-can's own readers and writers
(candump `.log`, `.asc`, `.blf`, `.csv`, `.trc`, … and `.gz` variants).
"""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, Iterable, Iterator

import can

from .frames import Frame

log = logging.getLogger(__name__)

SUPPORTED_LOG_SUFFIXES = (".log", ".asc", ".blf", ".csv", ".trc")


class LogFormatError(ValueError):
    """A log file whose format python-can cannot read or write."""


def message_to_frame(msg: can.Message) -> Frame:
    return Frame(
        float(msg.timestamp),
        int(msg.arbitration_id),
        bytes(msg.data[: msg.dlc] if msg.dlc is not None else msg.data),
        bool(msg.is_extended_id),
        bool(msg.is_error_frame),
        bool(msg.is_remote_frame),
    )


def frame_to_message(frame: Frame, channel: Any = None) -> can.Message:
    return can.Message(
        timestamp=frame.time_s,
        arbitration_id=frame.can_id,
        data=frame.data,
        is_extended_id=frame.is_extended,
        is_error_frame=frame.is_error,
        is_remote_frame=frame.is_remote,
        channel=channel,
    )


def _check_suffix(path: Path) -> None:
    suffixes = [s.lower() for s in path.suffixes]
    if suffixes and suffixes[-1] == ".gz":
        suffixes = suffixes[:-1]
    if not suffixes or suffixes[-1] not in SUPPORTED_LOG_SUFFIXES:
        raise LogFormatError(
            f"{path}: unknown log format {''.join(path.suffixes) or '(no suffix)'}; "
            f"use one of {', '.join(SUPPORTED_LOG_SUFFIXES)}"
        )


def read_log(path: str | Path) -> Iterator[Frame]:
    """Frames of a log file, in file order (timestamps may go backwards in spliced logs)."""
    path = Path(path)
    _check_suffix(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such log file")
    reader = can.LogReader(str(path))
    try:
        for msg in reader:
            yield message_to_frame(msg)
    finally:
        stop = getattr(reader, "stop", None)
        if stop is not None:
            stop()


class LogWriter:
    """Writes `Frame`s to a log file whose format follows the suffix."""

    def __init__(self, path: str | Path, channel: str = "can0") -> None:
        self.path = Path(path)
        _check_suffix(self.path)
        self.channel = channel
        self._logger = can.Logger(str(self.path))
        self.frames_written = 0

    def write(self, frame: Frame) -> None:
        self._logger.on_message_received(frame_to_message(frame, self.channel))
        self.frames_written += 1

    def write_all(self, frames: Iterable[Frame]) -> None:
        for frame in frames:
            self.write(frame)

    def close(self) -> None:
        self._logger.stop()

    def __enter__(self) -> "LogWriter":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def open_bus(interface: str, channel: str, receive_ids: Iterable[int] | None = None, **kwargs: Any) -> can.BusABC:
    """Open a python-can bus, ignoring stray can.conf files and CAN_* environment settings.

    `receive_ids` become exact-match kernel filters on SocketCAN (software filters elsewhere).
    """
    filters = None
    if receive_ids is not None:
        filters = [{"can_id": cid, "can_mask": 0x7FF, "extended": False} for cid in sorted(set(receive_ids))]
    return can.Bus(channel=channel, interface=interface, can_filters=filters, ignore_config=True, **kwargs)
