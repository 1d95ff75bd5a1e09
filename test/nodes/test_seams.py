"""The seams through ROS: the tracker node runs a second law and the plant node a second base,
each named by a parameter (``controller``, ``model``) and each one new file on PYTHONPATH; the
lockstep run equals the in-process simulation of the same pair to round-off."""
import os
import textwrap

import numpy as np

from nonfragile_tracker.bag.reader import read_bag
from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.control.simulation.tracker import TrackerConfig
from nonfragile_tracker.control.simulation.reference import circle
from nonfragile_tracker.control.simulation.simulate import simulate_tracking
from nonfragile_tracker.workflows.runner import run_processes, scenario_parameters
from nonfragile_tracker.interface.scenario import paper_plant_config

from conftest import CONFIG, unique_domain_id
from seam_files import KANAYAMA, SKID

DURATION = 4.0
GAINS = CONFIG / 'tracker_gains.yaml'


def test_a_second_law_and_base_through_the_nodes_equal_the_simulation(tmp_path, monkeypatch):
    lib = tmp_path / 'lib'
    lib.mkdir()
    monkeypatch.syspath_prepend(str(lib))
    (lib / 'my_law.py').write_text(textwrap.dedent(KANAYAMA))
    (lib / 'my_base.py').write_text(textwrap.dedent(SKID))
    ov = {'plant': {'ros__parameters': {'duration': DURATION, 'model': 'my_base:Skid'}},
          'tracker': {'ros__parameters': {'controller': 'my_law:Kanayama'}}}
    params = scenario_parameters(CONFIG / 'paper_scenario.yaml', GAINS, ov)
    env = dict(os.environ, ROS_DOMAIN_ID=str(unique_domain_id('seams')),
               PYTHONPATH=str(lib) + os.pathsep + os.environ.get('PYTHONPATH', ''))
    run_dir = tmp_path / 'run'
    run_dir.mkdir()
    res = run_processes(params, run_dir, env=env, progress=lambda s: None)
    assert all(c == 0 for c in res.exit_codes.values()), (res.exit_codes, [
        (p.name, p.read_text()[-2000:]) for p in run_dir.glob('*.log')])
    bag = read_bag(res.bag).run
    pc = paper_plant_config()
    sim = simulate_tracking(pc, TrackerConfig(K=read_gain_file(GAINS), A_tau=pc.A_tau,
                                              tau=pc.tau, controller='my_law:Kanayama'),
                            circle(), int(round(DURATION / pc.dt)), plant='my_base:Skid')
    steps = int(round(DURATION / pc.dt))
    assert len(bag.pose) == steps + 1 and len(bag.commands) == steps + 1
    # the nodes ran the pair: poses and commands equal the in-process run's
    np.testing.assert_allclose(bag.pose.x, sim.x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(bag.pose.th, sim.th, rtol=0, atol=1e-9)
    np.testing.assert_allclose(bag.commands.w, sim.cmd_w, rtol=0, atol=1e-9)
    assert np.max(np.abs(sim.cmd_w)) > 1e-3          # and the law did something


def test_a_controller_that_cannot_be_loaded_refuses_to_start(tmp_path):
    import subprocess
    import sys
    env = dict(os.environ, ROS_DOMAIN_ID=str(unique_domain_id('seams-bad')))
    out = subprocess.run(
        [sys.executable, '-m', 'nonfragile_tracker.nodes.tracker', '--ros-args',
         '--params-file', str(GAINS), '-p', 'controller:=no_such_pkg_x:Law'],
        env=env, capture_output=True, text=True, timeout=60)
    assert out.returncode == 2, (out.returncode, out.stderr[-2000:])
    text = out.stdout + out.stderr
    assert "no_such_pkg_x" in text and 'cannot be imported' in text
    assert 'Traceback' not in text
