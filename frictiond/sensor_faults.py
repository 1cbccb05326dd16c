"""The front end's sensor faults (`SensorFaults`, a part of `frontend.FrontEnd`; its state is the
front end's): a wheel-speed rate far from the DBC's, messages gone stale, a sample that used a
value found wrong after it, brake pressures that cannot explain the body's deceleration, and a
wheel-speed sensor that reads (near) zero while the car rolls on."""
from __future__ import annotations


class SensorFaults:
    """Checks of the inputs as sensors: rates, staleness, the pressures against the body, dead
    wheel-speed sensors."""

    @property
    def measured_period_s(self) -> float | None:
        """The wheel-speed message's mean cycle time as it arrives (None before 100 frames)."""
        return self._trigger_period_s if self._triggers_timed >= 100 else None

    def period_mismatch(self) -> bool:
        """Whether the wheel speeds arrive at a rate far from the DBC's cycle time (the derivative
        window, the staleness limits and the estimator's counts are sized from the latter)."""
        measured = self.measured_period_s
        nominal = self.declared_period_s
        return measured is not None and not 0.6 * nominal <= measured <= 1.6 * nominal

    # -- staleness ---------------------------------------------------------------------------
    def stale_messages(self, now_s: float) -> tuple[str, ...]:
        """Required messages whose last frame is older than `stale_periods` of their period."""
        limit = self.options.stale_periods
        stale = []
        for m, h in self._required_histories:   # (in name order: the result comes sorted)
            if now_s - h.last_arrival_s > limit * h.period_s + 1e-3:
                stale.append(m)
        return tuple(stale)

    def tainted(self, time_s: float) -> bool:
        """Whether a sample at `time_s` may have used an input value found wrong after it was
        made (a spike the next frame showed up: `InputGate.repaired`)."""
        spans = self.gate.repaired
        while spans and spans[0][1] < time_s - 1.0:
            spans.popleft()
        return any(a < time_s < b for a, b in spans)

    def _deceleration_unexplained(self, t_c: float, torqued: bool, accel_contact: float, omega_dot: list[float],
                                  speed_mps: float) -> bool:
        """Plausibility of the brake pressures against the body: a hard deceleration for 0.1 s with
        no pressure anywhere (and no drive torque to explain it) means the pressure signals are
        wrong, and every brake torque computed from them would be too. Unless the wheels are
        spinning back up: an ABS that released every wheel from deep slip at once leaves the
        road's force on them, J·ω̇/R each, braking the car for a few tenths of a second.
        `accel_contact` is the contact and air forces' (the accelerometer less its own offset),
        which does not hold the gravity slowing a car that coasts up a hill; the drag at the
        car's speed, up to what the config's drag may be off by, is taken off it."""
        veh = self.vehicle
        spin_up = veh.wheel_inertia * sum(a for a in omega_dot if a > 0.0) / (veh.wheel_radius * veh.mass)
        air = (veh.resistance_force(speed_mps) + veh.resistance_doubt_n(speed_mps)) / veh.mass
        if not torqued and accel_contact + spin_up + air < -self.options.unexplained_decel:
            self._unexplained_s += max(0.0, t_c - self._last_sample_time_s) if self._last_sample_time_s else 0.0
        else:
            self._unexplained_s = 0.0
        self._last_sample_time_s = t_c
        return self._unexplained_s > 0.1

    def _dead_wheels(self, time_s: float, wheel_linear: list[float], braked: list[bool]) -> list[bool]:
        """Wheels whose sensor reads (near) zero while the others say the car rolls on.

        A wheel far below the others is either locked by its brake or its sensor is dead (a
        broken wire reads 0). A lock needs brake pressure, and an ABS releases a locking wheel
        within a fraction of a second (ice included: the pressure is dumped, the road spins the
        wheel up again). So: far below the other wheels for longer than `dead_wheel_s`, or for
        `dead_wheel_unbraked_s` with no pressure on that wheel, is a dead sensor. It stays dead
        until its reading agrees with the others again (at a standstill all read zero, which
        proves nothing either way). Without ABS a wheel locked for longer is also reported: its
        slip is beyond `max_slip` then, so it is out of the fit anyway.
        """
        opts = self.options
        out = [False] * 4
        for i in range(4):
            others = max(wheel_linear[:i] + wheel_linear[i + 1:])
            w = wheel_linear[i]
            if self._dead[i]:
                if w > 0.5 * others and w > 0.3:
                    self._dead[i] = False
                    self._low_since_s[i] = None
                    self._low_unbraked_s[i] = 0.0
                out[i] = self._dead[i]
                continue
            low = others >= opts.min_speed and w < opts.dead_wheel_ratio * others
            if not low:
                self._low_since_s[i] = None
                self._low_unbraked_s[i] = 0.0
                continue
            since = self._low_since_s[i]
            if since is None or time_s < since:
                self._low_since_s[i] = since = time_s
                self._low_unbraked_s[i] = 0.0
            elif not braked[i] and self._last_sample_time_s is not None:
                self._low_unbraked_s[i] += max(0.0, min(time_s - self._last_sample_time_s, opts.max_gap))
            if time_s - since > opts.dead_wheel_s or self._low_unbraked_s[i] > opts.dead_wheel_unbraked_s:
                self._dead[i] = out[i] = True
        return out


def stood_in_for(failed: list[bool], wheel_linear: list[float]) -> list[float]:
    """The wheels' speeds with the slowest working wheel standing in for a stuck or dead sensor:
    a dead one's zero would drag the free-rolling observer, which pulls towards the wheels'
    mean, down by a quarter. (All failed: nothing to stand in.)"""
    if not any(failed) or all(failed):
        return wheel_linear
    slowest_ok = min(w for w, f in zip(wheel_linear, failed) if not f)
    return [slowest_ok if f else w for w, f in zip(wheel_linear, failed)]
