"""Bring-up workflow of issue 11: record -> identify -> latency-design -> run (ROS-free).

The recorded run is the in-process loop of the nodes (:func:`control.simulation.simulate.run_loop`,
the plant and tracker step functions) on the latency scenario's robot: figure eight
r = 1 m at 0.2 rad/s, 100 ms command latency, 50 ms lag on v and w, odometry 50 Hz
with 1 mm noise, the tracker's predictor on.  The identification, the derived interval
(one rule: :func:`control.synthesis.latency_design.plan_from_identification`), the gain file of
``latency-design --identification`` and a run with that file are checked with numbers.
"""
import math

import numpy as np
import pytest
import yaml

from nonfragile_tracker.cli import main
from nonfragile_tracker.control.simulation.gains import (DESIGN_SECTION, read_gain_design,
                                                         read_gain_file)
from nonfragile_tracker.control.identification.identify import (CommandSamples, Identification,
                                                                OdometrySamples, identify_latency,
                                                                read_identification, with_source,
                                                                write_identification)
from nonfragile_tracker.control.synthesis.input_delay import certify_input_delay
from nonfragile_tracker.control.synthesis.latency_design import (lagged_problem,
                                                                 plan_from_identification)
from nonfragile_tracker.control.simulation.plant import PlantConfig
from nonfragile_tracker.control.simulation.tracker import Tracker, TrackerConfig
from nonfragile_tracker.control.simulation.timing import step_time
from nonfragile_tracker.control.synthesis.problem import load_problem
from nonfragile_tracker.control.simulation.reference import figure_eight
from nonfragile_tracker.control.simulation.simulate import run_loop
from nonfragile_tracker.errors import InputError

from conftest import CONFIG, DI_PROBLEM

#: Depends on linear algebra: make test runs it again under a second BLAS kernel (Makefile).
pytestmark = pytest.mark.numerical

DT = 0.01            # plant step (config/latency_scenario.yaml)
LATENCY = 0.1
LAG = 0.05
PREDICTOR_KEYS = ('predict_latency', 'predict_odom_latency', 'predict_lag_v', 'predict_lag_w')


def scenario_run(K, predict: dict, *, duration: float, seed: int = 1):
    """One run of the latency scenario's robot; returns (run, commands, odometry)."""
    pc = PlantConfig(dt=DT, tau=0.0, A_tau=np.zeros((4, 4)), x0=0.0, y0=-0.1,
                     th0=math.pi / 4, v0=0.0, cmd_latency=LATENCY, lag_v=LAG, lag_w=LAG,
                     odom_rate=50.0, odom_noise=(1e-3, 1e-3, 1e-3), noise_seed=seed)
    tracker = Tracker(TrackerConfig(K=K, dt=0.02, max_angular_speed=2.0, **predict))
    path = figure_eight(radius=1.0, rate=0.2)
    cmds, odom = [], []

    def command(meas, th, k, ref):
        ts = step_time(meas.step, DT)
        cmd = tracker.step(meas.x, meas.y, th, path.sample(ts), meas.v, stamp=ts)
        cmds.append((step_time(k, DT), cmd.v, cmd.w))        # sent (received) at step k
        odom.append((ts, meas.x, meas.y, th, meas.v, meas.w))
        return cmd

    run = run_loop(pc, int(round(duration / DT)), command,
                   lambda k: path.sample(step_time(k, DT)))
    c, o = np.array(cmds).T, np.array(odom).T
    return run, CommandSamples(*c), OdometrySamples(*o)


def rms_after(run, t0: float = 10.0) -> float:
    e = run.error[run.t > t0]
    return float(np.sqrt(np.mean(e * e)))


def ident(lo=0.095, hi=0.11, period=0.02, age=(0.002, 0.008)) -> Identification:
    return Identification(0.1, lo, hi, 0.05, 0.045, 0.055, 0.06, 0.05, 0.07, 50.0, 1000,
                          1e-3, 1e-3, source='runs/x/bag', command_period_s=period,
                          command_age_low_s=age[0], command_age_high_s=age[1])


def test_plan_rule_with_and_without_predictor():
    plan = plan_from_identification(ident())
    assert plan.predictor and plan.h_min == 0.0
    # (L_hi - L_lo) + (a_hi - a_lo) + T = 0.015 + 0.006 + 0.02
    assert plan.h_max == pytest.approx(0.041, abs=1e-12)
    assert plan.lag == pytest.approx(0.06)
    assert plan.tracker_parameters() == pytest.approx(
        {'predict_latency': 0.095, 'predict_odom_latency': 0.002, 'predict_lag_v': 0.05,
         'predict_lag_w': 0.06})
    bare = plan_from_identification(ident(), predictor=False)
    # [L_lo + a_lo, L_hi + a_hi + T]
    assert (bare.h_min, bare.h_max) == pytest.approx((0.097, 0.138), abs=1e-12)
    assert set(bare.tracker_parameters().values()) == {0.0}
    # lockstep: no command age; the command period given overrides the file's
    lock = plan_from_identification(ident(age=(math.nan, math.nan)), command_period=0.01)
    assert (lock.h_min, lock.h_max) == pytest.approx((0.0, 0.025), abs=1e-12)
    meta = plan.metadata()
    assert meta['compensation'] == 'predictor' and meta['designed_from'] == 'runs/x/bag'
    assert meta['identified_latency_interval'] == [0.095, 0.11]


def test_plan_needs_a_command_period():
    with pytest.raises(InputError, match='--command-period'):
        plan_from_identification(ident(period=math.nan))
    with pytest.raises(InputError, match='command period'):
        plan_from_identification(ident(), command_period=-0.02)


@pytest.fixture(scope='module')
def recorded(tmp_path_factory):
    """Step 1 and 2: a 20 s run with the shipped gain, identified and written to a file."""
    K = read_gain_file(CONFIG / 'tracker_gains.yaml')
    predict = dict(predict_latency=LATENCY, predict_lag_v=LAG, predict_lag_w=LAG)
    _, cmds, odom = scenario_run(K, predict, duration=20.0)
    res = with_source(identify_latency(cmds, odom, bootstrap=50), 'sim/bag')
    path = write_identification(tmp_path_factory.mktemp('wf') / 'lat.yaml', res)
    return res, path


def test_identification_of_the_simulated_run(recorded):
    res, path = recorded
    assert abs(res.latency_s - LATENCY) <= DT                 # within one plant step
    assert res.latency_low_s <= LATENCY + DT and res.latency_high_s >= LATENCY - DT
    assert abs(res.tau_v_s - LAG) < 0.2 * LAG and abs(res.tau_w_s - LAG) < 0.2 * LAG
    assert res.command_period_s == pytest.approx(0.02)
    assert res.command_age_low_s == 0.0 and res.command_age_high_s == 0.0   # lockstep
    back = read_identification(path)
    assert back.command_period_s == pytest.approx(0.02)
    assert (back.command_age_low_s, back.command_age_high_s) == (0.0, 0.0)
    plan = plan_from_identification(back)
    lo, hi = back.latency_range_s            # the range (contains the interval of the mean)
    assert lo <= back.latency_low_s and hi >= back.latency_high_s
    assert plan.predict_latency == lo and plan.h_max == pytest.approx(hi - lo + 0.02, rel=1e-5)
    assert 0.02 <= plan.h_max < 0.03 and abs(plan.predict_latency - LATENCY) <= DT


def test_chain_gain_certified_for_the_plan_tracks_to_millimetres(recorded):
    """Design-step check without the synthesis (about 14 s): the shipped default gain is
    certified on the plan's residual interval with the identified lag, and a run with
    the plan's predictor settings tracks within the issue's 5 mm at 100 ms."""
    res, path = recorded
    plan = plan_from_identification(read_identification(path))
    problem = load_problem(CONFIG / 'paper_problem.yaml')
    K = read_gain_file(CONFIG / 'tracker_gains.yaml')
    lp = lagged_problem(problem, plan.lag)
    cert = certify_input_delay(lp, np.hstack([K, np.zeros((2, 2))]), plan.h_min, plan.h_max)
    assert cert.certified
    run, _, _ = scenario_run(K, plan.tracker_parameters(), duration=20.0, seed=2)
    assert rms_after(run) <= 0.005
    # the same robot without the predictor is far worse (the reason for the workflow)
    bare, _, _ = scenario_run(K, {}, duration=20.0, seed=2)
    assert rms_after(bare) > 2 * rms_after(run)


def test_cli_design_from_identification_records_it(tmp_path, capsys):
    """latency-design --identification: interval by the rule, predictor in the gain file."""
    prob = tmp_path / 'di.yaml'
    prob.write_text(DI_PROBLEM)
    from dataclasses import replace
    lat = write_identification(tmp_path / 'lat.yaml', replace(
        ident(lo=0.09, hi=0.1, period=0.02, age=(0.0, 0.0)), max_linear_accel=1.0,
        max_angular_accel=3.0))
    out = tmp_path / 'g.yaml'
    assert main(['latency-design', str(prob), '--identification', str(lat),
                 '-o', str(out)]) == 0
    text = capsys.readouterr().out
    assert 'residual delay to certify: [0.0000, 0.0300] s' in text
    rec = read_gain_design(out)
    assert rec['latency_interval'] == pytest.approx([0.0, 0.03])
    assert rec['actuator_lag'] == pytest.approx(0.06)
    assert rec['compensation'] == 'predictor' and rec['designed_from'] == 'runs/x/bag'
    assert rec['identified_latency_interval'] == pytest.approx([0.09, 0.1])
    params = yaml.safe_load(out.read_text())['/**/tracker']['ros__parameters']
    assert {k: params[k] for k in PREDICTOR_KEYS} == pytest.approx(
        {'predict_latency': 0.09, 'predict_odom_latency': 0.0, 'predict_lag_v': 0.05,
         'predict_lag_w': 0.06})
    # the identified acceleration limits go to the tracker section and the design record
    assert (params['max_linear_accel'], params['max_angular_accel']) == (1.0, 3.0)
    assert (rec['max_linear_accel'], rec['max_angular_accel']) == (1.0, 3.0)
    assert rec['identified_latency_range'] == pytest.approx([0.09, 0.1])
    assert DESIGN_SECTION in yaml.safe_load(out.read_text())
    assert read_gain_file(out).shape == (1, 2)
    # without the predictor: the whole delay, and the gain file switches the predictor off
    out2 = tmp_path / 'g2.yaml'
    assert main(['latency-design', str(prob), '--identification', str(lat), '--no-predictor',
                 '-o', str(out2)]) == 0
    assert read_gain_design(out2)['latency_interval'] == pytest.approx([0.09, 0.12])
    params = yaml.safe_load(out2.read_text())['/**/tracker']['ros__parameters']
    assert [params[k] for k in PREDICTOR_KEYS] == [0.0] * 4
    assert (params['max_linear_accel'], params['max_angular_accel']) == (1.0, 3.0)


def test_cli_design_writes_the_identified_limits_into_the_robot_file(tmp_path, capsys):
    """latency-design --identification --robot-file: the limits into the robot file (the
    gain file keeps them too), the robot file's other keys and comments untouched."""
    from dataclasses import replace
    from nonfragile_tracker.interface.robot import load_robot_file
    prob = tmp_path / 'di.yaml'
    prob.write_text(DI_PROBLEM)
    lat = write_identification(tmp_path / 'lat.yaml', replace(
        ident(lo=0.09, hi=0.1, period=0.02, age=(0.0, 0.0)), max_linear_accel=0.0,
        max_angular_accel=2.5))
    robot = tmp_path / 'robot.yaml'
    robot.write_text('# my base\n/**/tracker:\n  ros__parameters:\n'
                     '    max_linear_accel: 0.7   # from the data sheet\n')
    assert main(['latency-design', str(prob), '--identification', str(lat), '-o',
                 str(tmp_path / 'g.yaml'), '--robot-file', str(robot)]) == 0
    assert f'robot file {robot}: max_angular_accel: absent -> 2.5' in capsys.readouterr().out
    cfg = load_robot_file(robot)
    assert (cfg.max_linear_accel, cfg.max_angular_accel) == (0.7, 2.5)   # 0 = unknown: kept
    assert robot.read_text().startswith('# my base\n') and '# from the data sheet' in \
        robot.read_text()
    assert f'[identified in {lat}]' in robot.read_text()
    params = yaml.safe_load((tmp_path / 'g.yaml').read_text())['/**/tracker']['ros__parameters']
    assert params['max_angular_accel'] == 2.5 and 'max_linear_accel' not in params


@pytest.mark.parametrize('argv, match', [
    ([], 'either as --delay-interval'),
    (['--delay-interval', '0', '0.1', '--identification', 'X'], 'not both'),
    (['--delay-interval', '0', '0.1', '--no-predictor'], 'apply to --identification only'),
    (['--delay-interval', '0', '0.1', '--robot-file', 'r.yaml'], 'apply to --identification'),
    (['--identification', 'missing.yaml'], 'missing.yaml'),
])
def test_cli_refuses_bad_combinations(argv, match, capsys):
    assert main(['latency-design', str(CONFIG / 'paper_problem.yaml'), *argv]) == 2
    assert match in capsys.readouterr().err


@pytest.mark.slow
def test_full_chain_with_the_paper_design(recorded, tmp_path, capsys):
    """record -> identify -> latency-design (the real synthesis, about 14 s) -> run."""
    _, path = recorded
    out = tmp_path / 'g.yaml'
    assert main(['latency-design', str(CONFIG / 'paper_problem.yaml'), '--identification',
                 str(path), '-o', str(out)]) == 0
    rec = read_gain_design(out)
    assert rec['lag_certified_h_max'] >= rec['latency_interval'][1]
    assert rec['true_delay_margin'] > rec['lag_certified_h_max']    # the lagged loop's figures
    assert rec['exact_figures_loop'] == 'lagged' and rec['state_delay_in_exact_check']
    assert np.linalg.norm(read_gain_file(out), 2) <= 8.67 + 1e-6
    params = yaml.safe_load(out.read_text())['/**/tracker']['ros__parameters']
    run, _, _ = scenario_run(read_gain_file(out), {k: params[k] for k in PREDICTOR_KEYS},
                             duration=20.0, seed=3)
    assert rms_after(run) <= 0.005


# ---------------------------------------------------------------------------------------------
# Predictor while following a trajectory (control.simulation.follow.Follower)

def follow_lap(predict: dict, latency: float = 0.2):
    from nonfragile_tracker.control.simulation.follow import simulate_following
    from nonfragile_tracker.control.simulation.trajectory import load_waypoints
    traj = load_waypoints(CONFIG / 'trajectories' / 'lap.csv')
    pc = PlantConfig(dt=DT, tau=0.0, A_tau=np.zeros((4, 4)), x0=0.0, y0=-0.02, th0=0.0, v0=0.0,
                     cmd_latency=latency, lag_v=LAG, lag_w=LAG, odom_rate=50.0)
    tc = TrackerConfig(K=read_gain_file(CONFIG / 'max_decay_gains.yaml'), dt=0.02,
                       max_angular_speed=2.0, **predict)
    run = simulate_following(pc, tc, traj, int(round((traj.t_end + 3.0) / DT)))
    return run, traj


def test_follower_with_predictor_tracks_the_lap_and_stops():
    """200 ms latency, 50 ms lag: the predictor (trajectory sampled at the action time,
    odometry stamp as the measurement time) tracks the lap's tight turns far better
    than the uncompensated law and brings the robot to rest at the end."""
    pred, traj = follow_lap(dict(predict_latency=0.2, predict_lag_v=LAG, predict_lag_w=LAG))
    bare, _ = follow_lap({})
    rms = lambda r: float(np.sqrt(np.mean(r.error ** 2)))     # noqa: E731
    assert rms(pred) < 0.01
    assert rms(bare) > 10 * rms(pred)
    end = pred.t > traj.t_end + 2.0
    assert float(np.max(pred.error[end])) < 0.002
    assert float(np.max(np.abs(pred.cmd_v[end]))) == 0.0       # finished: at rest


def test_follower_without_predictor_is_unchanged():
    """No predictor: the follower passes no stamp, the law is today's (same as latency 0)."""
    from nonfragile_tracker.control.simulation.follow import Follower
    from nonfragile_tracker.control.simulation.trajectory import load_waypoints
    traj = load_waypoints(CONFIG / 'trajectories' / 'lap.csv')
    K = read_gain_file(CONFIG / 'tracker_gains.yaml')
    a = Follower(Tracker(TrackerConfig(K=K)), traj)
    b = Tracker(TrackerConfig(K=K))
    for k in range(1, 200):
        t = 0.05 * k
        s = traj.sample(t)
        ca = a.step(s.x + 0.01, s.y - 0.02, s.heading + 0.05, t, 0.1)
        cb = b.step(s.x + 0.01, s.y - 0.02, s.heading + 0.05, s, 0.1)
        assert (ca.v, ca.w) == (cb.v, cb.w)


def test_run_paper_flag_refuses_a_second_configuration(capsys):
    """`run --paper` is the paper's configuration; with --gains or compensation: exit 2."""
    for extra in (['--gains', str(CONFIG / 'tracker_gains.yaml')], ['--delay-compensation']):
        assert main(['run', '--paper', *extra]) == 2
        assert "--paper is the paper's configuration" in capsys.readouterr().err
