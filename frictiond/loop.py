"""The receive → pipeline → send step loop, owned by us rather than python-can's Notifier."""
from __future__ import annotations

import logging
import threading
import time

import can

from .busio import frame_to_message, message_to_frame
from .pipeline import Pipeline

log = logging.getLogger(__name__)


def serve(bus: can.BusABC, pipeline: Pipeline, stop: threading.Event, recv_timeout_s: float = 0.01) -> None:
    """Run until `stop` is set; a full transmit queue drops frames instead of blocking."""
    dropped = 0
    while not stop.is_set():
        msg = bus.recv(timeout=recv_timeout_s)
        if msg is None:
            out = pipeline.tick(time.time())
        else:
            out = pipeline.process(message_to_frame(msg))
        for frame in out:
            try:
                bus.send(frame_to_message(frame), timeout=0)
            except can.CanError:
                dropped += 1
    if dropped:
        log.warning("dropped %d output frames (transmit queue full)", dropped)
