"""Online tuning of the predictor: the shipped gain on a base it was not told about measures
the base's latency and lags and compensates them; on the paper's ideal plant it changes
nothing, bit for bit; the policy keeps the residual on the certified (delay) side."""
import math

import numpy as np
import pytest

from nonfragile_tracker.control.identification.errors import MonitorError
from nonfragile_tracker.control.identification.monitor import LatencyEstimate, MonitorSettings
from nonfragile_tracker.control.identification.tuning import (Tuned, TuningSettings,
                                                              tuned_prediction)
from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.control.simulation.plant import PlantConfig
from nonfragile_tracker.control.simulation.tracker import Tracker, TrackerConfig
from nonfragile_tracker.control.simulation.reference import figure_eight
from nonfragile_tracker.control.simulation.simulate import simulate_tracking

from conftest import CONFIG

K = read_gain_file(CONFIG / 'tracker_gains.yaml')


def _estimate(latency, half=0.005, lag_v=0.05, lag_w=0.04):
    return LatencyEstimate(True, 'ok', latency=latency,
                           interval=(latency - half, latency + half), lag_v=lag_v, lag_w=lag_w)


def test_the_policy_under_predicts_by_the_uncertainty_and_clamps():
    s = TuningSettings(max_latency=0.5, max_lag=0.05, step=0.005)
    # the uncertainty is the larger of the half interval and the tolerance (10 ms)
    assert tuned_prediction(_estimate(0.1), (0.0, 0.0, 0.0), s) == pytest.approx(
        (0.09, 0.05, 0.04))
    assert tuned_prediction(_estimate(0.1, half=0.02), (0.0, 0.0, 0.0), s)[0] == \
        pytest.approx(0.08)
    # never below 0, never above max_latency; lags within max_lag
    assert tuned_prediction(_estimate(0.004), (0.05, 0.0, 0.0), s)[0] == 0.0
    assert tuned_prediction(_estimate(0.9), (0.0, 0.0, 0.0), s)[0] == 0.5
    assert tuned_prediction(_estimate(0.1, lag_v=0.2), (0.0, 0.0, 0.0), s)[1] == 0.05
    # a channel without a lag keeps the current one; no change below the step; invalid: None
    assert tuned_prediction(_estimate(0.1, lag_w=math.nan), (0.0, 0.0, 0.03), s)[2] == 0.03
    assert tuned_prediction(_estimate(0.1), (0.092, 0.048, 0.041), s) is None
    assert tuned_prediction(LatencyEstimate(False, 'no excitation'), (0.0, 0.0, 0.0), s) is None
    with pytest.raises(MonitorError, match='period'):
        TuningSettings(period=0.0)


def test_a_lag_beyond_max_lag_is_predicted_as_latency_and_an_unexcited_channel_borrows():
    s = TuningSettings(max_latency=0.5, max_lag=0.05, step=0.005)
    # w's lag 100 ms, 50 ms of it not inverted: a delay of 50 ms at low frequency
    assert tuned_prediction(_estimate(0.005, lag_v=math.nan, lag_w=0.1), (0.0, 0.0, 0.0),
                            s) == pytest.approx((0.045, 0.0, 0.05))   # v: kept (measured)
    # the smaller excess of the channels (never over-predict the less lagging one)
    assert tuned_prediction(_estimate(0.1, lag_v=0.2, lag_w=0.07), (0.0, 0.0, 0.0),
                            s)[0] == pytest.approx(0.11)
    # v never excited (a straight at constant speed): it takes w's lag, until measured once
    assert tuned_prediction(_estimate(0.1, lag_v=math.nan, lag_w=0.03), (0.0, 0.0, 0.0), s,
                            measured=(False, True)) == pytest.approx((0.09, 0.03, 0.03))
    assert tuned_prediction(_estimate(0.1, lag_v=math.nan, lag_w=0.03), (0.0, 0.01, 0.0), s,
                            measured=(True, True))[1] == pytest.approx(0.01)


def _base(latency):
    path = figure_eight(radius=1.0, rate=0.3)
    r0 = path.sample(0.0)
    return path, PlantConfig(dt=0.01, x0=r0.x, y0=r0.y, th0=r0.heading,
                             v0=math.hypot(r0.vx, r0.vy), cmd_latency=latency, lag_v=0.05,
                             lag_w=0.05, odom_rate=50.0, odom_noise=(0.001, 0.001, 0.001),
                             noise_seed=3)


def _tuned(made):
    def make(config):
        t = Tuned(Tracker(config), MonitorSettings(max_linear_speed=config.max_linear_speed,
                                                   max_angular_speed=config.max_angular_speed))
        made.append(t)
        return t
    return make


def test_the_shipped_gain_measures_and_compensates_a_base_it_was_not_told_about():
    path, plant = _base(0.1)
    tc = TrackerConfig(K=K)
    made = []
    tuned = simulate_tracking(plant, tc, path, 3000, controller=_tuned(made))
    plain = simulate_tracking(plant, tc, path, 3000)
    told = simulate_tracking(plant, TrackerConfig(K=K, predict_latency=0.1, predict_lag_v=0.05,
                                                  predict_lag_w=0.05), path, 3000)
    c = made[0].tracker.config
    # the latency within the estimator's uncertainty below the truth, the lags the base's
    assert 0.08 <= c.predict_latency <= 0.1 and made[0].changes >= 1
    assert c.predict_lag_v == pytest.approx(0.05, abs=0.01)
    assert c.predict_lag_w == pytest.approx(0.05, abs=0.01)
    rms = [float(np.sqrt(np.mean(r.error[1500:] ** 2))) for r in (plain, tuned, told)]
    # far closer than the shipped gain alone, and within 50 % of a tracker told the truth
    assert rms[1] < 0.2 * rms[0], rms
    assert rms[1] < 1.5 * rms[2] + 2e-4, rms
    again = simulate_tracking(plant, tc, path, 3000, controller=_tuned([]))
    assert np.array_equal(again.cmd_w, tuned.cmd_w)         # deterministic: on the stamps


def test_on_the_ideal_plant_tuning_changes_nothing():
    from nonfragile_tracker.control.simulation.reference import circle
    from nonfragile_tracker.interface.scenario import paper_plant_config
    pc = paper_plant_config()
    tc = TrackerConfig(K=K, A_tau=pc.A_tau, tau=pc.tau)
    made = []
    tuned = simulate_tracking(pc, tc, circle(), 3000, controller=_tuned(made))
    plain = simulate_tracking(pc, tc, circle(), 3000)
    assert made[0].changes == 0 and made[0].tracker.predictor is None
    assert np.array_equal(tuned.cmd_v, plain.cmd_v) and np.array_equal(tuned.cmd_w, plain.cmd_w)


def test_a_tuned_tracker_copies_with_its_window_and_estimate():
    """A replay forks the tracker for trial runs (deepcopy) and may pickle it: the copy
    carries the samples, the estimate and the tuned prediction, with a lock and a stop
    signal of its own and no thread, and then runs on exactly as the original does."""
    import copy
    import pickle
    path, plant = _base(0.1)
    made = []
    simulate_tracking(plant, TrackerConfig(K=K), path, 800, controller=_tuned(made))
    t = made[0]
    assert t.changes >= 1 and t.latest is not None and t.predictor is t.tracker.predictor
    t.worker.start()                      # a running thread is not copied
    try:
        copies = [copy.deepcopy(t), pickle.loads(pickle.dumps(t))]
    finally:
        t.worker.stop()
    cmd, odom = t.worker.window.arrays()
    for c in copies:
        assert c.worker._thread is None and c.worker._stop is not t.worker._stop
        assert c.worker.window._lock is not t.worker.window._lock
        c2, o2 = c.worker.window.arrays()
        assert np.array_equal(c2, cmd) and np.array_equal(o2, odom)
        c.worker.window.add_odometry(odom[0, -1] + 0.01, 0.0, 0.0)   # its own samples and lock
        assert c.config == t.config and c.changes == t.changes and c.latest == t.latest
    assert np.array_equal(t.worker.window.arrays()[1], odom)     # the original untouched
    # the copies and the original step alike from here (the window and timing carried)
    twin = copy.deepcopy(t)
    r = path.sample(8.0)
    a = [t.step(r.x, r.y, r.heading, path.sample(8.0 + k * 0.02), 0.3, 8.0 + k * 0.02,
                measured_rate=0.1) for k in range(120)]
    b = [twin.step(r.x, r.y, r.heading, path.sample(8.0 + k * 0.02), 0.3, 8.0 + k * 0.02,
                   measured_rate=0.1) for k in range(120)]
    assert a == b and twin.config == t.config


def test_the_wrapper_exposes_the_law_settings_and_predictor():
    law = Tracker(TrackerConfig(K=K, predict_latency=0.05))
    t = Tuned(law)
    assert t.config is law.config and t.predictor is law.predictor is not None
    t.config = TrackerConfig(K=K, predict_latency=0.05, max_linear_speed=0.7)
    assert law.config.max_linear_speed == 0.7


@pytest.mark.parametrize('latency', [0.0, 0.02])
def test_a_retune_that_makes_the_predictor_does_not_kick_the_command(latency):
    """The first retune gives a tracker without a predictor one (lags inverted from then on):
    its actuator model starts at the last command, so the yaw-rate command moves as it does
    from step to step before (it jumped 1.5 rad/s in one 10 ms step when the model started
    at a yaw rate of 0)."""
    path, plant = _base(latency)
    plant = PlantConfig(**{**plant.__dict__, 'odom_rate': 100.0, 'odom_noise': (0.0,) * 3})
    made, steps, at = [], [], []

    def make(config):
        t = _tuned(made)(config)
        retune, step = t.tracker.retune, t.step

        def logged_retune(*a):
            at.append(len(steps))
            retune(*a)

        def logged_step(*a, **k):
            cmd = step(*a, **k)
            steps.append(cmd.w)
            return cmd
        t.tracker.retune = logged_retune
        t.step = logged_step
        return t
    simulate_tracking(plant, TrackerConfig(K=K), path, 800, controller=make)
    assert at and made[0].tracker.config.predict_lag_w > 0.0
    dw = np.abs(np.diff(steps))
    i = at[0]
    before, after = dw[100:i - 1].max(), dw[i - 1:i + 5].max()
    assert after <= 5.0 * before, (after, before)


def test_a_tuning_script_reads_back_exactly_and_bad_text_is_refused():
    from nonfragile_tracker.control.identification.tuning import format_script, parse_script
    script = ((1_796_191_467_123_456_789, 0.0897, 0.05, 0.04), (1_796_191_468_000_000_001,
                                                                 0.1 / 3, 0.0, 0.05))
    assert parse_script(format_script(script)) == script
    assert parse_script('') == () and parse_script(' ; ') == ()
    for bad, what in (('12 0.1 0.05', 'not "stamp_ns'), ('1.5 0.1 0.05 0.05', 'not "stamp_ns'),
                      ('12 -0.1 0.05 0.05', 'finite numbers >= 0'),
                      ('12 nan 0.05 0.05', 'finite numbers >= 0')):
        with pytest.raises(MonitorError, match=what):
            parse_script(bad)
    # a scripted tuning applies each entry at the first step stamped at or after it
    path, plant = _base(0.1)
    settings = TuningSettings(script=((int(2.0e9), 0.08, 0.05, 0.05),))
    made = []

    def make(config):
        made.append(Tuned(Tracker(config), settings=settings))
        return made[-1]
    simulate_tracking(plant, TrackerConfig(K=K), path, 400, controller=make)
    t = made[0]
    assert t.changes == 1 and t.last_change == (int(2.0e9), 0.08, 0.05, 0.05)
    assert (t.config.predict_latency, t.config.predict_lag_w) == (0.08, 0.05)


def test_a_new_time_base_restarts_the_tuning_clock():
    """The tracker node's input rules step the law by odometry stamp on reference samples
    (absolute stamps, about 1.8e9 s) until a trajectory comes, then by the trajectory's own
    time (from 0): through the nodes in real time the trajectory came after a few such steps,
    the tuning's next estimate stayed due at 1.8e9 s and the shipped tracker never tuned in
    40 s (2.5 mm on the eight against 0.55 tuned).  Now a step back in time (or beyond
    MAX_INTERVAL) starts the window and the clock again: the same base tuned as if the
    first steps had not been."""
    path, plant = _base(0.1)
    tc = TrackerConfig(K=K)

    def run(prelude):
        t = Tuned(Tracker(tc), MonitorSettings(max_linear_speed=1.0, max_angular_speed=2.0))
        r = path.sample(0.0)
        for k in range(prelude):                       # steps on the absolute stamps
            s = 1_796_234_977_000_000_000 + k * 20_000_000
            t.step(r.x, r.y, r.heading, r._replace(t=s * 1e-9), 0.28, stamp=s * 1e-9,
                   stamp_ns=s, measured_rate=0.0)
        t.reset()
        made = [t]
        simulate_tracking(plant, tc, path, 1500, controller=lambda c: made[0])
        return t
    fresh, late = run(0), run(8)
    assert fresh.changes >= 1 and late.changes == fresh.changes, (fresh.changes, late.changes)
    assert late.tracker.config.predict_latency == pytest.approx(
        fresh.tracker.config.predict_latency, abs=0.01)
    assert late.tracker.config.predict_lag_w == pytest.approx(
        fresh.tracker.config.predict_lag_w, abs=0.01)
