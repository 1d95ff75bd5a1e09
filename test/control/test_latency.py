"""Plant latency model (command delay, actuator lag, acceleration limits, odometry latency,
rate and noise) against closed forms, and the tracker's latency predictor (ROS-free)."""
import math
import warnings

import numpy as np
import pytest

from nonfragile_tracker.control.simulation.actuator import ActuatorModel, first_order_step
from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.control.simulation.errors import LoopConfigError
from nonfragile_tracker.control.simulation.plant import PlantConfig, UnicyclePlant
from nonfragile_tracker.control.simulation.tracker import Tracker, TrackerConfig
from nonfragile_tracker.control.simulation.predictor import LatencyPredictor, extrapolate_reference
from nonfragile_tracker.control.simulation.reference import circle, figure_eight
from nonfragile_tracker.control.simulation.simulate import simulate_tracking

from nonfragile_tracker.interface.scenario import paper_plant_config

from conftest import CONFIG

NO_DELAY = dict(A_tau=np.zeros((4, 4)), tau=0.0)
AT_REST = dict(x0=0.0, y0=0.0, th0=0.0, v0=0.0, **NO_DELAY)


def rms_after(run, t0=10.0):
    e = run.error[run.t > t0]
    return float(np.sqrt(np.mean(e * e)))


# ------------------------------------------------------------------------------ plant pieces

def test_lag_step_response_is_the_exponential():
    T, dt = 0.05, 0.01
    p = UnicyclePlant(PlantConfig(dt=dt, lag_v=T, lag_w=2 * T, **AT_REST))
    for k in range(1, 31):
        p.step(1.0, 0.0)
        t = k * dt
        assert p.v == pytest.approx(1.0 - math.exp(-t / T), abs=1e-14)
        # distance = integral of the speed, exact per step: t - T (1 - e^{-t/T})
        assert p.x == pytest.approx(t - T * (1.0 - math.exp(-t / T)), abs=1e-14)
        assert p.y == 0.0 and p.w == 0.0
    q = UnicyclePlant(PlantConfig(dt=dt, lag_w=0.1, **AT_REST))
    for _ in range(20):
        q.step(0.0, 2.0)
    t = 0.2                                      # heading = integral of w, exact
    assert q.w == pytest.approx(2.0 * (1 - math.exp(-t / 0.1)), abs=1e-14)
    assert q.th == pytest.approx(2.0 * (t - 0.1 * (1 - math.exp(-t / 0.1))), abs=1e-14)


def test_command_latency_shifts_the_commands_by_whole_steps():
    dt, d = 0.01, 7
    cmds = [(0.3 + 0.1 * math.sin(0.2 * k), 0.5 * math.cos(0.1 * k)) for k in range(200)]
    late = UnicyclePlant(PlantConfig(dt=dt, cmd_latency=d * dt, v0=0.05, **NO_DELAY))
    ideal = UnicyclePlant(PlantConfig(dt=dt, v0=0.05, **NO_DELAY))
    held = [(0.05, 0.0)] * d + cmds                  # (v0, 0) until the first command acts
    for k in range(200):
        late.step(*cmds[k])
        ideal.step(*held[k])
        assert (late.x, late.y, late.th, late.v) == (ideal.x, ideal.y, ideal.th, ideal.v)
    assert late.cmd_delay == d
    # 0.034 s at dt 0.01 is rounded to 3 steps
    assert PlantConfig(dt=dt, cmd_latency=0.034).cmd_latency_steps == 3


def test_acceleration_limit_ramps_then_holds():
    dt, a = 0.01, 0.5
    p = UnicyclePlant(PlantConfig(dt=dt, max_linear_accel=a, max_angular_accel=4.0, **AT_REST))
    for k in range(1, 301):
        p.step(1.0, 0.0)
        t = k * dt
        assert p.v == pytest.approx(min(a * t, 1.0), abs=1e-12)
        x = 0.5 * a * t * t if t <= 2.0 else 1.0 + (t - 2.0)     # ramp 2 s, then 1 m/s
        assert p.x == pytest.approx(x, abs=1e-12)


@pytest.mark.parametrize('s, c, T, a, h', [
    (0.0, 1.0, 0.05, 2.0, 0.01),       # ramp throughout
    (0.0, 1.0, 0.05, 2.0, 0.6),        # ramp, then exponential tail
    (0.3, -0.2, 0.1, 20.0, 0.05),      # lag only (rate never reaches the limit)
    (0.5, 0.5, 0.1, 1.0, 0.02),        # at the command already
    (0.2, -1.0, 0.02, 5.0, 0.3),       # ramp down, then tail
])
def test_saturated_lag_matches_a_fine_integration(s, c, T, a, h):
    """Closed form vs RK4 of s' = sat((c - s)/T, a) with the integral as a second state."""
    end, mean = first_order_step(s, c, T, a, h)
    f = lambda x: max(-a, min(a, (c - x) / T))      # noqa: E731
    n = 20000
    dt = h / n
    x, area = s, 0.0
    for _ in range(n):
        k1 = f(x)
        k2 = f(x + 0.5 * dt * k1)
        k3 = f(x + 0.5 * dt * k2)
        k4 = f(x + dt * k3)
        area += dt * (x + dt * (k1 + k2 + k3) / 6.0)    # RK4 of the integral (x' = its rate)
        x += dt * (k1 + 2 * k2 + 2 * k3 + k4) / 6.0
    assert end == pytest.approx(x, abs=1e-9)
    assert mean == pytest.approx(area / h, abs=1e-7)


def test_odometry_decimation_latency_and_stamps():
    dt = 0.01
    p = UnicyclePlant(PlantConfig(dt=dt, odom_rate=20.0, odom_latency=0.03, v0=0.2,
                                  **NO_DELAY))
    assert p.config.odometry.period_steps == 5 and p.config.odometry.latency_steps == 3
    truth, published = {}, {}
    for k in range(60):
        truth[k] = (p.x, p.y, p.th)
        m = p.odometry()
        if m is not None:
            published[k] = m
        p.step(0.2, 0.3)
    assert sorted(published) == [k for k in range(60) if k >= 3 and (k - 3) % 5 == 0]
    for k, m in published.items():
        assert m.step == k - 3 and (m.x, m.y, m.th) == truth[k - 3]


def test_odometry_noise_statistics_and_seed():
    std = (0.01, 0.02, 0.03)

    def measurements(seed, n=20000):
        p = UnicyclePlant(PlantConfig(dt=0.01, odom_noise=std, noise_seed=seed, **AT_REST))
        out = []
        for _ in range(n):
            m = p.odometry()
            out.append((m.x, m.y, m.th))
            p.step(0.0, 0.0)
        return np.array(out)

    a = measurements(3)
    n = len(a)
    for j, s in enumerate(std):
        assert abs(a[:, j].mean()) < 4 * s / math.sqrt(n)
        assert a[:, j].std() == pytest.approx(s, rel=0.03)
    assert abs(np.corrcoef(a[:, 0], a[:, 1])[0, 1]) < 0.03
    np.testing.assert_array_equal(measurements(3, 500), a[:500])        # reproducible
    assert not np.array_equal(measurements(4, 500), a[:500])


@pytest.mark.parametrize('kwargs, message', [
    (dict(cmd_latency=-0.1), 'cmd_latency: expected a number >= 0'),
    (dict(lag_v=float('nan')), 'lag_v: expected a finite number'),
    (dict(odom_rate=500.0), 'above the plant rate'),
    (dict(odom_noise=(0.1, 0.1)), 'odom_noise needs 3'),
    (dict(odom_noise=(0.1, -0.1, 0.0)), r'odom_noise\[1\]: expected a number >= 0'),
    (dict(noise_seed=-1), 'noise_seed must be an integer >= 0'),
    (dict(noise_seed=True), 'noise_seed must be an integer >= 0'),
])
def test_plant_latency_settings_are_validated(kwargs, message):
    with pytest.raises(LoopConfigError, match=message):
        PlantConfig(**kwargs)


def test_tracker_predictor_settings_are_validated():
    K = read_gain_file(CONFIG / 'tracker_gains.yaml')
    with pytest.raises(LoopConfigError, match='predict_latency: expected a number >= 0'):
        TrackerConfig(K=K, predict_latency=-0.1)
    with pytest.raises(LoopConfigError, match='predict_lag_w: expected a finite number'):
        TrackerConfig(K=K, predict_lag_w=float('inf'))


# ------------------------------------------------------------------------------ predictor

def test_prediction_is_exact_with_exact_knowledge():
    """Commands through a late, lagging plant: the predicted pose at the act time equals
    the plant's pose at that step to round-off."""
    dt, dc, do = 0.01, 12, 4
    cfg = PlantConfig(dt=dt, cmd_latency=dc * dt, odom_latency=do * dt, odom_rate=50.0,
                      lag_v=0.05, lag_w=0.03, v0=0.1, **NO_DELAY)
    plant = UnicyclePlant(cfg)
    pred = LatencyPredictor(dc * dt, do * dt, ActuatorModel(0.05, 0.03), dt)
    predicted, poses = {}, {}
    for k in range(400):
        poses[k] = (plant.x, plant.y, plant.th)
        m = plant.odometry()
        if m is not None:
            p = pred.predict(m.x, m.y, m.th, m.step * dt, m.v)
            predicted[round(p.t / dt)] = (p.x, p.y, p.th)
            cv, cw = 0.3 + 0.2 * math.sin(0.05 * k), 0.8 * math.sin(0.03 * k)
            pred.record(p.t, cv, cw)
            plant.command(cv, cw)
        plant.advance()
    checked = [k for k in predicted if k in poses]
    assert len(checked) > 150
    err = max(max(abs(a - b) for a, b in zip(predicted[k], poses[k])) for k in checked)
    assert err < 1e-12


def test_reference_extrapolation_error_is_fourth_order():
    path = figure_eight(radius=1.0, rate=0.2)
    prev, ref = path.sample(4.98), path.sample(5.0)
    jerk = ((ref.ax - prev.ax) / 0.02, (ref.ay - prev.ay) / 0.02)
    for h, bound in ((0.1, 1e-7), (0.3, 1e-5)):
        got, want = extrapolate_reference(ref, 5.0 + h, jerk), path.sample(5.0 + h)
        assert abs(got.x - want.x) < bound and abs(got.y - want.y) < bound
        assert abs(got.vx - want.vx) < 20 * bound / h and abs(got.vy - want.vy) < 20 * bound / h


def test_zero_assumed_latency_is_todays_law_bit_for_bit():
    K = read_gain_file(CONFIG / 'tracker_gains.yaml')
    pc = paper_plant_config()
    plain = TrackerConfig(K=K)
    zero = TrackerConfig(K=K, predict_latency=0.0, predict_odom_latency=0.0,
                         predict_lag_v=0.0, predict_lag_w=0.0)
    assert not zero.predicts and Tracker(zero).predictor is None
    a = simulate_tracking(pc, plain, circle(), 2000)
    b = simulate_tracking(pc, zero, circle(), 2000)
    for name in ('x', 'y', 'th', 'cmd_v', 'cmd_w'):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert a.commanded.all()
    # the same floats as the law written out by hand for the first step
    t = Tracker(zero)
    ref = circle().sample(0.0)
    cmd = t.step(pc.x0, pc.y0, pc.th0, ref, pc.v0)
    Km = np.array(K)
    e = np.array([pc.x0 - ref.x, pc.v0 * math.cos(pc.th0) - ref.vx, pc.y0 - ref.y,
                  pc.v0 * math.sin(pc.th0) - ref.vy])
    u = np.array([ref.ax, ref.ay]) + Km @ e
    w = (u[1] * math.cos(pc.th0) - u[0] * math.sin(pc.th0)) / pc.v0
    assert cmd.w == pytest.approx(min(w, 2.0), rel=1e-14)


def issue_scenario(latency, assumed, *, noise=0.0, predict=True, duration=20.0):
    """Figure eight r = 1 m at 0.2 rad/s, 50 ms lag, odometry 50 Hz (issue 11), no A_tau."""
    pc = PlantConfig(dt=0.01, x0=0.0, y0=-0.1, th0=math.pi / 4, v0=0.0, cmd_latency=latency,
                     lag_v=0.05, lag_w=0.05, odom_rate=50.0, odom_noise=(noise, noise, noise),
                     noise_seed=1, **NO_DELAY)
    kw = dict(predict_latency=assumed, predict_lag_v=0.05, predict_lag_w=0.05) if predict \
        else {}
    tc = TrackerConfig(K=read_gain_file(CONFIG / 'tracker_gains.yaml'), dt=0.02, **kw)
    return simulate_tracking(pc, tc, figure_eight(radius=1.0, rate=0.2),
                             int(round(duration / 0.01)))


def test_predictor_with_exact_knowledge_removes_the_latency_error():
    without = rms_after(issue_scenario(0.2, 0.0, predict=False))
    exact = rms_after(issue_scenario(0.2, 0.2))
    assert without > 5e-3                  # about 11 mm: the latency costs centimetres
    assert exact < 0.3e-3                  # about 0.1 mm: reference extrapolation, lag inversion
    assert without / exact > 30
    off = rms_after(issue_scenario(0.2, 0.26))       # 30 % too long: still far better
    assert off < 4e-3 and off < without / 3


def test_simulation_reports_a_tracker_step_that_is_not_the_odometry_period():
    """A dt override that disagrees with the odometry is run as set and reported (as the
    node reports it on /diagnostics); dt = 0 (the default) and an agreeing one are not."""
    K = read_gain_file(CONFIG / 'tracker_gains.yaml')
    with pytest.warns(UserWarning, match=r'dt = 0.01 s is set but the odometry period is '
                                         r'0.0200 s \(50.0 Hz\)'):
        run = simulate_tracking(PlantConfig(odom_rate=50.0), TrackerConfig(K=K, dt=0.01),
                                circle(), 10)
    assert run.t.size == 11
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        simulate_tracking(PlantConfig(odom_rate=50.0), TrackerConfig(K=K), circle(), 10)
        simulate_tracking(PlantConfig(odom_rate=50.0), TrackerConfig(K=K, dt=0.02), circle(), 10)


def test_predicting_tracker_survives_garbage_and_stays_bounded():
    """Random and malformed samples into a tracker with the predictor: every command is
    finite and within its limits, and the command buffer stays bounded."""
    rng = np.random.default_rng(5)
    tc = TrackerConfig(K=read_gain_file(CONFIG / 'tracker_gains.yaml'), dt=0.02,
                       predict_latency=0.2, predict_odom_latency=0.04, predict_lag_v=0.05,
                       predict_lag_w=0.05)
    tracker = Tracker(tc)
    path = figure_eight(radius=1.0, rate=0.2)
    bad = [math.nan, math.inf, -math.inf, 1e308, -1e308, 0.0]
    for k in range(3000):
        t = 0.02 * k
        x, y, th = rng.normal(0, 3, size=3)
        if k % 7 == 0:
            x = bad[k % len(bad)]
        stamp = bad[(k // 11) % len(bad)] if k % 11 == 0 else t
        ref = path.sample(t)
        cmd = tracker.step(float(x), float(y), float(th), ref, float(rng.normal(0, 0.5)),
                           stamp=stamp)
        assert math.isfinite(cmd.v) and math.isfinite(cmd.w)
        assert abs(cmd.v) <= tc.max_linear_speed and abs(cmd.w) <= tc.max_angular_speed
    assert len(tracker.predictor._segs) < 20
