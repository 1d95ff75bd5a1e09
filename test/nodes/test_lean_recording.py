"""A lean lockstep recording (odom, cmd_vel, run_done and the trajectory messages; no
per-step reference samples, /clock or pose) reports, compares and replays like a full one:
the bag reader rebuilds the reference from the recorded trajectory message with the
tracker's own conversion and sampling."""
import math

import numpy as np
import pytest

from nonfragile_tracker.interface import topics
from nonfragile_tracker.bag.reader import read_bag
from nonfragile_tracker.bag.replay import replay
from nonfragile_tracker.bag.report import bag_report
from nonfragile_tracker.workflows.runner import (lockstep_parameters, recorded_topics, records_samples,
                                       run_composed, scenario_parameters)

from conftest import CONFIG

DURATION = 4.0
STEPS = int(round(DURATION / 0.01))


def params():
    ov = {'plant': {'ros__parameters': {'duration': DURATION}}}
    return scenario_parameters(CONFIG / 'paper_scenario.yaml', CONFIG / 'tracker_gains.yaml', ov)


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    tmp = tmp_path_factory.mktemp('lean')
    out = {}
    for name, kw in (('lean', {}), ('full', {'record_all': True})):
        run_dir = tmp / name
        run_dir.mkdir()
        res = run_composed(params(), run_dir, **kw)
        assert all(c == 0 for c in res.exit_codes.values()), res.exit_codes
        out[name] = res.bag
    return out


def test_lean_is_the_lockstep_default_and_leaves_out_the_samples():
    p = params()
    assert recorded_topics(p) == list(topics.LEAN_TOPICS)
    assert recorded_topics(p, record_all=True) == list(topics.TYPES)
    assert not records_samples(topics.LEAN_TOPICS) and records_samples(topics.TYPES)
    assert lockstep_parameters(True, records_samples(topics.LEAN_TOPICS))['reference'][
        'publish_samples'] is False
    rt = scenario_parameters(CONFIG / 'paper_scenario.yaml', CONFIG / 'tracker_gains.yaml',
                             {'plant': {'ros__parameters': {'mode': 'realtime'}}})
    assert recorded_topics(rt) == list(topics.TYPES)


def test_lean_bag_holds_odom_cmd_vel_and_the_trajectory(bags):
    counts = read_bag(bags['lean']).counts
    assert counts == {'/odom': STEPS + 1, '/cmd_vel': STEPS + 1, '/run_done': 1,
                      '/trajectory_multidof': 1, '/reference/path': 1,
                      '/tracker/trajectory': 1}    # what the tracker followed
    full = read_bag(bags['full']).counts
    for name in ('/clock', '/pose', '/reference/pose', '/reference/twist',
                 '/reference/accel'):
        assert full[name] == STEPS + 1, name


def test_lean_reference_and_errors_equal_the_full_recording(bags):
    lean, full = read_bag(bags['lean']).run, read_bag(bags['full']).run
    assert lean.reference.source == '/tracker/trajectory'     # what the tracker followed
    np.testing.assert_array_equal(lean.reference.stamp_ns, full.reference.stamp_ns)
    for f in ('x', 'y', 'vx', 'vy', 'ax', 'ay'):
        np.testing.assert_allclose(getattr(lean.reference, f), getattr(full.reference, f),
                                   rtol=0, atol=1e-9, err_msg=f)
    np.testing.assert_array_equal(lean.commands.v, full.commands.v)
    a, b = bag_report(bags['lean']), bag_report(bags['full'])
    assert a.matched == b.matched == STEPS + 1
    ma, mb = a.metrics.as_dict(), b.metrics.as_dict()
    for key in ('final_error', 'rms_error', 'rms_error_settled', 'max_error_settled'):
        assert math.isclose(ma[key], mb[key], rel_tol=0, abs_tol=1e-9) or \
            (math.isnan(ma[key]) and math.isnan(mb[key])), key
    assert ma['rms_error'] > 1e-4               # a real error, not zero against itself


def test_replay_of_a_lean_bag_reproduces_its_commands(bags):
    res = replay(bags['lean'])
    assert res.mode == 'lockstep'
    assert res.inputs == {'odom': STEPS + 1, 'trajectory': 1, 'cmd': STEPS + 1}
    assert len(res.commands) == STEPS + 1
    assert res.comparison.equal and res.max_abs_error <= 1e-9
