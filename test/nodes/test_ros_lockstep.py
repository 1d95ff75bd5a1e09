"""The three nodes close the loop over DDS: deterministic lockstep, equal to the in-process
simulation, and the steady-state band of the paper's scenario."""
from pathlib import Path

import numpy as np
import pytest

from nonfragile_tracker.bag.reader import read_bag
from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.control.simulation.tracker import TrackerConfig
from nonfragile_tracker.control.simulation.reference import circle
from nonfragile_tracker.control.simulation.simulate import simulate_tracking
from nonfragile_tracker.workflows.runner import run_composed, run_processes, scenario_parameters
from nonfragile_tracker.interface.scenario import paper_plant_config

from conftest import CONFIG

DURATION = 12.0
#: The paper's ideal plant in lockstep: the max-decay design (the steady band below is pinned
#: to its fast transient; the shipped default decays at 0.66 1/s and is checked on real bases).
GAINS = CONFIG / 'max_decay_gains.yaml'


def params(duration=DURATION, **tracker):
    ov = {'plant': {'ros__parameters': {'duration': duration}},
          'tracker': {'ros__parameters': tracker}}
    return scenario_parameters(CONFIG / 'paper_scenario.yaml', GAINS, ov)


def simulation(steps, **tracker):
    K = read_gain_file(GAINS)
    pc = paper_plant_config()
    return simulate_tracking(pc, TrackerConfig(K=K, A_tau=pc.A_tau, tau=pc.tau, **tracker),
                             circle(), steps)


def run_and_read(tmp_path: Path, name: str, env, composed=False, **tracker):
    run_dir = tmp_path / name
    run_dir.mkdir()
    if composed:
        res = run_composed(params(**tracker), run_dir)
    else:
        res = run_processes(params(**tracker), run_dir, env=env, progress=lambda s: None)
    assert all(c == 0 for c in res.exit_codes.values()), (res.exit_codes, [
        (p.name, p.read_text()[-2000:]) for p in run_dir.glob('*.log')])
    return read_bag(res.bag)


@pytest.fixture(scope='module')
def two_runs(tmp_path_factory):
    import os
    from conftest import unique_domain_id
    env = dict(os.environ, ROS_DOMAIN_ID=str(unique_domain_id('lockstep')))
    tmp = tmp_path_factory.mktemp('lockstep')
    return run_and_read(tmp, 'a', env), run_and_read(tmp, 'b', env)


def test_run_matches_in_process_simulation(two_runs):
    bag = two_runs[0]
    run = bag.run
    steps = int(round(DURATION / 0.01))
    assert len(run.pose) == steps + 1 and len(run.commands) == steps + 1
    # the default lockstep recording is lean: per step odom and cmd_vel; the reference is
    # rebuilt from the recorded trajectory message (test_lean_recording.py)
    for name in ('/odom', '/cmd_vel'):
        assert bag.counts[name] == steps + 1, name
    assert bag.counts['/trajectory_multidof'] == 1 and '/reference/pose' not in bag.counts
    sim = simulation(steps)
    np.testing.assert_allclose(run.pose.x, sim.x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.pose.y, sim.y, rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.commands.v, sim.cmd_v, rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.commands.w, sim.cmd_w, rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.reference.x, sim.xd, rtol=0, atol=1e-12)


def test_two_runs_are_identical(two_runs):
    a, b = two_runs
    for attr in ('x', 'y', 'th', 'v'):
        np.testing.assert_array_equal(getattr(a.run.pose, attr), getattr(b.run.pose, attr))
    np.testing.assert_array_equal(a.run.commands.w, b.run.commands.w)


def test_error_converges_into_the_steady_band(two_runs):
    """Max-decay gain, paper scenario: the A_tau xi(t - tau) term leaves a bias that matches the
    quasi-static prediction -(A + B K + A_tau)^-1 A_tau xi_d (math notes section 7; the
    reference turns at 0.01 rad/s) within 5 % (test_loop.py pins the long-run band)."""
    run = two_runs[0].run
    err = np.hypot(run.pose.x - run.reference.x, run.pose.y - run.reference.y)
    assert err[0] > 0.2                              # starts 0.22 m away
    late = run.pose.t > 8.0
    pc = paper_plant_config()
    A = np.kron(np.eye(2), [[0.0, 1.0], [0.0, 0.0]])
    B = np.kron(np.eye(2), [[0.0], [1.0]])
    K = read_gain_file(GAINS)
    M = np.linalg.solve(A + B @ K + pc.A_tau, pc.A_tau)
    xd = np.stack([run.reference.x, np.zeros_like(run.reference.x), run.reference.y,
                   np.zeros_like(run.reference.y)])[:, late]
    bias = -M @ xd
    predicted = np.hypot(bias[0], bias[2])
    assert predicted.min() > 1e-3                    # a real bias, not round-off
    np.testing.assert_allclose(err[late], predicted, rtol=0.05)


def test_composed_run_equals_separate_processes(tmp_path, two_runs):
    bag = run_and_read(tmp_path, 'composed', None, composed=True)
    np.testing.assert_array_equal(bag.run.pose.x, two_runs[0].run.pose.x)
    np.testing.assert_array_equal(bag.run.commands.w, two_runs[0].run.commands.w)
