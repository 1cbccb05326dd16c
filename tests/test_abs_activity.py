"""ABS activity as evidence of the grip limit: from pressures, from the car's flags, in the estimator."""
from __future__ import annotations

import math

import numpy as np
import pytest

from frictiond import tyre_model as tm
from frictiond.abs_activity import AbsActivity
from frictiond.estimator import LugreTrustRegionEstimator
from frictiond.frontend import PRESSURE_NAMES, WHEEL_SPEED_NAMES, FrontEnd, FrontEndOptions
from frictiond.samples import PhysicalSample, Status
from frictiond.vehicle import VehicleParams

NO_FLAGS = (None, None, None, None)


def run(activity: AbsActivity, pressures_at, master_at=None, flag_at=None, duration_s=0.6):
    marks = []
    for k in range(int(duration_s / 0.01)):
        t = k * 0.01
        master = master_at(t) if master_at else None
        flag = flag_at(t) if flag_at else None
        marks.append((t, activity.update(t, pressures_at(t), master, flag, NO_FLAGS)))
    return marks


def test_a_wheel_released_while_the_others_hold_is_marked_and_the_mark_expires():
    # FL dumps from 90 to 20 bar at 0.2 s and is held there; the others keep 90 (front) and 45 (rear).
    marks = run(AbsActivity(), lambda t: (90.0 if t < 0.2 else 20.0, 90.0, 45.0, 45.0), duration_s=1.0)
    before = [m for t, m in marks if t < 0.195]
    during = [m for t, m in marks if 0.205 < t < 0.45]
    assert not any(any(m) for m in before)
    assert all(m == (True, False, False, False) for m in during)
    # The dump leaves the 0.3 s window at 0.5 s; the mark lasts another 0.3 s, then goes.
    assert marks[-1][1] == (False, False, False, False)


def test_the_driver_letting_go_is_no_release():
    # Every wheel falls together as the pedal comes up: the demand (the highest pressure) falls too.
    marks = run(AbsActivity(), lambda t: (max(0.0, 90 - 300 * t),) * 2 + (max(0.0, 45 - 150 * t),) * 2)
    assert not any(any(m) for _, m in marks)


def test_a_master_cylinder_pressure_is_the_demand_when_mapped():
    # All four wheels dumped at once (ice): without the master cylinder that looks like the driver
    # letting go; with it held at 100 bar it is the ABS.
    pressures = lambda t: (80.0,) * 4 if t < 0.2 else (15.0,) * 4  # noqa: E731
    assert not any(any(m) for _, m in run(AbsActivity(), pressures))
    marks = run(AbsActivity(), pressures, master_at=lambda t: 100.0)
    assert any(m == (True, True, True, True) for t, m in marks if 0.2 < t < 0.4)


def test_light_braking_and_small_wiggles_are_not_releases():
    # 8 bar falling to 2 bar (below the braking threshold), and 90 bar wiggling by 4 bar.
    assert not any(any(m) for _, m in run(AbsActivity(), lambda t: (8.0 if t < 0.2 else 2.0, 8.0, 4.0, 4.0)))
    wiggle = lambda t: (90.0 + 4 * math.sin(40 * t), 90.0, 45.0, 45.0)  # noqa: E731
    assert not any(any(m) for _, m in run(AbsActivity(), wiggle))


def test_a_shallow_dip_against_the_other_wheels_is_a_release_and_the_pedal_easing_is_not():
    # The fronts dip by 15 % (170 → 145 bar) while the rears hold: only ABS valves move one wheel
    # against another (a wheel-deceleration ABS reapplying in steps dumps this little).
    dip = lambda t: (170.0 if t < 0.2 else 145.0,) * 2 + (150.0, 150.0)  # noqa: E731
    marks = run(AbsActivity(), dip)
    assert not any(any(m) for t, m in marks if t < 0.195)
    assert all(m == (True, True, False, False) for t, m in marks if 0.205 < t < 0.45)
    # The driver easing the pedal by the same 15 %: every wheel falls alike, and so does the
    # master cylinder where it is mapped.
    ease = lambda t: (170.0 if t < 0.2 else 145.0,) * 2 + (150.0 if t < 0.2 else 128.0,) * 2  # noqa: E731
    assert not any(any(m) for _, m in run(AbsActivity(), ease))
    assert not any(any(m) for _, m in run(AbsActivity(), ease, master_at=lambda t: 200.0 if t < 0.2 else 170.0))
    # Against a master cylinder that holds, the same 15 % dip on one wheel is a release.
    one = lambda t: (170.0 if t < 0.2 else 145.0, 170.0, 150.0, 150.0)  # noqa: E731
    marks = run(AbsActivity(), one, master_at=lambda t: 200.0)
    assert any(m == (True, False, False, False) for t, m in marks if 0.2 < t < 0.4)


def test_the_cars_flag_marks_every_wheel_and_a_clock_step_back_forgets_the_maxima():
    a = AbsActivity()
    assert a.update(0.0, (50.0,) * 4, None, 1.0, NO_FLAGS) == (True,) * 4
    assert a.update(0.01, (50.0,) * 4, None, None, (0.0, 1.0, None, None)) == (True,) * 4  # (still remembered)
    a.update(1.0, (90.0,) * 4, None, 0.0, NO_FLAGS)
    # Back in time by 0.5 s with lower pressures: no comparison with the 90 bar of the old clock.
    assert a.update(0.5, (20.0,) * 4, None, 0.0, NO_FLAGS) == (False,) * 4


def test_the_front_end_marks_the_wheel_its_pressure_released():
    veh = VehicleParams()
    messages = {"WHEELS": WHEEL_SPEED_NAMES, "ACCEL": ("accel_long", "accel_lat"), "PRESS": PRESSURE_NAMES}
    fe = FrontEnd(veh, FrontEndOptions(), messages, {m: 0.01 for m in messages}, "WHEELS")
    samples = []
    for k in range(100):
        t = k * 0.01
        v = 25.0 - 6.0 * t
        fe.push(t + 0.003, "ACCEL", {"accel_long": -6.0, "accel_lat": 0.0})
        rear = 40.0
        fe.push(t + 0.006, "PRESS", dict(zip(PRESSURE_NAMES, (80.0 if t < 0.5 else 25.0, 80.0, rear, rear))))
        r = fe.push(t, "WHEELS", dict(zip(WHEEL_SPEED_NAMES, (v * 0.95 / veh.wheel_radius,) * 4)))
        if r is not None and r.sample is not None:
            samples.append(r.sample)
    assert samples
    assert all(s.abs_active == (False,) * 4 for s in samples if s.time_s < 0.48)
    assert any(s.abs_active == (True, False, False, False) for s in samples if s.time_s > 0.52)


def _held_near_the_peak(abs_marks: bool, seed: int = 4):
    """A wheel held by a fast ABS just below its peak: slip 68–92 % of λ*, never running away."""
    p = tm.LugreParams(theta=1.0, sigma0=230.0, v_s=5.0, sigma2=0.002)
    rng = np.random.default_rng(seed)
    est = LugreTrustRegionEstimator()
    statuses, errors = [], []
    v, t = 25.0, 0.0
    while v > 6.0:
        lam_star = tm.peak(v, p)[1]
        slips = [lam_star * (0.8 + 0.12 * math.sin(2 * math.pi * 2.0 * t + i)) for i in range(4)]
        mus = [float(tm.mu(s, v, p)) + float(rng.normal(0, 0.01)) for s in slips]
        # The ABS releases each wheel at the top of its (smooth, slow) slip cycle.
        marks = tuple(abs_marks and math.sin(2 * math.pi * 2.0 * t + i) > 0.9 for i in range(4))
        e = est.update(PhysicalSample(t, v, tuple(slips), tuple(mus), (4000.0,) * 4, (0.0,) * 4, (True,) * 4,
                                      True, abs_active=marks))
        statuses.append(e.status)
        if e.status == Status.VALID:
            errors.append(abs(e.mu_max - tm.peak(v, p)[0]) / tm.peak(v, p)[0])
        v -= float(np.mean(mus)) * 9.81 * 0.01
        t += 0.01
    return statuses, errors


def test_an_abs_working_the_wheels_is_evidence_where_the_slip_never_runs_away():
    statuses, _ = _held_near_the_peak(abs_marks=False)
    assert Status.VALID not in statuses          # no run-away, no ABS: the peak is not proven
    statuses, errors = _held_near_the_peak(abs_marks=True)
    assert statuses.count(Status.VALID) > 0.5 * len(statuses)
    assert max(errors) < 0.1
