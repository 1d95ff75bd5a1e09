"""The certificate monitor (control.identification.monitor): the estimator recovers the latency within one
plant step, its gates reject saturated, limit-binding and gap segments, the status moves
OK -> WARN -> ERROR at the thresholds, the certificate comes from the gain file's record,
adaptation clamps; and the plant's latency schedule that the tests and benchmark use."""
import math

import numpy as np
import pytest

from nonfragile_tracker.control.simulation.errors import LoopConfigError
from nonfragile_tracker.control.simulation.plant import PlantConfig, UnicyclePlant
from nonfragile_tracker.control.simulation.timing import step_time
from nonfragile_tracker.control.identification.monitor import (ERROR, OK, STALE, WARN, Certificate,
                                                               LatencyEstimate, MonitorError,
                                                               MonitorSettings, MonitorWorker,
                                                               adapted_prediction,
                                                               certificate_from_design,
                                                               certificate_from_parameters,
                                                               estimate_latency, evaluate)

DT = 0.01            # plant step: the precision asked for


def steps_run(L, *, lag_v=0.05, lag_w=0.04, acc=(0.0, 0.0), duration=10.0, seed=0,
              hold=0.3, vmax=0.5, wmax=1.5, noise=(0.003, 0.01)):
    """Open-loop random steps through the package's plant: commands and odometry twist."""
    rng = np.random.default_rng(seed)
    p = UnicyclePlant(PlantConfig(dt=DT, cmd_latency=L, lag_v=lag_v, lag_w=lag_w,
                                  max_linear_accel=acc[0], max_angular_accel=acc[1],
                                  odom_rate=50.0))
    cmds, odom = [], []
    v = w = 0.0
    for k in range(int(round(duration / DT))):
        if k % int(round(hold / DT)) == 0:
            v, w = rng.uniform(-vmax, vmax), rng.uniform(-wmax, wmax)
        m = p.odometry()
        if m is not None:
            odom.append((step_time(m.step, DT), m.v + noise[0] * rng.standard_normal(),
                         m.w + noise[1] * rng.standard_normal()))
        if k % 2 == 0:                           # a command every 20 ms
            p.command(v, w)
            cmds.append((step_time(k, DT), v, w))
        p.advance()
    return np.array(cmds).T, np.array(odom).T


@pytest.mark.parametrize('L', [0.07, 0.13, 0.25])
def test_latency_recovered_within_one_plant_step(L):
    c, o = steps_run(L)
    est = estimate_latency(*c, *o)
    assert est.valid and est.reason == ''
    assert abs(est.latency - L) <= DT
    assert est.interval[0] <= L <= est.interval[1]
    assert abs(est.lag_v - 0.05) <= 0.2 * 0.05 and abs(est.lag_w - 0.04) <= 0.2 * 0.04
    assert est.r2 > 0.99 and est.confidence > 0.9 and est.excluded == {}


def test_saturated_commands_are_excluded_and_named():
    """Commands at the tracker's limit: the samples they can act on are left out (per
    channel); with w saturated throughout only v is used, and the estimate stays right."""
    c, o = steps_run(0.12, seed=1)
    sat = MonitorSettings(max_angular_speed=1.0)             # |w| up to 1.5 is commanded
    est = estimate_latency(*c, *o, sat)
    assert est.excluded['w saturated'] > 0 and 'v saturated' not in est.excluded
    assert est.valid and abs(est.latency - 0.12) <= DT
    c2 = c.copy()
    c2[2] = np.sign(c2[2]) * 1.0                            # every w command at the limit
    est = estimate_latency(*c2, *o, sat)
    assert est.channels == ('v',) and 'w: 100 % of the window excluded' in est.reason
    assert abs(est.latency - 0.12) <= DT


def test_binding_acceleration_limits_are_gated_not_believed():
    """Limits binding (1 m/s^2, 3 rad/s^2; steps up to 0.3 m/s, 0.8 rad/s on 80/50 ms lags):
    without the limits the fit is biased well beyond a step, the lags pinned at 0.13-0.2 s;
    with them the binding segments are excluded and the monitor refuses (no estimate)
    rather than report a wrong latency."""
    c, o = steps_run(0.12, lag_v=0.08, lag_w=0.05, acc=(1.0, 3.0), hold=0.5, vmax=0.3,
                     wmax=0.8)
    blind = estimate_latency(*c, *o, MonitorSettings())
    assert blind.valid and abs(blind.latency - 0.12) > 2 * DT       # believed and wrong
    assert blind.lag_v > 0.12 and blind.lag_w > 0.1
    gated = estimate_latency(*c, *o, MonitorSettings(max_linear_accel=1.0,
                                                     max_angular_accel=3.0))
    assert gated.excluded['v acceleration limit'] > 100
    assert gated.excluded['w acceleration limit'] > 100
    assert not gated.valid and 'not observable' in gated.reason
    assert evaluate(gated, Certificate((0.0, 0.2), 0.05, None), 0.1).level == STALE


def test_odometry_gap_is_excluded():
    """0.4 s without odometry (a stalled driver): the samples around it are excluded and
    the estimate stays within a step; a window of nothing but gaps is refused."""
    c, o = steps_run(0.1, seed=2)
    keep = ~((o[0] >= 7.0) & (o[0] < 7.4))
    est = estimate_latency(*c, *o[:, keep])
    assert est.excluded['odometry gap'] >= 10
    assert est.valid and abs(est.latency - 0.1) <= DT
    few = estimate_latency(*c, *o[:, :8])
    assert not few.valid and 'too little data' in few.reason


def test_no_excitation_and_short_windows_give_no_estimate():
    c, o = steps_run(0.1, seed=3)
    flat = c.copy()
    flat[1:] = 0.2
    est = estimate_latency(*flat, *o)
    assert not est.valid and 'command varies too little' in est.reason
    short = estimate_latency(*c[:, :50], *o[:, o[0] < 1.0])
    assert not short.valid and 'window not filled' in short.reason


def estimate(L, lag=0.05, width=0.004):
    return LatencyEstimate(True, '', t_end=10.0, latency=L,
                           interval=(L - width / 2, L + width / 2), lag_v=lag, lag_w=lag,
                           r2=0.99, confidence=0.99, valid_fraction=1.0, channels=('v', 'w'))


def test_status_transitions_at_the_thresholds():
    """Certified delay [0, 0.15] s, hold 0.02 s, predictor 0.1 s: latency certified in
    [0.1, 0.23] s; WARN from 0.21 s (margin 0.02 s), ERROR above 0.23 s and below
    0.1 - 0.01 s (over-prediction beyond the estimator's tolerance)."""
    cert = Certificate(residual=(0.0, 0.15), lag=0.05, adapt_range=(0.09, 0.11), hold=0.02)
    s = MonitorSettings(warn_margin=0.02, tolerance=0.01)
    levels = {L: evaluate(estimate(L), cert, 0.1, s).level
              for L in (0.095, 0.1, 0.15, 0.205, 0.215, 0.229, 0.235, 0.3, 0.085)}
    assert levels == {0.095: OK, 0.1: OK, 0.15: OK, 0.205: OK, 0.215: WARN, 0.229: WARN,
                      0.235: ERROR, 0.3: ERROR, 0.085: ERROR}
    err = evaluate(estimate(0.25), cert, 0.1, s, adapting=True)
    assert 'latency 250 ms' in err.message and 'certified [100 ms, 230 ms]' in err.message
    assert 'cannot adapt' in err.message and '[90 ms, 110 ms]' in err.message
    assert 'latency-design' in err.message                  # the command to run
    assert err.values['certified latency (s)'] == '[0.1000, 0.2300]'
    assert 'below (over-prediction)' in evaluate(estimate(0.085), cert, 0.1, s).message
    # OK says what was compared: the residual L - P plus the hold against [h_min, H]
    assert evaluate(estimate(0.15), cert, 0.1, s).message == (
        'latency 150 ms (interval 148 ms-152 ms): residual 50 ms (latency - predict_latency '
        '100 ms) plus the hold 0 to 20 ms: 50 ms to 70 ms, inside the certified delay '
        '[0 ms, 150 ms] (latency certified in [100 ms, 230 ms])')
    # below P + h_min within the estimator's tolerance: certified, and not called "inside"
    low = evaluate(estimate(0.095), cert, 0.1, s).message
    assert 'inside' not in low and ('residual -5 ms' in low and '5 ms below the lower end of '
                                    'the certified delay [0 ms, 150 ms], within the '
                                    "estimator's tolerance 10 ms" in low)
    # the lag estimate is coarser (closed loop: up to twice the truth seen): WARN above
    # (1 + lag_tolerance) x the certified lag + tolerance = 0.11 s
    assert evaluate(estimate(0.12, lag=0.1), cert, 0.1, s).level == OK
    lag = evaluate(estimate(0.12, lag=0.13), cert, 0.1, s)
    assert lag.level == WARN and 'actuator lag 130 ms above the certified 50 ms' in lag.message
    assert evaluate(None, cert, 0.1).level == STALE
    assert evaluate(LatencyEstimate(False, 'window not filled yet'), cert, 0.1).message == \
        'latency unknown: window not filled yet'
    unknown = evaluate(estimate(0.1), None, 0.1)
    assert unknown.level == STALE and 'records none' in unknown.message


def test_adaptation_moves_the_prediction_and_clamps():
    cert = Certificate(residual=(0.0, 0.15), lag=0.05, adapt_range=(0.09, 0.3), hold=0.02)
    s = MonitorSettings(tolerance=0.01)
    # estimate 0.25 s (ERROR for P = 0.1): P = L - (r_lo + u) = 0.25 - 0.01, OK again
    assert evaluate(estimate(0.25), cert, 0.1, s).level == ERROR
    P = adapted_prediction(estimate(0.25), cert, 0.1, s)
    assert P == pytest.approx(0.24)
    assert evaluate(estimate(0.25), cert, P, s).level == OK
    assert adapted_prediction(estimate(0.45), cert, 0.1, s) == 0.3         # clamped
    # inside the OK band [P - tolerance, P + 0.13 - margin]: no change (hysteresis)
    assert adapted_prediction(estimate(0.104), cert, 0.1, s) == 0.1
    assert adapted_prediction(estimate(0.2), cert, 0.1, s) == 0.1
    assert adapted_prediction(estimate(0.22), cert, 0.1, s) == pytest.approx(0.21)
    assert adapted_prediction(estimate(0.08), cert, 0.1, s) == pytest.approx(0.09)  # clamp
    assert adapted_prediction(LatencyEstimate(False, 'x'), cert, 0.1, s) == 0.1
    narrow = Certificate(residual=(0.0, 0.03), lag=0.0, adapt_range=(0.0, 1.0), hold=0.02)
    # certified residual [0, 0.01] narrower than 2u: the estimate is put in its middle
    assert adapted_prediction(estimate(0.2), narrow, 0.1, s) == pytest.approx(0.195)


def test_certificate_from_the_gain_files_record():
    plan = {'latency_interval': [0.0, 0.03], 'actuator_lag': 0.05, 'certified_h_max': 0.2,
            'lag_certified_h_max': 0.148, 'identified_latency_interval': [0.098, 0.101],
            'identified_command_age': [0.002, 0.006], 'compensation': 'predictor'}
    cert = certificate_from_design(plan, hold=0.02)
    # the lag's certificate, less the odometry-age spread; the hold at the tracker's dt
    assert cert.residual == pytest.approx((0.0, 0.144)) and cert.lag == 0.05
    assert cert.interval(0.098) == pytest.approx((0.098, 0.222))
    assert cert.adapt_range == (0.098, 0.101)
    params = cert.parameters()
    back = certificate_from_parameters(params['certified_residual'], params['certified_lag'],
                                       params['certified_adapt_range'], hold=0.02)
    assert back.residual == cert.residual and back.adapt_range == cert.adapt_range
    theorem1 = certificate_from_design({'certified_latency': 0.193}, hold=0.01)
    assert theorem1.residual == (0.0, 0.193) and theorem1.lag == 0.0
    assert theorem1.adapt_range is None
    assert certificate_from_design({'actuator_lag': 0.05, 'certified_h_max': 0.2}, 0.02) \
        is None                                            # the lag was not certified
    assert certificate_from_design(None, 0.02) is None
    assert certificate_from_parameters(None, 0.0, None) is None
    with pytest.raises(MonitorError, match='certified_residual must be'):
        certificate_from_parameters([0.2, 0.1], 0.0, None)
    with pytest.raises(MonitorError, match='latency_interval'):
        certificate_from_design({'certified_h_max': 0.2, 'latency_interval': 'x'}, 0.02)


@pytest.mark.parametrize('bad, match', [
    (dict(window=0.0), 'window'), (dict(resolution=0.1), 'resolution'),
    (dict(min_excitation=(0.1,)), 'min_excitation'), (dict(min_r2=1.5), 'min_r2'),
    (dict(max_linear_accel=-1.0), 'max_linear_accel'), (dict(tolerance=math.nan), 'tolerance'),
])
def test_settings_are_validated(bad, match):
    with pytest.raises(MonitorError, match=match):
        MonitorSettings(**bad)


def test_worker_estimates_in_its_own_thread():
    c, o = steps_run(0.1, seed=4)
    worker = MonitorWorker(MonitorSettings(), period=0.01)
    for t, v, w in c.T:
        worker.window.add_command(t, v, w)
    for t, v, w in o.T:
        worker.window.add_odometry(t, v, w)
    worker.start()
    try:
        deadline = 200
        while worker.estimates == 0 and deadline:
            import time
            time.sleep(0.01)
            deadline -= 1
    finally:
        worker.stop()
    assert worker.estimates >= 1 and abs(worker.latest.latency - 0.1) <= DT


def test_plant_latency_schedule():
    """From 0.05 s the latency is 5 steps, from 0.1 s none: a command at step k acts from
    k + 2, then k + 5; the latency drop skips the queued commands (the newest acts)."""
    p = UnicyclePlant(PlantConfig(dt=DT, cmd_latency=0.02,
                                  cmd_latency_schedule=[0.05, 0.05, 0.1, 0.0]))
    acted = []
    for k in range(15):
        p.command(float(k), 0.0)
        p.advance()
        acted.append(p.cmd[0])
    assert acted == [0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 4.0, 4.0, 4.0, 4.0, 10.0, 11.0, 12.0,
                     13.0, 14.0]
    # default: no schedule, the plant is unchanged
    assert PlantConfig().cmd_latency_schedule == ()


@pytest.mark.parametrize('bad, match', [
    ([0.1], 'pairs'), ([1.0, 0.1, 0.5, 0.2], 'must increase'), ([0.005, 0.1], 'multiple'),
    (['a', 0.1], r'cmd_latency_schedule\[0\]'), ([1.0, -0.1], '>= 0'), ('1.0', 'flat list'),
])
def test_plant_latency_schedule_is_validated(bad, match):
    with pytest.raises(LoopConfigError, match=match):
        PlantConfig(dt=DT, cmd_latency_schedule=bad)


def at_rest_after(moving, L=0.1, lag=0.04, duration=12.0, seed=0):
    """Random steps for ``moving`` s, then zero commands (the robot stands still)."""
    rng = np.random.default_rng(seed)
    p = UnicyclePlant(PlantConfig(dt=DT, cmd_latency=L, lag_v=lag, lag_w=lag, odom_rate=50.0))
    cmds, odom = [], []
    v = w = 0.0
    for k in range(int(round(duration / DT))):
        if k % 30 == 0:
            v, w = rng.uniform(-0.5, 0.5), rng.uniform(-1.5, 1.5)
        if k * DT >= moving:
            v = w = 0.0
        m = p.odometry()
        if m is not None:
            odom.append((step_time(m.step, DT), m.v + 0.003 * rng.standard_normal(),
                         m.w + 0.01 * rng.standard_normal()))
        if k % 2 == 0:
            p.command(v, w)
            cmds.append((step_time(k, DT), v, w))
        p.advance()
    return np.array(cmds).T, np.array(odom).T


def test_a_robot_at_rest_is_stale_never_warn():
    """Issue 30 item 5: after the motion ends and the robot stands still, every window is
    OK (its latest half still moving) or STALE (at rest: no excitation), never WARN or
    ERROR; from half a window after the stop the reason says there is no excitation."""
    c, o = at_rest_after(6.0)
    cert = Certificate((0.0, 0.15), 0.041, None, hold=0.02)
    s = MonitorSettings()
    seen = {}
    for end in np.arange(6.0, 12.0, 0.25):
        est = estimate_latency(*c[:, c[0] <= end], *o[:, o[0] <= end], s)
        st = evaluate(est, cert, 0.0, s)
        assert st.level in (OK, STALE), (end, st.message)
        seen[round(float(end), 2)] = st
        if 6.0 + 0.5 * s.window + 0.2 <= end < 6.0 + s.window:   # latest half at rest
            assert st.level == STALE and 'no excitation in the last 2 s' in st.message
        elif end >= 6.0 + s.window:                 # the whole window at rest
            assert st.level == STALE and 'command varies too little' in st.message
    assert seen[6.0].level == OK                    # while it moved: an estimate
    # standing still from the start: commands all zero
    z = c.copy()
    z[1:] = 0.0
    st = evaluate(estimate_latency(*z, *o, s), cert, 0.0, s)
    assert st.level == STALE
