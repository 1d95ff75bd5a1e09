"""The tracker's channel-gain compensation (TrackerConfig gain_v, gain_w): off by default and
then bit-identical, the command sent is the law's motion over the gain, bad gains and the
batch refuse; the limits are the command's and the law works within them times the
gains.  On a skid-steer it is what makes the figure eight track (test_physics.py)."""
from __future__ import annotations

import numpy as np
import pytest

from conftest import CONFIG
from nonfragile_tracker.control.simulation.batch import simulate_batch
from nonfragile_tracker.control.simulation.errors import BatchError, LoopConfigError
from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.control.simulation.plant import PlantConfig
from nonfragile_tracker.control.simulation.tracker import Tracker, TrackerConfig
from nonfragile_tracker.control.simulation.reference import figure_eight
from nonfragile_tracker.control.simulation.simulate import simulate_tracking
from nonfragile_tracker.interface.tracker_inputs import input_rules

K = read_gain_file(CONFIG / 'tracker_gains.yaml')


def _commands(tc: TrackerConfig, steps: int = 200):
    """Commands of the tracker on a figure eight measured at the reference plus an offset."""
    path = figure_eight(radius=1.0, rate=0.2)
    tracker = Tracker(tc)
    out = []
    for k in range(steps):
        ref = path.sample(0.01 * k)
        out.append(tracker.step(ref.x + 0.01, ref.y - 0.005, ref.heading + 0.02, ref, 0.2,
                                stamp=ref.t))
    return out


@pytest.mark.parametrize('extra', [{}, dict(predict_latency=0.05, predict_lag_v=0.04,
                                            predict_lag_w=0.04, max_linear_accel=1.0,
                                            max_angular_accel=3.0)])
def test_gains_of_one_change_nothing_bit_for_bit(extra):
    plain = _commands(TrackerConfig(K=K, **extra))
    ones = _commands(TrackerConfig(K=K, gain_v=1.0, gain_w=1, **extra))
    assert plain == ones
    assert not TrackerConfig(K=K).compensates and TrackerConfig(K=K, gain_w=0.6).compensates


@pytest.mark.parametrize('extra', [{}, dict(predict_latency=0.05, predict_lag_v=0.04,
                                            predict_lag_w=0.04)])
def test_the_command_is_the_laws_motion_over_the_gain(extra):
    """The law, its limits and predictor run on the motion, within the command's limits
    times the gains; only the sent command is divided (the rest of each step - error,
    acceleration, flags - is that of the plain law within those motion limits).  The
    acceleration limits: the next test."""
    gains = dict(gain_v=0.98, gain_w=0.64)
    comp_config = TrackerConfig(K=K, **gains, **extra)
    m = comp_config.motion_limits
    motion = dict(extra, max_linear_speed=m.max_linear_speed,
                  max_angular_speed=m.max_angular_speed)
    plain = _commands(TrackerConfig(K=K, **motion))
    comp = _commands(comp_config)
    assert max(abs(c.w) for c in plain) > 0.1 and max(abs(c.w) for c in comp) < 2.0
    assert [c.v / 0.98 for c in plain] == [c.v for c in comp]
    assert [c.w / 0.64 for c in plain] == [c.w for c in comp]
    assert [c[2:] for c in plain] == [c[2:] for c in comp]


def test_a_base_with_those_gains_is_then_driven_as_without_them():
    """A kinematic base whose turn rate is 0.64 of its command, fed commands over 0.64,
    moves as the ideal base does under the plain tracker (to round-off)."""
    path = figure_eight(radius=1.0, rate=0.2)
    pc = PlantConfig(dt=0.01, th0=path.rest_heading, v0=0.2 * 2 ** 0.5)   # on the path
    ideal = simulate_tracking(pc, TrackerConfig(K=K), path, 1500)

    class TurnsSlow:
        def __init__(self, config):
            from nonfragile_tracker.control.simulation.plant import UnicyclePlant
            self.inner = UnicyclePlant(config)

        def __getattr__(self, name):
            return getattr(self.inner, name)

        def command(self, v, w):
            self.inner.command(v, 0.64 * w)

    slow = simulate_tracking(pc, TrackerConfig(K=K), path, 1500, plant=TurnsSlow)
    fixed = simulate_tracking(pc, TrackerConfig(K=K, gain_w=0.64), path, 1500,
                              plant=TurnsSlow)
    assert np.max(np.abs(fixed.cmd_w)) < 2.0             # no command clipped
    assert np.max(np.abs(fixed.x - ideal.x)) < 1e-9 and np.max(np.abs(fixed.y - ideal.y)) < 1e-9
    assert slow.error[1000:].min() > 5e-3 and ideal.error[1000:].max() < 5e-4   # 9.7, 0.10 mm


def test_the_command_sent_stays_within_the_speed_limits():
    """Divided by its gain a command may exceed the command limits (max_linear_speed,
    max_angular_speed, what cmd_vel may carry): it is clipped there and flagged saturated."""
    plain = _commands(TrackerConfig(K=K, max_angular_speed=0.5))
    comp = _commands(TrackerConfig(K=K, max_angular_speed=0.5, gain_w=0.25))
    assert max(abs(c.w) for c in comp) == 0.5
    clipped = [i for i, c in enumerate(comp) if abs(plain[i].w) / 0.25 > 0.5]
    assert clipped and all(comp[i].saturated and abs(comp[i].w) == 0.5 for i in clipped)


def test_the_limits_are_the_commands_and_the_motion_is_within_them_times_the_gains():
    """max_*_speed / max_*_accel are the command's (cmd_vel's, the firmware's ramp): a base
    turning at 0.64 of its command turns at most 0.64 of them (motion_limits: the law's
    clamps, the predictor's actuator model, the re-timer's limits); the rate limit holds the
    motion to the limit's number, so the command sent changes at up to max_angular_accel /
    0.64 (the firmware ramps it; at the firmware's own ramp a 100 Hz loop fell into a limit
    cycle)."""
    tc = TrackerConfig(K=K, gain_w=0.64, max_angular_speed=2.0, max_angular_accel=6.0,
                       max_linear_accel=1.5, predict_latency=0.05, predict_lag_w=0.05)
    m = tc.motion_limits
    assert (m.max_linear_speed, m.max_linear_accel) == (1.0, 1.5)
    assert m.max_angular_speed == pytest.approx(1.28) and \
        m.max_angular_accel == pytest.approx(3.84)
    assert TrackerConfig(K=K).motion_limits.max_angular_speed == 2.0
    rules = input_rules({'max_angular_speed': 2.0, 'max_angular_accel': 6.0, 'gain_w': 0.64,
                         'gain_v': 'bad'})
    assert rules.limits.max_angular_speed == pytest.approx(1.28)
    assert rules.limits.max_angular_accel == pytest.approx(3.84)
    assert rules.limits.max_linear_speed == 0.0            # not given: none (the bad gain: 1)
    # a turn the law asks for at once: the commands ramp at the command's limit
    path = figure_eight(radius=0.5, rate=0.6)
    tracker = Tracker(tc)
    assert tracker.predictor.actuator.max_angular_accel == pytest.approx(3.84)
    cmds = []
    for k in range(300):
        ref = path.sample(0.01 * k)
        cmds.append(tracker.step(ref.x, ref.y + 0.05 * (k > 100), ref.heading, ref, 0.3,
                                 stamp=ref.t).w)
    steps = np.abs(np.diff(cmds))
    assert steps.max() == pytest.approx(6.0 * 0.01 / 0.64, rel=1e-9)   # binds, and no more


@pytest.mark.parametrize('gains', [dict(gain_w=0.0), dict(gain_v=-1.0), dict(gain_w=float('nan')),
                                   dict(gain_v=True), dict(gain_w='0.6')])
def test_a_gain_that_is_not_a_positive_number_is_refused(gains):
    with pytest.raises(LoopConfigError, match='must be a finite number > 0'):
        TrackerConfig(K=K, **gains)


def test_the_batch_refuses_gain_compensation():
    with pytest.raises(BatchError, match='gain compensation'):
        simulate_batch(PlantConfig(), TrackerConfig(K=K, gain_w=0.6),
                       figure_eight(radius=1.0, rate=0.2), 10)
