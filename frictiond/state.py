"""The persisted estimator state: an atomically replaced JSON file.

Layout: `{"format": 1, "version": "...", "time": <unix s>, "estimator": <estimator.state()>}`.

Writes go to `<file>.tmp`, are fsynced, renamed over the file and the directory is fsynced, so
a kill -9 or a power cut at any instant leaves either the previous complete file or the new
complete file, never a mixture. A file that cannot be read or does not parse is reported with one
warning and ignored: the estimator then starts from its nominal prior.
"""
from __future__ import annotations

import json
import logging
import math
import os
import time
from pathlib import Path
from typing import Any

from . import __version__

log = logging.getLogger(__name__)

STATE_FORMAT = 1
MAX_STATE_BYTES = 1 << 20


class StateError(ValueError):
    """A state file that exists but cannot be used."""


def write_atomic(path: str | Path, data: bytes, mode: int = 0o600) -> None:
    """Replace `path` by `data` so that readers only ever see the old or the new content."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_CLOEXEC, mode)
    try:
        view = memoryview(data)
        while view:
            written = os.write(fd, view)
            view = view[written:]
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(tmp, path)
    dir_fd = os.open(path.parent, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    try:
        os.fsync(dir_fd)
    finally:
        os.close(dir_fd)


def _finite_json(obj: Any) -> Any:
    """JSON cannot carry NaN/inf portably: store them as null."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {str(k): _finite_json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite_json(v) for v in obj]
    return obj


def encode_state(estimator_state: dict[str, Any], now_s: float | None = None) -> bytes:
    doc = {
        "format": STATE_FORMAT,
        "version": __version__,
        "time": time.time() if now_s is None else now_s,
        "estimator": _finite_json(estimator_state),
    }
    return (json.dumps(doc, allow_nan=False, sort_keys=True, indent=1) + "\n").encode()


def decode_state(raw: bytes) -> dict[str, Any]:
    """The whole state document; `StateError` naming what is wrong."""
    if len(raw) > MAX_STATE_BYTES:
        raise StateError(f"larger than {MAX_STATE_BYTES} bytes")
    try:
        doc = json.loads(raw.decode("utf-8"), parse_constant=_reject_constant)
    except (UnicodeDecodeError, ValueError) as exc:
        raise StateError(f"not valid JSON ({exc})") from None
    if not isinstance(doc, dict):
        raise StateError("not a JSON object")
    if doc.get("format") != STATE_FORMAT:
        raise StateError(f"unknown format {doc.get('format')!r} (expected {STATE_FORMAT})")
    if not isinstance(doc.get("estimator"), dict):
        raise StateError("no estimator state")
    t = doc.get("time")
    if isinstance(t, bool) or not isinstance(t, (int, float)):
        raise StateError("no time stamp")
    return doc


def _reject_constant(name: str) -> Any:
    raise ValueError(f"{name} is not allowed")


class StateFile:
    """Saves and loads one estimator's state at `path`."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.saves = 0
        self.failures = 0
        self._warned_save = False

    def save(self, estimator_state: dict[str, Any], now_s: float | None = None) -> bool:
        """Write the state atomically; a failure is logged (once per streak) and returns False."""
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            write_atomic(self.path, encode_state(estimator_state, now_s))
        except (OSError, TypeError, ValueError) as exc:
            self.failures += 1
            if not self._warned_save:
                self._warned_save = True
                log.warning("cannot write state file %s: %s", self.path, exc)
            return False
        if self._warned_save:
            log.warning("state file %s written again", self.path)
        self._warned_save = False
        self.saves += 1
        return True

    def read(self) -> dict[str, Any] | None:
        """The state document, None if there is no file; `StateError` if it is unusable."""
        try:
            with open(self.path, "rb") as fh:
                raw = fh.read(MAX_STATE_BYTES + 1)
        except FileNotFoundError:
            return None
        except OSError as exc:
            raise StateError(f"cannot read: {exc.strerror or exc}") from None
        return decode_state(raw)

    def load_into(self, estimator: Any) -> bool:
        """Use the saved state as the estimator's prior. False (with a warning) if unusable."""
        try:
            doc = self.read()
            if doc is None:
                log.info("no state file %s yet: starting from the nominal prior", self.path)
                return False
            estimator.load_state(doc["estimator"])
        except (StateError, ValueError, TypeError, KeyError) as exc:
            log.warning("ignoring state file %s: %s", self.path, exc)
            return False
        age = time.time() - float(doc["time"])
        log.info("loaded estimator state from %s (saved %.0f s ago)", self.path, age)
        return True
