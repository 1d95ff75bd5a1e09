"""The tracker's step from the odometry stamps (control.simulation.timing, issue 30 item 1).

The period estimate is robust to jitter, dropped and bunched messages and reports a
changed rate once; the tracker integrates its compensator over the interval that passed
(a dropped message included), gives the commands of a tracker told the right period
(after the first step) and tracks at 20, 50 and 100 Hz odometry, jitter included, where a
tracker told the paper's 10 ms does not; a plant's odometry jitter is seeded and in order.
"""
import math
import warnings

import numpy as np
import pytest

from conftest import CONFIG
from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.control.simulation.errors import LoopConfigError
from nonfragile_tracker.control.simulation.plant import PlantConfig, UnicyclePlant
from nonfragile_tracker.control.simulation.tracker import Tracker, TrackerConfig
from nonfragile_tracker.control.simulation.timing import step_time
from nonfragile_tracker.control.simulation.reference import figure_eight
from nonfragile_tracker.control.simulation.simulate import simulate_tracking
from nonfragile_tracker.control.simulation.timing import (PeriodEstimator, WINDOW,
                                                          period_disagreement)

K = read_gain_file(CONFIG / 'tracker_gains.yaml')
PATH = figure_eight(radius=1.0, rate=0.2)


def stamps(period_ns, n, start_ns=1_000_000_000):
    return [(start_ns + i * period_ns) * 1e-9 for i in range(n)]


def test_constant_period_is_exact_in_whole_nanoseconds():
    est = PeriodEstimator()
    assert est.period is None and est.observe(3.0) is None
    ivs = [est.observe(t) for t in stamps(20_000_000, 200, 3_000_000_000)[1:]]
    assert set(ivs) == {0.02} and est.period == 0.02 and est.settled


def test_period_is_robust_to_jitter_drops_and_bunching():
    rng = np.random.default_rng(1)
    est = PeriodEstimator()
    t = 10.0 + np.arange(500) * 0.02 + rng.uniform(-0.005, 0.005, 500)     # 5 ms jitter
    keep = rng.uniform(size=500) > 0.1                                      # 10 % dropped
    got = []
    for i, ti in enumerate(t):
        if not keep[i]:
            continue
        est.observe(float(ti))
        if i % 50 == 7:                      # a bunched pair: the same message twice, 1 ms on
            est.observe(float(ti) + 0.001)
        if i > 3 * WINDOW:
            got.append(est.period)
    assert max(abs(p - 0.02) for p in got) <= 0.004          # within the jitter of 20 ms
    p = est.period
    assert est.observe(float(t[-1])) == 0.0                  # the same stamp: nothing passed
    assert est.observe(5.0) is None and est.period == p      # a new time base: the period stays
    assert est.observe(5.02) == pytest.approx(0.02)
    assert est.observe(math.nan) is None and est.observe(1e300) is None and est.period == p


def test_a_changed_rate_is_reported_once_with_both_periods():
    est = PeriodEstimator()
    for t in stamps(10_000_000, 50):
        est.observe(t)
    assert est.rate_change() is None
    last = 1.0 + 49 * 0.01
    changes = []
    for i in range(1, 60):                   # 100 Hz -> 50 Hz
        est.observe(last + i * 0.02)
        changes.append(est.rate_change())
    reported = [c for c in changes if c is not None]
    assert reported == [(0.01, 0.02)]
    assert changes.index(reported[0]) <= WINDOW // 2 + 1     # within half a window


def test_disagreeing_override_message_has_both_numbers():
    msg = period_disagreement(0.01, 0.05)
    assert 'dt = 0.01 s' in msg and '0.0500 s (20.0 Hz)' in msg and 'set dt to 0' in msg
    assert period_disagreement(0.01, 0.011) is None          # within 20 %
    assert period_disagreement(0.0, 0.05) is None and period_disagreement(0.01, None) is None


def drive(tracker, times, th=0.3):
    """Commands of ``tracker`` for a pose beside the path at the given stamps."""
    out = []
    for t in times:
        ref = PATH.sample(t)
        out.append(tracker.step(ref.x + 0.02, ref.y - 0.01, th, ref, 0.1, stamp=t))
    return out


def test_step_from_the_stamps_equals_the_right_override_after_the_first_step():
    """20 ms odometry: dt = 0 gives, from the second step on, exactly the commands of a
    tracker told dt = 0.02; its first command (no interval known) has no ramp."""
    times = stamps(20_000_000, 300)
    auto = drive(Tracker(TrackerConfig(K=K)), times)
    told = Tracker(TrackerConfig(K=K, dt=0.02))
    ref0 = PATH.sample(times[0])
    first = told.step(ref0.x + 0.02, ref0.y - 0.01, 0.3, ref0, 0.1, stamp=times[0])
    rest = drive(told, times[1:])
    assert auto[0].v == 0.1 and first.v != 0.1 and auto[0].w == first.w
    assert [(c.v, c.w) for c in auto[1:]] == [(c.v, c.w) for c in rest]


def test_compensator_integrates_over_the_interval_that_passed():
    """A dropped message (40 ms instead of 20): the speed the next step starts from is
    v + a * 0.04; a tracker told dt = 0.02 integrates 0.02 whatever happened."""
    tr = Tracker(TrackerConfig(K=K))
    times = stamps(20_000_000, 12)
    drive(tr, times)
    v0, a0 = tr._ramp[0], tr._ramp[1]
    assert tr.v == pytest.approx(v0 + a0 * 0.02, abs=0, rel=1e-15)
    t_late = times[-1] + 0.04
    ref = PATH.sample(t_late)
    cmd = tr.step(ref.x, ref.y, 0.3, ref, 0.1, stamp=t_late)
    assert tr._ramp[0] == v0 + a0 * 0.04                    # the speed this step started from
    assert cmd.v == pytest.approx(tr._ramp[0] + 0.5 * cmd.a * 0.02, rel=1e-12)


def rms_after(dt, rate, latency, *, plant_dt=0.01, jitter=0.0, seconds=40.0):
    pc = PlantConfig(dt=plant_dt, x0=0.0, y0=-0.1, th0=math.pi / 4, cmd_latency=latency,
                     lag_v=0.05, lag_w=0.05, max_linear_accel=1.0, max_angular_accel=3.0,
                     odom_rate=rate, odom_noise=(0.001, 0.001, 0.001), noise_seed=1,
                     odom_jitter=jitter)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')              # the disagreeing override is warned
        run = simulate_tracking(pc, TrackerConfig(K=K, dt=dt), PATH,
                                int(round(seconds / plant_dt)))
    e = run.error[run.t > 10.0]
    return float(np.sqrt(np.mean(e * e)))


@pytest.mark.parametrize('rate', [20.0, 50.0, 100.0])
def test_defaults_track_at_any_odometry_rate(rate):
    """Issue 30's robot (50 ms lag, 1 m/s^2 and 3 rad/s^2, 1 mm noise, 100 ms latency),
    in process: the default (dt from the stamps) is within the issue's 10 mm at every
    rate; the paper's 10 ms told by hand is 3-10 times worse below 100 Hz (23 and 67 mm)."""
    auto = rms_after(0.0, rate, 0.1)
    assert auto <= 10e-3
    told = rms_after(0.01, rate, 0.1)
    if rate < 100.0:
        assert told > 3 * auto
    else:
        assert told == pytest.approx(auto, rel=1e-3)


def test_defaults_track_with_jittered_odometry():
    """50 Hz odometry with 5 ms jitter (plant step 1 ms), 150 ms latency: within 15 mm."""
    assert rms_after(0.0, 50.0, 0.15, plant_dt=0.001, jitter=0.005, seconds=30.0) <= 15e-3


def test_plant_odometry_jitter_is_seeded_in_order_and_validated():
    def stamps_of(seed):
        p = UnicyclePlant(PlantConfig(dt=0.001, odom_rate=50.0, odom_jitter=0.005,
                                      noise_seed=seed))
        out = []
        for _ in range(2000):
            m = p.odometry()
            if m is not None:
                out.append(step_time(m.step, 0.001))
            p.step(0.1, 0.0)
        return np.array(out)
    a, b = stamps_of(3), stamps_of(3)
    d = np.diff(a)
    assert np.array_equal(a, b) and not np.array_equal(a, stamps_of(4))
    assert d.min() >= 0.01 - 1e-9 and d.max() <= 0.03 + 1e-9 and d.std() > 0.002
    assert abs(d.mean() - 0.02) < 1e-3
    with pytest.raises(LoopConfigError, match='odom_jitter'):
        PlantConfig(dt=0.01, odom_rate=50.0, odom_jitter=0.01)


def test_gaps_do_not_count_but_a_dropped_rate_is_followed():
    """A 1 s gap (a stalled driver) leaves the 10 ms period; 100 Hz -> 20 Hz (five times
    the period: gaps at first) is the new period after half a window, reported once."""
    est = PeriodEstimator()
    for t in stamps(10_000_000, 20):
        est.observe(t)
    t = 1.0 + 19 * 0.01
    assert est.observe(t + 1.0) == pytest.approx(1.0) and est.period == 0.01
    t += 1.0
    for i in range(1, 4):                    # 100 Hz again after the gap
        assert est.observe(t + i * 0.01) == pytest.approx(0.01) and est.period == 0.01
    t += 3 * 0.01
    periods, changes = [], []
    for i in range(1, 20):
        est.observe(t + i * 0.05)
        periods.append(est.period)
        changes.append(est.rate_change())
    assert periods[:WINDOW // 2] == [0.01] * (WINDOW // 2)
    assert periods[WINDOW // 2] == 0.05 and periods[-1] == 0.05
    assert [c for c in changes if c] == [(0.01, 0.05)]
