"""Bus and log-file I/O: the only module that imports python-can.

Log formats are chosen by file suffix through python-can's own readers and writers
(candump `.log`, `.asc`, `.blf`, `.csv`, `.trc`, … and `.gz` variants).
"""
from __future__ import annotations

import errno
import locale
import logging
import math
import re
import select
import socket
from pathlib import Path
from typing import Any, Iterable, Iterator

import can

from .frames import Frame

try:
    # The common candump line parsed in C (setup.py builds it when a C compiler is there); the
    # regular expression below is the fallback and the reference (tests/test_logcore.py).
    from . import _logcore as compiled_log
except ImportError:  # pragma: no cover - depends on the install
    compiled_log = None

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
        is_fd=len(frame.data) > 8,   # (a classic frame carries at most 8 bytes)
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


# linux/can.h, as python-can's candump reader interprets them
_CAN_ERR_FLAG = 0x20000000
_CAN_ERR_BUSERROR = 0x00000080


def _candump_line_slow(temp: str) -> Frame:
    """One stripped candump line, exactly as python-can's `CanutilsLogReader` + `message_to_frame`."""
    if temp[-2:].lower() in (" r", " t"):
        timestamp_string, channel_string, frame, _rx = temp.split()
    else:
        timestamp_string, channel_string, frame = temp.split()
    timestamp = float(timestamp_string[1:-1])
    can_id_string, data = frame.split("#", maxsplit=1)
    channel: int | str = int(channel_string) if channel_string.isdigit() else channel_string
    is_extended = len(can_id_string) > 3
    can_id = int(can_id_string, 16)
    is_fd = brs = esi = False
    if data and data[0] == "#":
        is_fd = True
        fd_flags = int(data[1])
        brs, esi = bool(fd_flags & 0x01), bool(fd_flags & 0x02)
        data = data[2:]
    data_bin: bytearray | None
    if data and data[0].lower() == "r":
        is_remote = True
        dlc = int(data[1:]) if len(data) > 1 else 0
        data_bin = None
    else:
        is_remote = False
        dlc = len(data) // 2
        data_bin = bytearray(int(data[i:i + 2], 16) for i in range(0, len(data), 2))
    if can_id & _CAN_ERR_FLAG and can_id & _CAN_ERR_BUSERROR:
        msg = can.Message(timestamp=timestamp, is_error_frame=True)
    else:
        msg = can.Message(timestamp=timestamp, arbitration_id=can_id & 0x1FFFFFFF, is_extended_id=is_extended,
                          is_remote_frame=is_remote, is_fd=is_fd, bitrate_switch=brs, error_state_indicator=esi,
                          dlc=dlc, data=data_bin, channel=channel)
    return message_to_frame(msg)


# A classical data frame as candump -L and python-can write it: `(time) channel ID#HEX`, optionally
# ` R`/` T`. Only ASCII digits and plain spaces, so a match reads exactly as python-can reads it.
_CANDUMP_DATA_LINE = re.compile(r"\((-?[0-9]+\.[0-9]+)\) [!-~]+ ([0-9A-Fa-f]{1,8})#([0-9A-Fa-f]*)(?: [RrTt])?\n?")


def _is_unrelated(frame: Frame, keep_ids: frozenset[int]) -> bool:
    """A standard-ID data frame of an ID outside keep_ids: what `LogFrames` counts, not yields."""
    return not (frame.is_extended or frame.is_error or frame.is_remote) and frame.can_id not in keep_ids


def _id_bitmap(ids: Iterable[int]) -> bytes:
    """The IDs of up to three hex digits as `_logcore.candump_lines` takes them, a bit each."""
    bits = bytearray(512)
    for can_id in ids:
        if 0 <= can_id < 0x1000:
            bits[can_id >> 3] |= 1 << (can_id & 7)
    return bytes(bits)


def _candump_lines(text: str, keep_ids: frozenset[int] | None
                   ) -> tuple[list[Frame | str], int, int, float, float]:
    """The lines of a block of candump text, in order: the common line (a classical data frame) as
    a Frame, blank lines left out, any other line as its str for `_candump_line_slow`.

    With keep_ids, common standard-ID lines of other IDs are counted (`skipped`) instead.
    Returns (items, slow_lines, skipped, lead_time, tail_time): lead_time/tail_time are the times
    of the block's first/last frame line when that is a common line (NaN when it is a str item or
    there is none), so a reader knows the log's span without building the skipped frames.
    `_logcore.candump_lines` is this in C; this is its fallback and reference.
    """
    match = _CANDUMP_DATA_LINE.fullmatch
    new_frame = tuple.__new__   # Frame(...) without its Python-level __new__ (half the cost)
    items: list[Frame | str] = []
    slow_lines = skipped = 0
    lead_time = tail_time = math.nan
    any_frame_line = False
    lines = text.split("\n")
    last = lines.pop()
    for k, line in enumerate(lines + [last] if last else lines):
        if k < len(lines):
            line += "\n"
        m = match(line)
        if m is not None:
            time_string, id_string, data = m.groups()
            can_id = int(id_string, 16)
            if not can_id & _CAN_ERR_FLAG and not len(data) & 1:
                time_s = float(time_string)
                if not any_frame_line:
                    lead_time = time_s
                any_frame_line = True
                tail_time = time_s
                extended = len(id_string) > 3
                if keep_ids is not None and not extended and can_id not in keep_ids:
                    skipped += 1
                else:
                    items.append(new_frame(Frame, (time_s, can_id & 0x1FFFFFFF, bytes.fromhex(data), extended, False,
                                                             False)))
                continue
        if line.strip():
            any_frame_line = True
            tail_time = math.nan
            slow_lines += 1
            items.append(line)
    return items, slow_lines, skipped, lead_time, tail_time


_BLOCK_CHARS = 1 << 20   # candump text read and parsed a block at a time


class LogFrames:
    """The frames of a log file, in file order (timestamps may go backwards in spliced logs).

    With keep_ids, standard-ID data frames of any other ID are counted in `skipped` and never
    built: most of a loaded bus's log is other ECUs' traffic, which a consumer of a few IDs would
    only drop. Every other frame (kept IDs, extended IDs, remote and error frames) is yielded.
    After iteration `first_time_s`/`last_time_s` are the times of the file's first and last
    frames, skipped or not. Iterating again reads the file again.
    """

    def __init__(self, path: str | Path, keep_ids: Iterable[int] | None = None) -> None:
        self.path = Path(path)
        self.keep_ids = None if keep_ids is None else frozenset(keep_ids)
        self.skipped = 0
        self.first_time_s: float | None = None
        self.last_time_s: float | None = None

    def __iter__(self) -> Iterator[Frame]:
        path = self.path
        _check_suffix(path)
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such log file")
        self.skipped = 0
        self.first_time_s = self.last_time_s = None
        if path.suffix.lower() == ".log":
            yield from self._candump()
            return
        reader = can.LogReader(str(path))
        try:
            for msg in reader:
                frame = message_to_frame(msg)
                if self._kept(frame):
                    yield frame
        finally:
            stop = getattr(reader, "stop", None)
            if stop is not None:
                stop()

    def _candump(self) -> Iterator[Frame]:
        """candump -L `.log` files a block at a time, without a `can.Message` per line.

        Common lines are parsed by `_candump_lines`; any other (CAN FD, remote, error frames, odd
        digits, other spacing) goes through the same steps as python-can's reader, so the frames
        are identical to `message_to_frame` over `can.LogReader`.
        """
        keep_ids = self.keep_ids
        keep_bits = None if keep_ids is None else _id_bitmap(keep_ids)
        compiled = compiled_log.candump_lines if compiled_log is not None else None
        rest = ""
        with self.path.open("r", encoding=locale.getpreferredencoding(False)) as fh:
            while True:
                block = fh.read(_BLOCK_CHARS)
                text = rest + block
                cut = text.rfind("\n") + 1 if block else len(text)
                text, rest = text[:cut], text[cut:]
                if text:
                    parsed = compiled(text, Frame, keep_bits) if compiled is not None else None
                    if parsed is None:
                        parsed = _candump_lines(text, keep_ids)
                    items, slow_lines, skipped, lead_time, tail_time = parsed
                    self.skipped += skipped
                    if self.first_time_s is None and lead_time == lead_time:
                        self.first_time_s = lead_time
                    if slow_lines:
                        yield from self._with_slow_lines(items)
                    else:
                        yield from items
                    if tail_time == tail_time:   # else the block's last frame line was a str item, or none
                        self.last_time_s = tail_time
                if not block:
                    return

    def _with_slow_lines(self, items: list[Frame | str]) -> Iterator[Frame]:
        for item in items:
            if type(item) is str:
                frame = _candump_line_slow(item.strip())
                if self._kept(frame):
                    yield frame
            else:
                yield item

    def _kept(self, frame: Frame) -> bool:
        """Whether a frame built one by one is yielded (`keep_ids`); its time bounds the file's
        span either way, and a frame left out counts in `skipped`."""
        if self.first_time_s is None:
            self.first_time_s = frame.time_s
        self.last_time_s = frame.time_s
        if self.keep_ids is not None and _is_unrelated(frame, self.keep_ids):
            self.skipped += 1
            return False
        return True


def read_log(path: str | Path) -> Iterator[Frame]:
    """Frames of a log file, in file order (timestamps may go backwards in spliced logs)."""
    return iter(LogFrames(path))


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


def open_bus(interface: str, channel: str, receive_ids: Iterable[int] | None = None, fd: bool = False,
             extended_ids: Iterable[int] = (), **kwargs: Any) -> can.BusABC:
    """Open a python-can bus, ignoring stray can.conf files and CAN_* environment settings.

    `receive_ids` become exact-match kernel filters on SocketCAN (software filters elsewhere), as
    11-bit IDs; those also in `extended_ids` as 29-bit ones too.
    `fd`: some inputs are CAN FD frames; a SocketCAN socket is then opened for FD (it receives
    classic frames as well). Other interfaces take their FD settings (data bitrate, timing)
    from their own keyword arguments, which a config cannot give: there it is left to them.
    """
    if fd and interface == "socketcan":
        kwargs["fd"] = True
    filters = None
    if receive_ids is not None:
        ids = sorted(set(receive_ids))
        filters = [{"can_id": cid, "can_mask": 0x7FF, "extended": False} for cid in ids]
        filters += [{"can_id": cid, "can_mask": 0x1FFFFFFF, "extended": True} for cid in sorted(set(extended_ids))]
    bus = can.Bus(channel=channel, interface=interface, can_filters=filters, ignore_config=True, **kwargs)
    _enlarge_receive_buffer(bus)
    return bus


# A second of a loaded bus's input traffic queued in the kernel rides out a scheduling hiccup
# (a busy gateway CPU) instead of dropping frames; the kernel caps it at net.core.rmem_max.
RECEIVE_BUFFER_BYTES = 1 << 20


def _enlarge_receive_buffer(bus: can.BusABC) -> None:
    sock = getattr(bus, "socket", None)
    if not isinstance(sock, socket.socket):
        return
    try:
        if sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF) < RECEIVE_BUFFER_BYTES:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)
    except OSError as exc:  # not fatal: the default buffer still works
        log.debug("cannot enlarge the CAN socket's receive buffer: %s", exc)


class SocketcanDirect:
    """Receive and send on a python-can SocketCAN bus's own socket, one system call per frame.

    python-can's `recv`/`send` add a clock read and a `select` to every frame; on a busy gateway
    (or a user-mode Linux guest, where each system call costs ~0.3 ms) that is most of the cost
    of a frame. The socket is made non-blocking: `recv` reads first and only waits in `select`
    when nothing is queued, `send` never blocks (a full queue raises, and the caller drops).
    Frames are parsed and built by python-can's own SocketCAN helpers.
    """

    def __init__(self, bus: can.BusABC, sock: socket.socket) -> None:
        from can.interfaces.socketcan import socketcan as _sc

        self._capture = _sc.capture_message
        self._build = _sc.build_can_frame
        self._sock = sock
        self._stamped = _KernelTimestamp(sock, _sc.RECEIVED_TIMESTAMP_STRUCT)
        self._channel = getattr(bus, "channel", None) or getattr(bus, "channel_info", None)
        sock.setblocking(False)

    def recv(self, timeout: float) -> can.Message | None:
        msg = self._read()
        if msg is None:
            try:
                ready = select.select([self._sock], [], [], timeout)[0]
            except OSError as error:
                raise can.CanOperationError(f"Failed to receive: {error.strerror}", error.errno) from error
            if not ready:
                return None
            msg = self._read()
        if msg is not None and not msg.channel:
            msg.channel = self._channel
        return msg

    def _read(self) -> can.Message | None:
        """One queued frame, or None when nothing is queued."""
        stamped = self._stamped
        try:
            msg = self._capture(stamped)
        except can.CanOperationError as exc:
            if exc.error_code in (errno.EAGAIN, errno.EWOULDBLOCK):
                return None
            raise
        if msg is not None:
            msg.timestamp = stamped.time_s()
        return msg

    def send(self, msg: can.Message) -> None:
        try:
            self._sock.send(self._build(msg))
        except OSError as error:
            raise can.CanOperationError(f"Failed to transmit: {error.strerror}", error.errno) from error


class _KernelTimestamp:
    """The socket as python-can's frame parser reads it, keeping the kernel's receive time.

    python-can gives the time as `seconds + nanoseconds * 1e-9`; here it is truncated to the
    microsecond, as candump writes it (the kernel's own timeval): a candump recording of the bus
    then replays bit for bit what the daemon computed live. (An epoch time in a double resolves
    only ~0.24 µs anyway, and a CAN frame lasts over 40 µs on the wire.)
    """

    __slots__ = ("_recvmsg", "_ancillary", "_timespec")

    def __init__(self, sock: socket.socket, timespec: Any) -> None:
        self._recvmsg = sock.recvmsg
        self._ancillary: list = []
        self._timespec = timespec      # python-can's own struct timespec layout

    def recvmsg(self, *args: int) -> tuple:
        received = self._recvmsg(*args)
        self._ancillary = received[1]
        return received

    def time_s(self) -> float:
        """The last frame's receive time, s, on the µs grid. (An exact integer count of µs over an
        exact 1e6: the double nearest the decimal time, the one float() makes of candump's text.)"""
        _level, _kind, data = self._ancillary[0]
        seconds, nanoseconds = self._timespec.unpack_from(data)
        return (seconds * 1_000_000 + nanoseconds // 1000) / 1e6


def direct_io(bus: can.BusABC) -> SocketcanDirect | None:
    """The one-system-call path for a SocketCAN bus; None for every other interface."""
    sock = getattr(bus, "socket", None)
    if type(bus).__name__ != "SocketcanBus" or not isinstance(sock, socket.socket):
        return None
    try:
        return SocketcanDirect(bus, sock)
    except (ImportError, AttributeError, OSError) as exc:   # another python-can layout: use its own calls
        log.debug("SocketCAN direct path unavailable: %s", exc)
        return None
