"""The optional log of every frame the daemon sends: python-can writers, size-rotated, flushed.

The format follows the suffix (`.log` candump, `.blf`, `.asc`, ... through `busio.LogWriter`).
Rotation keeps the suffix so that rotated files stay readable by `frictiond replay` and python-can:
`estimates.log` → `estimates.1.log` → `estimates.2.log` ... up to `backups` files (the oldest is
deleted). A file left by an earlier run is rotated away at start (BLF cannot be appended to).

`poll()` (called from the daemon loop) flushes buffered frames to the file and fsyncs it at
least every `flush_interval_s`, so a power cut loses at most about the last second of frames.
"""
from __future__ import annotations

import logging
import os
import time
from pathlib import Path
from typing import Callable, Iterable

from .busio import LogWriter
from .frames import Frame

log = logging.getLogger(__name__)


def rotated_path(path: Path, index: int) -> Path:
    """`estimates.log`, 1 → `estimates.1.log`; `estimates.log.gz`, 2 → `estimates.2.log.gz`."""
    if index == 0:
        return path
    suffixes = "".join(path.suffixes[-2:] if path.suffix.lower() == ".gz" else path.suffixes[-1:])
    stem = path.name[: len(path.name) - len(suffixes)] if suffixes else path.name
    return path.with_name(f"{stem}.{index}{suffixes}")


class EstimateLog:
    """Rotating, periodically flushed log of output frames."""

    def __init__(
        self,
        path: str | Path,
        max_bytes: int = 50_000_000,
        backups: int = 5,
        channel: str = "can0",
        flush_interval_s: float = 1.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.path = Path(path)
        self.max_bytes = max(1024, int(max_bytes))
        self.backups = max(0, int(backups))
        self.channel = channel
        self.flush_interval_s = flush_interval_s
        self._clock = clock
        self.frames_written = 0
        self.rotations = 0
        self.write_errors = 0
        self._dirty = False
        self._writer: LogWriter | None = None
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if self.path.exists() and self.path.stat().st_size > 0:
            self._shift()
        self._open()

    # ------------------------------------------------------------------------------------------
    def _open(self) -> None:
        self._writer = LogWriter(self.path, channel=self.channel)
        self._last_flush = self._clock()

    def _shift(self) -> None:
        """Rename path → .1 → .2 ...; the oldest beyond `backups` is removed."""
        if self.backups == 0:
            self.path.unlink(missing_ok=True)
            return
        oldest = rotated_path(self.path, self.backups)
        oldest.unlink(missing_ok=True)
        for i in range(self.backups - 1, -1, -1):
            src = rotated_path(self.path, i)
            if src.exists():
                os.replace(src, rotated_path(self.path, i + 1))

    def _raw_writer(self):
        return self._writer._logger if self._writer is not None else None  # noqa: SLF001

    def size(self) -> int:
        w = self._raw_writer()
        if w is None:
            return 0
        try:
            return int(w.file_size())
        except (OSError, ValueError, AttributeError):
            return 0

    # ------------------------------------------------------------------------------------------
    def write(self, frame: Frame) -> None:
        if self._writer is None:
            return
        try:
            self._writer.write(frame)
        except (OSError, ValueError) as exc:
            self.write_errors += 1
            if self.write_errors == 1:
                log.warning("estimate log %s: write failed: %s", self.path, exc)
            return
        self.frames_written += 1
        self._dirty = True
        if self.size() >= self.max_bytes:
            self.rotate()

    def write_all(self, frames: Iterable[Frame]) -> None:
        for frame in frames:
            self.write(frame)

    def poll(self, now: float | None = None) -> None:
        """Flush if the flush interval has passed since the last flush."""
        now = self._clock() if now is None else now
        if now - self._last_flush >= self.flush_interval_s:
            self.flush()

    def flush(self) -> None:
        """Buffered frames to the file, and the file to the disk."""
        self._last_flush = self._clock()
        w = self._raw_writer()
        if w is None or not self._dirty:
            return
        try:
            inner_flush = getattr(w, "_flush", None)  # BLF keeps a container buffer of its own
            if callable(inner_flush):
                inner_flush()
            w.file.flush()
            os.fsync(w.file.fileno())
        except (OSError, ValueError, AttributeError) as exc:
            self.write_errors += 1
            log.warning("estimate log %s: flush failed: %s", self.path, exc)
            return
        self._dirty = False

    def rotate(self) -> None:
        self.close()
        self._shift()
        self.rotations += 1
        self._open()

    def close(self) -> None:
        if self._writer is None:
            return
        try:
            self._writer.close()
            fd = os.open(self.path, os.O_RDONLY | os.O_CLOEXEC)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
        except OSError as exc:
            log.warning("estimate log %s: close failed: %s", self.path, exc)
        self._writer = None
        self._dirty = False

    def __enter__(self) -> "EstimateLog":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
