"""Each wheel-speed input held until the messages its sample is matched with have caught up.

The front end makes one sample per wheel-speed frame, from the derivative filter's window of
wheel speeds, which ends at that frame. The brake torques and the body's acceleration it is set
against are averaged over the same window (`input_alignment`): read up to the window's end. At
the wheel frame's arrival the newest pressure frame is up to a period older (20 ms at 50 Hz), and
`MessageHistory` holds its value beyond: the brakes' torque at the window's end then lags by that
much on top of the sensor's own lag, and the rate its lag is compensated with ends on a held
value. Under ABS the pressure moves by hundreds of bar per second, and the wheels' μ read low
while it rose and high while it fell.

`TriggerHold` passes every decoded input on in order, except a wheel-speed input: that waits until
each partner message (pressures, acceleration) has been received at or past its time, or until
an input `max_wait_s` younger arrives (a partner that lost a frame or went silent is not waited
for longer; its staleness is the front end's to tell). The estimate comes that much later
(at most a partner's period, as a rule); its time is still the sample's. Pure bookkeeping:
nothing of CAN or of the physics.
"""
from __future__ import annotations

from collections import deque
from typing import Iterable

from .codec import DecodedInput, InputMessage
from .input_names import PRESSURE_NAMES

# What the front end matches to the derivative window (`input_alignment`): the messages awaited.
_MATCHED = frozenset(PRESSURE_NAMES) | {"accel_long"}


class TriggerHold:
    """Holds the `trigger` message's inputs until the `partners` (message names) reach their time."""

    def __init__(self, trigger: str, partners: Iterable[str], max_wait_s: float) -> None:
        self.trigger = trigger
        self.partners = frozenset(partners) - {trigger}
        self.max_wait_s = max_wait_s
        self._newest: dict[str, float] = {}
        self._pending: deque[DecodedInput] = deque()

    @classmethod
    def for_messages(cls, trigger: str, messages: Iterable[InputMessage], wait_periods: float,
                     default_period: float) -> "TriggerHold":
        """The hold for these input messages: awaiting those that carry pressures or the
        acceleration, at most `wait_periods` of the longest of their periods."""
        awaited = [m for m in messages if m.name != trigger and _MATCHED & set(m.signals)]
        longest = max((m.period_s or default_period for m in awaited), default=0.0)
        return cls(trigger, [m.name for m in awaited], wait_periods * longest)

    @property
    def waiting(self) -> int:
        """Wheel-speed inputs held now."""
        return len(self._pending)

    def push(self, item: DecodedInput) -> list[DecodedInput]:
        """`item` in; the inputs to pass on now, in order (empty while it is held)."""
        if not self.partners or self.max_wait_s <= 0.0:
            return [item]
        pending = self._pending
        out: list[DecodedInput] = []
        if pending and item.time_s < pending[-1].time_s - self.max_wait_s:
            # Time went back (a clock step, a log spliced), further than frames of different
            # messages arrive out of order: what waits belongs to the old time line.
            out.extend(pending)
            pending.clear()
            self._newest.clear()
        out.extend(self.due(item.time_s))
        if item.message == self.trigger:
            pending.append(item)
        else:
            out.append(item)
            if item.message in self.partners:
                self._newest[item.message] = max(item.time_s, self._newest.get(item.message, item.time_s))
        if pending:
            caught_up = min(self._newest.get(name, float("-inf")) for name in self.partners)
            while pending and pending[0].time_s <= caught_up:
                out.append(pending.popleft())
        return out

    def due(self, now_s: float) -> list[DecodedInput]:
        """The inputs that have waited `max_wait_s` by `now_s` (the bus gone quiet), in order."""
        out = []
        while self._pending and self._pending[0].time_s + self.max_wait_s <= now_s:
            out.append(self._pending.popleft())
        return out

    def flush(self) -> list[DecodedInput]:
        """Every input still held (the end of a log), in order."""
        out = list(self._pending)
        self._pending.clear()
        return out
