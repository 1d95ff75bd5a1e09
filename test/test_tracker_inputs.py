"""The tracker's input rules (nonfragile_tracker.interface.tracker_inputs), ROS-free: which odometry,
reference and trajectory message is taken or refused and why, and when a command is due.

Messages are plain namespaces with the ROS field names (the rules read fields by name, as
from rclpy and rosbags messages); test/nodes/test_tracker_input_rules.py checks that the
node and the bag replay decide alike on the same sequence."""
from __future__ import annotations

import math
from types import SimpleNamespace as NS

import pytest

from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.control.simulation.tracker import Tracker, TrackerConfig
from nonfragile_tracker.control.simulation.reference import circle
from nonfragile_tracker.errors import InputError
from nonfragile_tracker.control.identification.tuning import TuningSettings
from nonfragile_tracker.interface.tracker_inputs import (INPUT_DEFAULTS, MONITOR_DEFAULTS,
                                               REF_BUFFER, InputRules, Rejection,
                                               TrackerInputs, input_rules, monitor_settings,
                                               stale_inputs)

from conftest import CONFIG

MS = 1_000_000
T0 = 100 * 10 ** 9                     # a stamp well after 0 (ns)
REF = circle().sample(0.0)


@pytest.fixture(scope='module')
def config() -> TrackerConfig:
    return TrackerConfig(K=read_gain_file(CONFIG / 'tracker_gains.yaml'))


def _hdr(ns, frame='odom'):
    return NS(stamp=NS(sec=ns // 10 ** 9, nanosec=ns % 10 ** 9), frame_id=frame)


def _vec(x=0.0, y=0.0):
    return NS(x=x, y=y, z=0.0)


def _pose(x, y, th):
    if not math.isfinite(th):
        return NS(position=_vec(x, y), orientation=NS(x=0.0, y=0.0, z=th, w=1.0))
    return NS(position=_vec(x, y), orientation=NS(x=0.0, y=0.0, z=math.sin(th / 2),
                                                  w=math.cos(th / 2)))


def odom(ns, x=0.5, y=0.0, th=1.57, v=0.05, frame='odom'):
    return NS(header=_hdr(ns, frame), pose=NS(pose=_pose(x, y, th)),
              twist=NS(twist=NS(linear=_vec(v), angular=_vec())))


def refs(ns, r=REF, frame='odom'):
    return (NS(header=_hdr(ns, frame), pose=_pose(r.x, r.y, r.heading)),
            NS(header=_hdr(ns, frame), twist=NS(linear=_vec(r.vx, r.vy), angular=_vec())),
            NS(header=_hdr(ns, frame), accel=NS(linear=_vec(r.ax, r.ay), angular=_vec())))


def multidof(ns, points, frame='odom', dt=1.0):
    """A MultiDOFJointTrajectory through ``points`` (x, y, yaw), ``dt`` s apart."""
    pts = [NS(transforms=[NS(translation=_vec(x, y),
                             rotation=NS(x=0.0, y=0.0, z=math.sin(th / 2), w=math.cos(th / 2)))],
              velocities=[], accelerations=[],
              time_from_start=NS(sec=int(i * dt), nanosec=int(round(i * dt % 1 * 1e9))))
           for i, (x, y, th) in enumerate(points)]
    return NS(header=_hdr(ns, frame), joint_names=['base'], points=pts)


LINE = [(0.5 * i, 0.0, 0.0) for i in range(6)]       # 2.5 m along x in 5 s


def feed(inputs, ns, **odom_kw):
    """The three reference parts then the odometry of stamp ``ns``; the steps made due."""
    out = [inputs.reference(i, m) for i, m in enumerate(refs(ns))]
    out.append(inputs.odom(odom(ns, **odom_kw)))
    return [s for s in out if s is not None]


# ---------------------------------------------------------------------- odometry
def test_odometry_in_another_frame_is_refused_and_the_frame_is_a_parameter(config):
    inputs = TrackerInputs(config)
    assert inputs.accept_odom(odom(T0, frame='map')) is None
    assert inputs.ignored == {"odom in frame 'map' (expected 'odom')": 1}
    assert inputs.rejected == 1 and inputs.last_odom_stamp == -1
    world = TrackerInputs(config, input_rules({'odom_frame': 'world'}))
    assert world.accept_odom(odom(T0, frame='world')) == T0
    assert world.accept_odom(odom(T0 + 10 * MS)) is None        # 'odom' is wrong there
    assert world.ignored == {"odom in frame 'odom' (expected 'world')": 1}


def test_stamps_repeat_backwards_and_jump(config):
    seen: list[Rejection] = []
    jumps: list[float] = []
    inputs = TrackerInputs(config, on_reject=seen.append, on_jump=jumps.append)
    assert len(feed(inputs, T0)) == 1 and len(feed(inputs, T0 + 10 * MS)) == 1
    assert feed(inputs, T0 + 10 * MS) == [] and inputs.rejected == 0     # repeat: silent
    assert feed(inputs, T0 + 5 * MS) == [] and inputs.rejected == 1      # backwards
    assert seen == [Rejection('odom', 'odom stamp going backwards',
                              f'{T0 + 5 * MS} < {T0 + 10 * MS} ns')]
    assert str(seen[0]) == f'odom stamp going backwards ({T0 + 5 * MS} < {T0 + 10 * MS} ns)'
    assert inputs.ignored == {'odom stamp going backwards': 1}
    # 1.0 s (the default max_stamp_jump) ahead is no jump, 1.01 s is
    assert len(feed(inputs, T0 + 1010 * MS)) == 1 and inputs.jumps == 0
    inputs.tracker.v = 0.9                                   # a stale compensator
    (step,) = feed(inputs, T0 + 2020 * MS, v=0.05)
    assert inputs.jumps == 1 and jumps == [pytest.approx(1.01)]
    assert inputs.tracker.v == pytest.approx(0.05, abs=0.05)  # re-initialised from odom
    assert step.stamp == T0 + 2020 * MS


@pytest.mark.parametrize('change, reason', [
    (dict(x=math.nan), 'odom: non-finite pose'),
    (dict(th=math.inf), 'odom: non-finite pose'),
])
def test_a_non_finite_pose_is_refused_and_the_odometry_dropped(config, change, reason):
    inputs = TrackerInputs(config)
    assert feed(inputs, T0, **change) == []
    assert inputs.rejected == 1 and next(iter(inputs.ignored)).startswith(reason)
    assert inputs.odom_msg is None and inputs.last_stamp == -1
    assert inputs.last_odom_stamp == T0           # its stamp was taken: a repeat is ignored
    assert len(feed(inputs, T0 + 10 * MS)) == 1   # the next good one is answered


def test_a_non_unit_quaternion_is_refused(config):
    inputs = TrackerInputs(config)
    msg = odom(T0, th=0.0)
    msg.pose.pose.orientation.w = 0.5
    for i, m in enumerate(refs(T0)):
        inputs.reference(i, m)
    assert inputs.odom(msg) is None
    assert list(inputs.ignored) == ['odom: quaternion norm 0.5 is not 1']
    # an odometry taken before the samples were in is not answered again at its stamp
    late = TrackerInputs(config)
    assert late.odom(odom(T0)) is None
    for i, m in enumerate(refs(T0)):
        late.reference(i, m)
    assert late.odom(odom(T0)) is None and late.odom(odom(T0 + MS)) is not None


# ---------------------------------------------------------------------- reference samples
def test_reference_in_another_frame_and_non_finite_reference_are_refused(config):
    inputs = TrackerInputs(config)
    pose, twist, accel = refs(T0)
    assert not inputs.accept_reference(0, refs(T0, frame='map')[0])
    assert inputs.ignored == {"reference in frame 'map' (expected 'odom')": 1}
    twist.twist.linear.x = math.nan
    for i, m in enumerate((pose, twist, accel)):
        assert inputs.accept_reference(i, m)
    assert inputs.odom(odom(T0)) is None
    assert inputs.rejected == 2
    assert any(k.startswith('reference twist/accel not finite') for k in inputs.ignored)


def test_realtime_answers_each_odometry_with_the_latest_reference(config):
    inputs = TrackerInputs(config)                          # real time
    for i, m in enumerate(refs(T0 - 5 * MS)):
        assert inputs.reference(i, m) is None               # never a command on a sample
    a = inputs.odom(odom(T0))
    b = inputs.odom(odom(T0 + 10 * MS))                     # same samples, next odometry
    assert a is not None and b is not None and (a.stamp, b.stamp) == (T0, T0 + 10 * MS)
    assert a.ref == b.ref and a.ref.t == pytest.approx((T0 - 5 * MS) * 1e-9)
    # the law's own answer, for the same inputs
    law = Tracker(config)
    expect = law.step(0.5, 0.0, 1.57, a.ref, measured_speed=0.05, stamp=T0 * 1e-9)
    assert (a.command.v, a.command.w) == (expect.v, expect.w)
    inputs.stopped = True                                   # the watchdog's stop
    assert inputs.odom(odom(T0 + 20 * MS)) is None
    inputs.stopped = False
    assert inputs.odom(odom(T0 + 30 * MS)) is not None


def test_lockstep_answers_a_stamp_once_when_all_four_parts_are_in(config):
    inputs = TrackerInputs(config, InputRules('lockstep'))
    pose, twist, accel = refs(T0)
    assert inputs.reference(0, pose) is None and inputs.reference(1, twist) is None
    assert inputs.odom(odom(T0)) is None                   # accel of T0 not in yet
    step = inputs.reference(2, accel)                       # the last part: answered now
    assert step is not None and step.stamp == T0
    assert inputs.odom(odom(T0)) is None                   # once
    assert inputs.by_stamp == {}                            # answered parts are let go
    # samples of the next stamp but odometry of a later one: not answered
    for i, m in enumerate(refs(T0 + 10 * MS)):
        inputs.reference(i, m)
    assert inputs.odom(odom(T0 + 20 * MS)) is None
    assert sorted(inputs.by_stamp) == [T0 + 10 * MS]
    # samples older than the last answered stamp are not kept
    inputs.reference(0, refs(T0 - 10 * MS)[0])
    assert T0 - 10 * MS not in inputs.by_stamp
    assert inputs.rejected == 0


def test_lockstep_keeps_at_most_ref_buffer_stamps(config):
    inputs = TrackerInputs(config, InputRules('lockstep'))
    for k in range(REF_BUFFER + 5):
        inputs.reference(0, refs(T0 + k * MS)[0])
    assert len(inputs.by_stamp) == REF_BUFFER
    assert min(inputs.by_stamp) == T0 + 5 * MS               # the oldest went first


# ---------------------------------------------------------------------- trajectories
def test_a_trajectory_is_adopted_and_answers_a_waiting_odometry(config):
    inputs = TrackerInputs(config, InputRules('lockstep', wait_for_trajectory=True))
    assert feed(inputs, T0, x=0.0, th=0.0) == []             # samples never used
    step = inputs.trajectory(multidof(T0, LINE), 'multidof', 'test')
    assert step is not None and step.stamp == T0 and step.started
    assert inputs.follower is not None and inputs.origin_ns == T0
    assert step.ref.x == pytest.approx(0.0) and step.command.v > 0
    assert inputs.odom(odom(T0 + 10 * MS, x=0.0, th=0.0)).stamp == T0 + 10 * MS
    deferred = TrackerInputs(config)
    deferred.odom(odom(T0, x=0.0, th=0.0))
    assert deferred.trajectory(multidof(T0, LINE), 'multidof', 'test', defer=True) is None


def test_a_bad_trajectory_is_refused_and_the_previous_one_stays(config):
    seen: list[Rejection] = []
    inputs = TrackerInputs(config, on_reject=seen.append)
    inputs.trajectory(multidof(T0, LINE), 'multidof', 'test')
    kept = inputs.follower.trajectory
    assert inputs.trajectory(multidof(T0, LINE, frame='map'), 'multidof', 'topic x') is None
    assert inputs.follower.trajectory is kept and inputs.rejected == 1
    assert seen[0].kind == 'trajectory' and inputs.last_refusal == seen[0].reason
    assert "'map'" in inputs.last_refusal and inputs.last_refusal.startswith('topic x')
    assert list(inputs.ignored) == [f'trajectory refused: {inputs.last_refusal}']


def test_a_trajectory_too_far_at_its_start_is_refused(config):
    seen: list[Rejection] = []
    inputs = TrackerInputs(config, InputRules(max_start_distance=0.5), on_reject=seen.append)
    inputs.odom(odom(T0, x=0.0, y=2.0, th=0.0))              # 2 m from the start
    step = inputs.trajectory(multidof(T0, LINE), 'multidof', 'test')
    assert step is not None and step.started and (step.command.v, step.command.w) == (0, 0)
    assert [r.kind for r in seen] == ['start'] and inputs.rejected == 1
    assert 'more than max_start_distance = 0.5 m' in inputs.last_refusal


def test_an_untimed_path_gets_the_time_law_from_the_rules(config):
    poses = [NS(header=_hdr(0), pose=_pose(x, y, th)) for x, y, th in LINE]
    path = NS(header=_hdr(0), poses=poses)
    slow = TrackerInputs(config, InputRules(cruise_speed=0.25, max_accel=0.5, retime=False))
    slow.odom(odom(T0, x=0.0, th=0.0))
    fast = TrackerInputs(config, InputRules(cruise_speed=0.5, max_accel=0.5, retime=False))
    fast.odom(odom(T0, x=0.0, th=0.0))
    traj_slow, origin = slow.build(path, 'path', 'test')
    traj_fast, _ = fast.build(path, 'path', 'test')
    assert origin == T0                                      # untimed, unstamped: now
    # 2.5 m, trapezoid at 0.5 m/s^2: to 0.5 m/s in 1 s (0.25 m) and back, 2 m cruising 4 s;
    # to 0.25 m/s in 0.5 s (0.0625 m) and back, 2.375 m cruising 9.5 s
    assert traj_fast.duration == pytest.approx(6.0)
    assert traj_slow.duration == pytest.approx(10.5)
    with pytest.raises(InputError, match='trajectory kind'):
        slow.build(path, 'spline', 'test')


# ---------------------------------------------------------------------- settings
def test_rules_from_parameter_values():
    # the node's defaults tune the predictor (monitor_tune, monitor on): an estimate every
    # monitor_period, the monitor's settings, no lag inverted without a certified_lag
    tuned = input_rules({})
    assert tuned == InputRules(tune=(monitor_settings({}), TuningSettings(
        period=MONITOR_DEFAULTS['monitor_period'], max_latency=0.5, max_lag=0.0)))
    assert INPUT_DEFAULTS['monitor_tune'] is True and INPUT_DEFAULTS['monitor'] is True
    assert input_rules({'certified_lag': 0.03}).tune[1].max_lag == 0.03
    # off, or without the monitor (whose estimates it follows): the plain rules
    assert input_rules({'monitor_tune': False}) == input_rules({'monitor': False}) == \
        InputRules()
    r = input_rules({'mode': 'lockstep', 'odom_frame': 'world', 'max_stamp_jump': 0.5,
                     'retime': False, 'max_linear_accel': 0.7})
    assert (r.mode, r.frame, r.max_stamp_jump, r.retime) == ('lockstep', 'world', 0.5, False)
    assert r.limits.max_linear_accel == 0.7
    assert input_rules({'mode': 'lockstep'}, mode='realtime').mode == 'realtime'
    assert INPUT_DEFAULTS['odom_frame'] == 'odom' and INPUT_DEFAULTS['max_stamp_jump'] == 1.0
    with pytest.raises(InputError, match='mode must be one of'):
        input_rules({'mode': 'fast'})
    with pytest.raises(InputError, match='max_stamp_jump'):
        InputRules(max_stamp_jump=0.0)
    assert input_rules({'trajectory_accel_fraction': 0.6}).accel_fraction == 0.6
    assert InputRules().accel_fraction == INPUT_DEFAULTS['trajectory_accel_fraction'] == 0.8
    for bad in (0.0, 0.01, -0.5, 1.5, math.nan):
        with pytest.raises(InputError, match=r'trajectory_accel_fraction must be in \[0.05, 1\]'):
            input_rules({'trajectory_accel_fraction': bad})


def test_stale_inputs():
    s = 10 ** 9
    assert stale_inputs(5 * s, None, None, 0.5, own_trajectory=False) is None
    assert stale_inputs(5 * s, 4 * s, None, 0.5, own_trajectory=False) is None
    assert stale_inputs(5 * s, 4 * s, None, 0.5, own_trajectory=True) == ['odom']
    assert stale_inputs(5 * s, 4.6 * s, 4.4 * s, 0.5, own_trajectory=False) == ['reference']
    assert stale_inputs(5 * s, 4.6 * s, 4.6 * s, 0.5, own_trajectory=False) == []
    assert stale_inputs(5 * s, 4.6 * s, 1 * s, 0.5, own_trajectory=True) == []


def test_fork_diverges_without_touching_the_original(config):
    inputs = TrackerInputs(config)
    feed(inputs, T0)
    trial = inputs.fork()
    trial.tracker.reset(0.7)
    trial.odom(odom(T0 + 10 * MS))
    assert inputs.last_stamp == T0 and trial.last_stamp == T0 + 10 * MS
    assert inputs.tracker.v != 0.7 and trial.latest == inputs.latest


def test_one_parameters_to_tracker_config_mapping():
    """``tracker_config_from`` (the study, the reproduction) is the node's mapping with the
    node's defaults: a scenario's gain compensation and rate limits are kept, not dropped."""
    import numpy as np

    from nonfragile_tracker.bag.replay import TRACKER_DEFAULTS
    from nonfragile_tracker.interface.msgconv import (LAW_DEFAULTS, tracker_config,
                                                      tracker_config_from)
    K = -np.array([[1.0, 1.5, 0.0, 0.0], [0.0, 0.0, 1.0, 1.5]])   # A + B K Hurwitz
    params = {'gain_w': 1.5, 'max_angular_accel': 3.0, 'max_linear_speed': 0.4}
    cfg = tracker_config_from(params, K)
    assert (cfg.gain_w, cfg.max_angular_accel, cfg.max_linear_speed) == (1.5, 3.0, 0.4)
    assert cfg == tracker_config({**TRACKER_DEFAULTS, **params, 'K': K.ravel().tolist(),
                                  'K_shape': [2, 4]})
    assert np.array_equal(np.asarray(cfg.K), K) and LAW_DEFAULTS.items() <= TRACKER_DEFAULTS.items()
