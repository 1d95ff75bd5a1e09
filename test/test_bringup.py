"""The bring-up's ROS-free steps: robot settings, refusals (not informative, not certifiable),
the files it writes.  The node and its stops are in test/nodes/test_bringup_node.py."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import yaml

from conftest import CONFIG
from nonfragile_tracker.workflows.commissioning import (BringupRefusal, analyse, bringup_limits, design_gain,
                                        identify_samples, write_robot_file)
from nonfragile_tracker.control.identification.identify import read_identification_text
from recordings import record_open_loop
from nonfragile_tracker.control.simulation.gains import read_gain_design, read_gain_file
from nonfragile_tracker.control.simulation.plant import PlantConfig
from nonfragile_tracker.errors import InputError
from nonfragile_tracker.interface.robot import RobotConfig, load_robot_file, parse_robot_parameters

BASE = PlantConfig(dt=0.01, cmd_latency=0.1, lag_v=0.05, lag_w=0.05, odom_rate=50.0,
                   odom_noise=(1e-3, 1e-3, 1e-3), noise_seed=3)


def _ident(lo, hi, lag=0.05):
    """An identification file's text: latency range [lo, hi] s, lags ``lag``."""
    mid = 0.5 * (lo + hi)
    return read_identification_text(yaml.safe_dump({'identification': {
        'source': 'test', 'latency_s': mid, 'latency_interval_s': [mid - 0.002, mid + 0.002],
        'tau_v_s': lag, 'tau_v_interval_s': [lag - 0.002, lag + 0.002], 'tau_w_s': lag,
        'tau_w_interval_s': [lag - 0.002, lag + 0.002], 'odom_rate_hz': 50.0, 'samples': 2000,
        'residual_rms': {'v': 0.005, 'w': 0.01}, 'command_period_s': 0.02,
        'latency_range_s': [lo, hi], 'latency_range_from': '40 command steps'}}))


def test_robot_file_settings_and_the_bringup_limits(tmp_path):
    r = RobotConfig()
    assert (r.odom_topic, r.cmd_vel_topic, r.enable_stamped_cmd_vel) == ('odom', 'cmd_vel',
                                                                          False)
    assert bringup_limits(r) == (0.3, 1.0)                       # the defaults
    slow = parse_robot_parameters({'max_linear_speed': 0.2, 'max_angular_speed': 2.0})
    assert bringup_limits(slow) == (0.2, 1.0)                    # the robot file's if lower
    assert bringup_limits(slow, 0.5, 0.4) == (0.2, 0.4)
    with pytest.raises(InputError, match='max_linear_accel'):
        parse_robot_parameters({'max_linear_accel': -1.0})
    with pytest.raises(InputError, match='enable_stamped_cmd_vel'):
        parse_robot_parameters({'enable_stamped_cmd_vel': 'yes'})
    path = tmp_path / 'robot.yaml'
    path.write_text(yaml.safe_dump({'/**/tracker': {'ros__parameters': {
        'cmd_vel_topic': '/diff_drive_controller/cmd_vel', 'enable_stamped_cmd_vel': True,
        'max_linear_accel': 0.8}}}))
    r2 = load_robot_file(path)
    assert r2.cmd_vel_topic == '/diff_drive_controller/cmd_vel' and r2.enable_stamped_cmd_vel
    path.write_text('other: 1\n')
    with pytest.raises(InputError, match='section'):
        load_robot_file(path)


def test_uninformative_data_is_refused_with_what_to_change():
    # a straight line at constant speed: w never varies
    t = np.arange(0.0, 30.0, 0.02)
    rec = record_open_loop(BASE, t, np.full_like(t, 0.2), np.zeros_like(t))
    with pytest.raises(BringupRefusal, match=r'does not excite the base.*larger box \(--box\)'):
        identify_samples(rec.commands, rec.odometry)
    # too short a recording
    t = np.arange(0.0, 1.0, 0.02)
    rec = record_open_loop(BASE, t, 0.1 + 0.1 * (t > 0.5), 0.3 * (t > 0.5))
    with pytest.raises(BringupRefusal, match='not enough data'):
        identify_samples(rec.commands, rec.odometry)


def test_a_latency_that_jumps_is_refused_naming_it():
    # the base's latency jumps between 0.1 and 0.6 s every 1.5 s: no latency to design for
    sched = []
    for i in range(1, 20):
        sched += [1.5 * i, 0.6 if i % 2 else 0.1]
    base = PlantConfig(dt=0.01, cmd_latency=0.1, lag_v=0.05, lag_w=0.05, odom_rate=50.0,
                       odom_noise=(1e-3, 1e-3, 1e-3), noise_seed=3,
                       cmd_latency_schedule=tuple(sched))
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 30.0, 0.02)
    v = np.repeat(rng.uniform(0.05, 0.3, 20), t.size // 20 + 1)[:t.size]
    w = np.repeat(rng.uniform(-0.8, 0.8, 20), t.size // 20 + 1)[:t.size]
    rec = record_open_loop(base, t, v, w)
    with pytest.raises(BringupRefusal, match=r'the latency is not pinned down: 0\.\d+ s .*'
                       r'reduce the variation'):
        identify_samples(rec.commands, rec.odometry)


def test_informative_steps_are_identified():
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 30.0, 0.02)
    hold = np.repeat(rng.uniform(0.05, 0.3, 20), t.size // 20 + 1)[:t.size]
    turn = np.repeat(rng.uniform(-0.8, 0.8, 20), t.size // 20 + 1)[:t.size]
    rec = record_open_loop(BASE, t, hold, turn)
    res = identify_samples(rec.commands, rec.odometry, accel_segment=False)
    assert abs(res.latency_s - 0.1) <= 0.02                      # one odometry period
    assert res.tau_v_s == pytest.approx(0.05, rel=0.2)
    assert any('linear and angular acceleration limit not seen (0 = unknown): the excitation '
               'had no acceleration segment' in n for n in res.notes)


def test_the_default_excitation_identifies_both_limits_or_says_not_seen(tmp_path):
    """Issue 39's base that is not ours (120 ms, 60 ms lags, 0.8 m/s^2 / 2.5 rad/s^2,
    30 Hz): the default excitation (its acceleration segment) makes both limits bind, and
    they are identified within 10 % (a sweep of 10 bases, 0.5-3 m/s^2, 1.5-6 rad/s^2, 20-50
    Hz, 0-150 ms: 0-2 % where a limit binds for several odometry periods, one 2 m/s^2 at
    20 Hz +42 %) and written to the robot file; on a base without limits they are not seen,
    said so, and stay 0."""
    from nonfragile_tracker.workflows.commissioning import write_report
    from recordings import record_bringup
    base = PlantConfig(dt=0.01, cmd_latency=0.12, lag_v=0.06, lag_w=0.06, odom_rate=30.0,
                       odom_noise=(1e-3, 1e-3, 1e-3), noise_seed=1, max_linear_accel=0.8,
                       max_angular_accel=2.5)
    for plant, limits in ((base, (0.8, 2.5)),
                          (dataclasses.replace(base, max_linear_accel=0.0,
                                               max_angular_accel=0.0), (0.0, 0.0))):
        rec = record_bringup(plant)
        res = identify_samples(rec.commands, rec.odometry, odom_period=1 / 30)
        assert res.latency_s == pytest.approx(0.12, abs=1 / 30)
        assert (res.max_linear_accel, res.max_angular_accel) == pytest.approx(limits, rel=0.1)
        written = load_robot_file(write_robot_file(tmp_path / 'robot.yaml', RobotConfig(), res))
        assert (written.max_linear_accel, written.max_angular_accel) == pytest.approx(
            limits, rel=0.1)
    assert sum('acceleration limit not seen (0 = unknown): it did not bind' in n
               for n in res.notes) == 2
    write_report(tmp_path, {'ok': True, 'latency_s': 0.12, 'latency_interval_s': [0.1, 0.13],
                            'latency_range_s': [0.1, 0.13], 'tau_v_s': 0.06, 'tau_w_s': 0.06,
                            'max_linear_accel': 0.0, 'max_angular_accel': 2.5, 'summary': ''},
                 None, {})
    text = (tmp_path / 'report.md').read_text()
    assert 'acceleration limits not seen (0 = unknown) m/s^2, 2.5 rad/s^2' in text


def test_latency_beyond_certifiable_is_refused_naming_the_latency(tmp_path):
    gain = tmp_path / 'g.yaml'
    with pytest.raises(BringupRefusal) as err:
        design_gain(_ident(0.10, 0.45, lag=0.08), CONFIG / 'paper_problem.yaml', gain)
    text = str(err.value)
    assert 'the identified latency 0.2750 s' in text and '[0.1000, 0.4500] s' in text
    assert 'no gain was written' in text and not gain.exists()


def test_design_writes_the_gain_and_the_robot_file(tmp_path):
    ident = _ident(0.100, 0.104)
    out = design_gain(ident, CONFIG / 'paper_problem.yaml', tmp_path / 'g.yaml',
                      extra={'max_linear_accel': 1.0})
    K = read_gain_file(out.gain_file)
    assert K.shape == (2, 4)
    params = yaml.safe_load(out.gain_file.read_text())['/**/tracker']['ros__parameters']
    assert params['predict_latency'] == pytest.approx(0.100)
    assert params['max_linear_accel'] == 1.0
    design = read_gain_design(out.gain_file)
    assert design['lag_certified_h_max'] >= out.plan.h_max + out.plan.lag - 1e-9
    robot = parse_robot_parameters({'max_angular_accel': 2.5})
    ident2 = read_identification_text(yaml.safe_dump({'identification': {
        'source': 'b', 'latency_s': 0.1, 'latency_interval_s': [0.099, 0.101],
        'tau_v_s': 0.05, 'tau_v_interval_s': [0.049, 0.051], 'tau_w_s': 0.05,
        'tau_w_interval_s': [0.049, 0.051], 'odom_rate_hz': 50.0, 'samples': 100,
        'residual_rms': {'v': 0.01, 'w': 0.01}, 'max_linear_accel': 0.9,
        'max_angular_accel': 3.1}}))
    path = write_robot_file(tmp_path / 'robot.yaml', robot, ident2)
    written = load_robot_file(path)
    assert written.max_linear_accel == pytest.approx(0.9)       # unknown: identified
    assert written.max_angular_accel == pytest.approx(2.5)      # known: kept


def test_analyse_reports_the_phase_and_cause_of_a_refusal(tmp_path):
    out = analyse(tmp_path / 'missing_bag', tmp_path, {
        'robot': dataclasses.asdict(RobotConfig()),
        'problem': str(CONFIG / 'paper_problem.yaml'),
        'odom_period': 0.02, 'accel_segment': False})
    assert out['ok'] is False and out['phase'] == 'identify'
    assert 'missing_bag' in out['refusal']


def test_dry_run_prints_the_extent_and_moves_nothing(capsys, tmp_path):
    from nonfragile_tracker.cli import main
    assert main(['bringup', '--dry-run', '--box', '0.8', '--max-speed', '0.2',
                 '--out', str(tmp_path)]) == 0
    out = capsys.readouterr().out
    first = out.splitlines()[0]
    far = float(first.split('farthest ')[1].split(' m')[0])
    assert far <= 0.8 - 0.5 * (0.05 + 0.15 * 0.8)
    assert 'dry run: nothing moved' in out
    assert not any(tmp_path.iterdir())                     # no run folder, no ROS
    # a box too small, a bad robot file: refused before anything starts (exit 2)
    assert main(['bringup', '--dry-run', '--box', '0.1']) == 2
    bad = tmp_path / 'robot.yaml'
    bad.write_text("'/**/tracker': {ros__parameters: {max_linear_speed: -1.0}}\n")
    assert main(['bringup', '--dry-run', '--robot', str(bad)]) == 2
    err = capsys.readouterr().err
    assert 'at least 0.3 m' in err and 'max_linear_speed is -1.0: it must be above 0' in err
