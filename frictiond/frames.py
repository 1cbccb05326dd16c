"""The project's own CAN frame record, so that only the I/O layer imports python-can."""
from __future__ import annotations

from typing import NamedTuple


class Frame(NamedTuple):
    time_s: float
    can_id: int
    data: bytes
    is_extended: bool = False
    is_error: bool = False
    is_remote: bool = False
