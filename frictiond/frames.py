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


# A frame's key in the tables of inputs: its ID, with this bit for a 29-bit (extended) one: a
# standard and an extended frame of the same number are different messages.
EXTENDED_KEY = 1 << 29


def frame_key(can_id: int, extended: bool) -> int:
    return can_id | EXTENDED_KEY if extended else can_id
