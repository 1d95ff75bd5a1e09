"""The side slip: its table, its dead reckoning in the tracker, its identification.

A kinematic base that slides outward at ``-c(|w|) v w`` (a known table), its odometry the
unicycle of the same speeds (blind to the slide), an external pose with 1 mm of noise:
the identification finds the table within its intervals, in any frame of the external
pose, and refuses what it cannot fit from; the tracker's correction is the integral of the
table's slide.  The physics skid-steer: test/control/test_physics.py.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from nonfragile_tracker.control.identification.errors import (InsufficientExcitationError,
                                                              NotEnoughDataError)
from nonfragile_tracker.control.identification.records import (OdometrySamples,
                                                               read_identification,
                                                               write_identification)
from nonfragile_tracker.control.identification.slip import identify_side_slip
from nonfragile_tracker.control.simulation.errors import LoopConfigError
from nonfragile_tracker.control.simulation.reference import RefSample
from nonfragile_tracker.control.simulation.slip import (SlideReckoner, hat_basis,
                                                        slip_coefficient)
from nonfragile_tracker.control.simulation.tracker import Tracker, TrackerConfig

from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.interface.resources import config_dir

K = read_gain_file(config_dir() / 'tracker_gains.yaml')
RATES, TABLE = (0.25, 0.5), (0.04, 0.08)


def test_the_table_is_linear_between_its_rates_and_flat_beyond():
    assert slip_coefficient(RATES, TABLE, 0.125) == 0.04
    assert slip_coefficient(RATES, TABLE, -0.375) == pytest.approx(0.06)
    assert slip_coefficient(RATES, TABLE, 3.0) == 0.08
    assert slip_coefficient((), (), 1.0) == 0.0
    w = np.array([0.0, 0.1, -0.3, 0.7])
    assert np.allclose(hat_basis(RATES, w) @ np.array(TABLE),
                       [slip_coefficient(RATES, TABLE, x) for x in w], atol=1e-15)


def test_the_reckoner_integrates_the_slide_of_a_steady_turn():
    """v = 0.3 m/s, w = 0.4 rad/s for 5 s at 50 Hz: the slide -c v w (c = 0.064 s) integrated
    in the turning frame, ((cos wT - 1) / w, sin wT / w) v_y, to the midpoint rule's
    (w dt)^2 / 6 = 1.1e-5 of it (measured 2.7e-6)."""
    v, w, dt, n = 0.3, 0.4, 0.02, 250
    r = SlideReckoner(RATES, TABLE)
    for k in range(n + 1):
        r.update(w * k * dt, v, w, dt if k else None)
    vy = -slip_coefficient(RATES, TABLE, w) * v * w
    T = n * dt
    want = (vy * (math.cos(w * T) - 1.0) / w, vy * math.sin(w * T) / w)
    assert np.allclose(r.offset, want, rtol=(w * dt) ** 2 / 6, atol=0), (r.offset, want)
    assert r.course_offset(v) == pytest.approx(math.atan(vy / v))
    before = r.offset
    r.update(1.0, math.nan, w, dt)            # an unknown speed skips the interval
    assert r.offset == before


@pytest.mark.parametrize('rates, coefficients, words', [
    ((0.0, 0.5), (0.1,), 'one coefficient'),
    ((0.5, 0.25), (0.1, 0.1), 'strictly increasing'),
    ((-0.1, 0.5), (0.1, 0.1), '>= 0'),
    ((0.0,), (math.inf,), 'finite'),
    ((0.0,), ('x',), 'sequences of numbers'),
])
def test_a_bad_table_is_refused(rates, coefficients, words):
    with pytest.raises(LoopConfigError, match=words):
        TrackerConfig(K=K, side_slip_rates=rates, side_slip=coefficients)


def test_a_zero_table_is_no_table_bit_for_bit():
    a = Tracker(TrackerConfig(K=K))
    b = Tracker(TrackerConfig(K=K, side_slip_rates=(0.0,), side_slip=(0.0,)))
    assert not b.config.slides and b.slide is None
    for k in range(50):
        t = 0.02 * k
        ref = RefSample(t, 0.3 * t, 0.0, 0.3, 0.0, 0.0, 0.0, 0.0)
        ca = a.step(0.3 * t, 0.01, 0.02, ref, 0.3, stamp=t, measured_rate=0.1)
        cb = b.step(0.3 * t, 0.01, 0.02, ref, 0.3, stamp=t, measured_rate=0.1)
        assert ca == cb


def test_the_tracker_tracks_the_odometry_plus_the_slide():
    """With a table, the tracker's error is the one of the odometry's position plus the
    reckoned slide (and the course for the heading); a reset keeps the slide."""
    cfg = TrackerConfig(K=K, side_slip_rates=RATES, side_slip=TABLE)
    trk, ref_trk = Tracker(cfg), Tracker(TrackerConfig(K=K))
    r = SlideReckoner(RATES, TABLE)
    for k in range(100):
        t = 0.02 * k
        th = 0.4 * t
        ref = RefSample(t, 0.0, 0.0, 0.3, 0.0, 0.0, 0.0, 0.0)
        dx, dy = r.update(th, 0.3, 0.4, 0.02 if k else None)
        got = trk.step(0.1, 0.2, th, ref, 0.3, stamp=t, measured_rate=0.4)
        want = ref_trk.step(0.1 + dx, 0.2 + dy, th + r.course_offset(0.3), ref, 0.3, stamp=t,
                            measured_rate=0.4)
        assert got == want
    assert np.hypot(*trk.slide.offset) > 1e-3
    before = trk.slide.offset
    trk.reset()
    assert trk.slide.offset == before


def _drive(table, seconds=60.0, w_max=0.8, seed=4, frame=(0.0, 0.0, 0.0), rates=RATES):
    """A kinematic base that slides by ``table`` (on ``rates``): (odometry, external pose)."""
    rng = np.random.default_rng(seed)
    dt, n = 0.02, int(seconds / 0.02)
    levels = [(rng.uniform(0.1, 0.4), rng.uniform(-w_max, w_max)) for _ in range(n // 50 + 1)]
    x = y = th = ox = oy = 0.0
    odom, truth = [], []
    c, s = math.cos(frame[2]), math.sin(frame[2])
    for k in range(n):
        v, w = levels[k // 50]
        vy = -slip_coefficient(rates, table, w) * v * w if table else 0.0
        odom.append((k * dt, ox, oy, th, v, w))
        truth.append((k * dt, frame[0] + c * x - s * y + rng.normal(0, 1e-3),
                      frame[1] + s * x + c * y + rng.normal(0, 1e-3), th + frame[2]))
        mid = th + 0.5 * w * dt
        x += (v * math.cos(mid) - vy * math.sin(mid)) * dt
        y += (v * math.sin(mid) + vy * math.cos(mid)) * dt
        ox += v * math.cos(mid) * dt
        oy += v * math.sin(mid) * dt
        th += w * dt
    return OdometrySamples(*np.array(odom).T), OdometrySamples(*np.array(truth).T)


@pytest.mark.parametrize('frame', [(0.0, 0.0, 0.0), (3.0, -2.0, 1.2)])
def test_the_identification_finds_a_known_table_in_any_frame(frame):
    """The table (0.04, 0.08) s at (0.25, 0.5) rad/s, 1 mm pose noise, 60 s: found within
    its 95 % intervals and to 0.01 s, also with the external pose in a frame moved by
    (3, -2) m and turned by 1.2 rad."""
    odom, truth = _drive(TABLE, frame=frame)
    slip = identify_side_slip(odom, truth)
    assert slip.rates == RATES and slip.significant, slip
    for j in (0, 1):
        assert slip.low[j] <= TABLE[j] <= slip.high[j], slip
        assert abs(slip.coefficients[j] - TABLE[j]) < 0.01, slip
    assert slip.residual_rms < 0.5 * slip.drift_rms


@pytest.mark.parametrize('w_max, knots', [(0.6, (0.25, 0.5)), (0.9, (0.25, 0.5, 1.0))])
def test_the_table_reaches_the_turns_driven(w_max, knots):
    """A slide growing with the turn rate, c = 0.02 + 0.1 |w| s: turns up to 0.9 rad/s (95 %
    below 0.86) give the knot at 1 rad/s (KNOT_REACH: a table on 0.25 and 0.5 alone is flat
    beyond 0.5, 0.035 s short at 0.85 rad/s) and c at 0.85 rad/s to 0.01 s; turns up to
    0.6 rad/s (95 % below 0.57) stop at 0.5."""
    rates = (0.25, 0.5, 1.0)
    truth_table = tuple(0.02 + 0.1 * r for r in rates)
    odom, truth = _drive(truth_table, w_max=w_max, rates=rates)
    slip = identify_side_slip(odom, truth)
    assert slip.rates == knots and slip.significant, slip
    if len(knots) == 3:
        assert abs(slip_coefficient(slip.rates, slip.coefficients, 0.85) - 0.105) < 0.01, slip


def test_no_slide_is_found_not_significant_and_the_file_keeps_a_table(tmp_path):
    odom, truth = _drive(None)
    assert not identify_side_slip(odom, truth).significant
    from dataclasses import replace
    from nonfragile_tracker.control.identification.records import Identification
    ident = Identification(0.05, 0.04, 0.06, 0.05, 0.04, 0.06, 0.05, 0.04, 0.06, 50.0, 100,
                           0.01, 0.01, source='test')
    path = write_identification(tmp_path / 'id.yaml', replace(ident, side_slip_rates=RATES,
                                                              side_slip=TABLE))
    back = read_identification(path)
    assert back.side_slip_rates == RATES and back.side_slip == TABLE
    assert read_identification(write_identification(tmp_path / 'none.yaml', ident)
                               ).side_slip == ()


def test_too_little_turning_or_too_short_a_recording_is_refused():
    odom, truth = _drive(TABLE, w_max=0.1)
    with pytest.raises(InsufficientExcitationError, match='turned too little'):
        identify_side_slip(odom, truth)
    odom, truth = _drive(TABLE, seconds=4.0)
    with pytest.raises(NotEnoughDataError, match='overlap'):
        identify_side_slip(odom, truth)


def _skid_bag(bag):
    """20 s of random steps on the MuJoCo skid-steer, recorded as a robot with motion capture
    would record it: cmd_vel (Twist), odom (the encoders and gyro) and pose (the true pose
    with 1 mm of noise, PoseStamped)."""
    from geometry_msgs.msg import PoseStamped, Twist
    from nav_msgs.msg import Odometry
    from rclpy.serialization import serialize_message
    from nonfragile_tracker.bag.writer import BagWriter
    from nonfragile_tracker.control.simulation import physics
    from nonfragile_tracker.control.simulation.model import yaw_to_quaternion
    from nonfragile_tracker.control.simulation.plant import PlantConfig
    from nonfragile_tracker.control.simulation.timing import step_time

    def stamp(m, t):
        ns = int(round(t * 1e9))
        m.header.stamp.sec, m.header.stamp.nanosec = ns // 10**9, ns % 10**9

    def put(pose, x, y, th):
        pose.position.x, pose.position.y = float(x), float(y)
        o = pose.orientation
        o.x, o.y, o.z, o.w = yaw_to_quaternion(float(th))

    plant = physics.PhysicsPlant(PlantConfig(dt=0.01, odom_rate=50.0, cmd_latency=0.04),
                                 'jackal_skid')
    rng = np.random.default_rng(3)
    levels = [(rng.uniform(0.1, 0.5), rng.uniform(-1.0, 1.0)) for _ in range(20)]
    rows = []
    for k in range(2000):
        s = plant.odometry()
        t = step_time(k, plant.dt)
        if s is not None:
            m = Odometry()
            stamp(m, t)
            m.header.frame_id, m.child_frame_id = 'odom', 'base_link'
            put(m.pose.pose, s.x, s.y, s.th)
            m.twist.twist.linear.x, m.twist.twist.angular.z = s.v, s.w
            rows.append((t + 0.002, 'odom', serialize_message(m)))
            p = PoseStamped()
            stamp(p, t)
            p.header.frame_id = 'world'
            put(p.pose, plant.x + rng.normal(0, 1e-3), plant.y + rng.normal(0, 1e-3), plant.th)
            rows.append((t + 0.003, 'pose', serialize_message(p)))
        if k % 5 == 0:
            c = Twist()
            c.linear.x, c.angular.z = levels[k // 100]
            plant.command(*levels[k // 100])
            rows.append((t, 'cmd_vel', serialize_message(c)))
        plant.advance()
    rows.sort(key=lambda r: r[0])
    with BagWriter(bag, connections={'cmd_vel': 'geometry_msgs/msg/Twist',
                                     'odom': 'nav_msgs/msg/Odometry',
                                     'pose': 'geometry_msgs/msg/PoseStamped'}) as wr:
        for t, topic, raw in rows:
            wr.write(topic, int(round(t * 1e9)), raw)


def test_identify_with_truth_writes_the_table_the_design_compensates(tmp_path, capsys):
    """``identify BAG --truth pose -o F``: the skid-steer's table in the file, and the plan
    the design makes of it gives the tracker its parameters; an absent topic is an error
    naming it (exit 2), not a traceback."""
    from nonfragile_tracker.cli import main
    from nonfragile_tracker.control.synthesis.latency_design import plan_from_identification
    bag = tmp_path / 'skid'
    _skid_bag(bag)
    out = tmp_path / 'id.yaml'
    assert main(['identify', str(bag), '--truth', 'pose', '-o', str(out),
                 '--bootstrap', '50']) == 0
    text = capsys.readouterr().out
    assert 'side slip from pose: side slip c(|w|) 0.25 rad/s' in text, text
    assert 'tracker: side_slip_rates [0.25, 0.5]' in text, text
    ident = read_identification(out)
    assert ident.side_slip_rates == (0.25, 0.5) and 0.03 < ident.side_slip[1] < 0.12
    params = plan_from_identification(ident).slip_parameters()
    assert params == {'side_slip_rates': [0.25, 0.5], 'side_slip': list(ident.side_slip)}
    assert main(['identify', str(bag), '--truth', 'mocap']) == 2
    err = capsys.readouterr().err
    assert 'mocap' in err and 'Traceback' not in err, err
