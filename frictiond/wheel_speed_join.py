"""Wheel speeds sent in more than one message (front and rear apart, or one per wheel), joined.

The front end updates on the message of `wheel_speed_fl` (the trigger) and needs all four wheels'
speeds at that instant. A car that sends the other wheels in messages of their own sends them at
other instants, with their own jitter and losses: their speeds at the trigger's instant are
interpolated between the partner frames just before and just after it. A trigger frame therefore
waits for every partner's next frame (about one partner period: the estimate comes that much
later), and a trigger whose partner was silent around it (no frame within `GAP_PERIODS` of its
period on either side) is dropped, never completed with an old speed: the updates stop, and the
wheel speeds go stale as any silent input does.

Plumbing on decoded values, between the codec and the front end: nothing here knows of tyres.
"""
from __future__ import annotations

import bisect
import math
from collections import Counter, deque
from collections.abc import Iterable, Mapping

from .codec import DecodedInput, InputMessage
from .message_clock import CLOCK_STEP_S

# A partner's frames may be this many of its periods apart and still be interpolated between
# (one lost frame), and a trigger waits this long past its instant for the partner's next one.
GAP_PERIODS = 2.5
DEFAULT_PERIOD_S = 0.01        # a partner without a DBC cycle time (as elsewhere: 100 Hz)
MAX_HELD = 64                  # trigger frames waiting at most (a partner silent for good)
_KEPT_FRAMES = 8               # partner frames kept per partner


class _Partner:
    """One partner message: the wheel speeds it carries and its newest frames, in time order."""

    __slots__ = ("names", "period_s", "times", "values")

    def __init__(self, names: tuple[str, ...], period_s: float) -> None:
        self.names = names
        self.period_s = period_s
        self.times: list[float] = []
        self.values: list[tuple[float, ...]] = []

    def add(self, time_s: float, values: Mapping[str, float]) -> None:
        k = bisect.bisect_right(self.times, time_s)   # (a frame out of order goes to its place)
        self.times.insert(k, time_s)
        self.values.insert(k, tuple(values[n] for n in self.names))
        if len(self.times) > _KEPT_FRAMES:
            del self.times[0], self.values[0]

    def at(self, time_s: float) -> tuple[float, ...] | None | bool:
        """The speeds at `time_s`, interpolated; None while the next frame may still come; False
        when they cannot be known (no frame before it, or too long a silence around it)."""
        times = self.times
        k = bisect.bisect_left(times, time_s)
        if k == len(times) or times[k] - time_s > CLOCK_STEP_S:
            return None           # (no frame after it yet, but one stamped far ahead: not the bus's time)
        if times[k] == time_s:
            return self.values[k]
        if k == 0 or times[k] - times[k - 1] > GAP_PERIODS * self.period_s:
            return False
        t0, t1 = times[k - 1], times[k]
        w = (time_s - t0) / (t1 - t0)
        return tuple(a + (b - a) * w for a, b in zip(self.values[k - 1], self.values[k]))


class WheelSpeedJoin:
    """Completes each trigger frame with the partner messages' wheel speeds at its instant."""

    def __init__(self, trigger: str, partners: Mapping[str, tuple[str, ...]],
                 periods: Mapping[str, float | None]) -> None:
        self.trigger = trigger
        self._partners = {name: _Partner(tuple(names), periods.get(name) or DEFAULT_PERIOD_S)
                          for name, names in partners.items()}
        self._held: deque[DecodedInput] = deque()
        # The time of the frame just pushed (what "now" is for a trigger still waiting), and of
        # the newest trigger (the clock partner frames are taken against).
        self._now_s = float("-inf")
        self._trigger_s = float("-inf")
        # Trigger frames dropped, by the partner message whose wheel speeds around them were missing.
        self.dropped_by: Counter[str] = Counter()

    @property
    def dropped(self) -> int:
        """Trigger frames dropped (no update): a partner's wheel speeds around them missing."""
        return sum(self.dropped_by.values())

    @staticmethod
    def front_end_messages(messages: Iterable[InputMessage], trigger: str,
                           partners: Mapping[str, tuple[str, ...]]) -> list[InputMessage]:
        """The input messages as the front end sees them after the join: the trigger carrying
        all four wheel speeds, each partner only its other signals (left out if none)."""
        moved = tuple(n for names in partners.values() for n in names)
        out = []
        for m in messages:
            if m.name == trigger:
                out.append(m._replace(signals=tuple(m.signals) + moved))
            elif m.name in partners:
                rest = tuple(s for s in m.signals if s not in partners[m.name])
                if rest:
                    out.append(m._replace(signals=rest))
            else:
                out.append(m)
        return out

    def push(self, decoded: DecodedInput) -> list[DecodedInput]:
        """The decoded inputs to give the front end, in order, now that `decoded` has come.

        A frame whose time no clock reads (not finite) goes on as it is, for the front end's gate
        to refuse; one far from the trigger's clock (a stepped or corrupt time) adds no speeds and
        waits for nothing: one bad time must not hold every update behind it."""
        t = decoded.time_s
        partner = self._partners.get(decoded.message)
        if not math.isfinite(t):
            return [decoded] if partner is None else []
        self._now_s = t
        if partner is not None:
            if abs(t - self._trigger_s) <= CLOCK_STEP_S or self._trigger_s == float("-inf"):
                partner.add(t, decoded.values)
            out = self._release()
            rest = {k: v for k, v in decoded.values.items() if k not in partner.names}
            if rest:
                out.append(DecodedInput(t, decoded.message, rest, False))
            return out
        if decoded.message != self.trigger:
            return [decoded]
        self._trigger_s = t
        late = [n for n, p in self._partners.items() if p.times and t - p.times[-1] > CLOCK_STEP_S]
        if late:
            # (its partners' newest frames are far behind it: silent, or this time is not the bus's)
            self.dropped_by[late[0]] += 1
            return self._release()
        self._held.append(decoded)
        while len(self._held) > MAX_HELD:
            waited_for = next((n for n, p in self._partners.items() if p.at(self._held[0].time_s) is None), "")
            self._held.popleft()
            self.dropped_by[waited_for] += 1
        return self._release()

    def _release(self) -> list[DecodedInput]:
        """The held triggers whose partners' speeds are now known, completed, oldest first;
        those that can never be completed are dropped."""
        out: list[DecodedInput] = []
        held = self._held
        while held:
            first = held[0]
            merged = dict(first.values)
            for name, partner in self._partners.items():
                speeds = partner.at(first.time_s)
                if speeds is None and self._now_s - first.time_s > GAP_PERIODS * partner.period_s:
                    speeds = False   # the partner's next frame is overdue: silent around this trigger
                if speeds is None:
                    return out       # (wait for it)
                if speeds is False:
                    break
                merged.update(zip(partner.names, speeds))
            else:
                held.popleft()
                out.append(DecodedInput(first.time_s, first.message, merged, True))
                continue
            held.popleft()
            self.dropped_by[name] += 1
        return out
