"""Faults: a dead node ends a lockstep run cleanly; bad bags give clear errors; two systems
run side by side without cross-talk."""
import os
import shutil
import signal
import subprocess
import threading
import time

import numpy as np
import pytest

from nonfragile_tracker.bag.reader import read_bag
from nonfragile_tracker.cli import main
from nonfragile_tracker.workflows import runner
from nonfragile_tracker.workflows.runner import run_processes, scenario_parameters

from conftest import CONFIG, ROOT, domain_ids, unique_domain_id


def params(duration, **plant):
    ov = {'plant': {'ros__parameters': {'duration': duration, **plant}}}
    return scenario_parameters(CONFIG / 'paper_scenario.yaml', CONFIG / 'tracker_gains.yaml', ov)


@pytest.mark.parametrize('sig', [signal.SIGSTOP, signal.SIGKILL])
def test_dead_or_hung_tracker_ends_the_lockstep_run_with_a_readable_bag(tmp_path, sig,
                                                                        monkeypatch):
    """SIGSTOP: the tracker stops answering, the plant aborts after lockstep_timeout (exit 5).
    SIGKILL: the runner sees the dead node and stops the run.  Either way: no hang, a clear
    message, and a closed, readable bag.  (The recorder's drain and the runner's wait for
    the stopped tracker are shortened from 5 s and 10 s: what they end is the same.)"""
    monkeypatch.setattr(runner, 'STOP_WAIT_S', 3.0)
    env = dict(os.environ, ROS_DOMAIN_ID=str(unique_domain_id(f'kill{int(sig)}')))
    hit = threading.Event()
    lines = []
    killed: list[float] = []                # when the tracker was stopped or killed

    def progress(line):
        lines.append(line)
        if 'progress' in line and not hit.is_set():
            out = subprocess.run(['pgrep', '-f', f'nodes.entry tracker.*{tmp_path}'],
                                 capture_output=True, text=True)
            for pid in out.stdout.split():
                os.kill(int(pid), sig)
                killed.append(time.monotonic())
                hit.set()

    start = time.monotonic()
    # SIGSTOP: the plant's lockstep_timeout is what ends the run (4 s: a tracker's first
    # answer can take seconds on a loaded machine); SIGKILL: the default (10 s) never fires
    p = params(200.0, lockstep_timeout=4.0) if sig == signal.SIGSTOP else params(200.0)
    p.setdefault('recorder', {}).setdefault('ros__parameters', {})['drain_timeout'] = 1.0
    res = run_processes(p, tmp_path, env=env, progress=progress)
    assert hit.is_set(), (lines[-10:], runner.log_tail(tmp_path, 'plant'))
    # no hang: the run ends soon after the tracker stopped (timeout 4 s, the runner's wait
    # 3 s, the drain 1 s, teardown); the start-up before it is not what is judged here (it
    # took up to a minute with the whole suite on two cores)
    assert time.monotonic() - killed[0] < 30, time.monotonic() - start
    if sig == signal.SIGSTOP:
        assert res.exit_codes['plant'] == 5
        log = (tmp_path / 'plant.log').read_text()
        assert 'lockstep run aborted' in log and 'no command for step' in log
    else:
        assert res.exit_codes['tracker'] == -signal.SIGKILL
        assert any('exited early' in line and 'tracker' in line for line in lines)
    assert res.exit_codes['recorder'] == 0
    bag = read_bag(res.bag)                                    # closed and readable
    assert 1000 <= len(bag.run.pose) < 20001


def test_bag_commands_reject_bad_bags(tmp_path, capsys):
    assert main(['bag', 'report', str(tmp_path / 'nope')]) == 2
    assert 'does not exist' in capsys.readouterr().err
    # a truncated MCAP without metadata (a killed recorder)
    src = ROOT / 'test' / 'data' / 'golden_paper'
    cut = tmp_path / 'cut'
    cut.mkdir()
    data = (src / 'bag.mcap').read_bytes()
    (cut / 'bag.mcap').write_bytes(data[: len(data) // 2])
    assert main(['bag', 'report', str(cut)]) == 2
    assert 'bag repair' in capsys.readouterr().err
    assert main(['bag', 'repair', str(cut)]) == 0
    out = capsys.readouterr().out
    assert '/odom' in out
    rep = read_bag(tmp_path / 'cut_repaired', strict=False)
    assert 0 < rep.counts['/odom'] < 251
    # a bag without the expected topics
    from nonfragile_tracker.bag.writer import BagWriter
    with BagWriter(tmp_path / 'other', connections={'/chatter': 'std_msgs/msg/UInt64'}) as w:
        w.write('/chatter', 1, b'\x00\x01\x00\x00' + bytes(8))
    assert main(['bag', 'report', str(tmp_path / 'other')]) == 2
    err = capsys.readouterr().err
    assert 'odom' in err and 'cmd_vel' in err
    # the report never overwrites plots unless asked
    shutil.copytree(src, tmp_path / 'g')
    assert main(['bag', 'report', str(tmp_path / 'g')]) == 0
    assert main(['bag', 'report', str(tmp_path / 'g')]) == 2
    assert 'pass --force' in capsys.readouterr().err
    assert main(['bag', 'report', str(tmp_path / 'g'), '--force']) == 0


def test_run_refuses_a_bad_gain_file_and_never_reuses_a_run_dir(tmp_path, capsys):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('tracker:\n  ros__parameters:\n    K: [1.0, 1.0]\n    K_shape: [2, 4]\n')
    assert main(['run', '--gains', str(bad), '--out', str(tmp_path)]) == 2
    assert 'has 2 entries' in capsys.readouterr().err
    assert main(['run', '--name', '../escape', '--out', str(tmp_path), '--no-record',
                 '--duration', '0.1']) == 2
    assert 'escape' in capsys.readouterr().err


def test_two_systems_on_two_domains_do_not_cross_talk(tmp_path):
    """Two lockstep systems at once (one with a perturbed gain) each equal their own run."""
    results = {}

    def run(name, domain, delta):
        env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
        p = params(5.0)
        p['tracker']['ros__parameters']['Delta'] = delta
        d = tmp_path / name
        d.mkdir()
        results[name] = run_processes(p, d, env=env, progress=lambda s: None)

    one, two = domain_ids('two-systems', 2)
    a = threading.Thread(target=run, args=('a', one, [0.0] * 4))
    b = threading.Thread(target=run, args=('b', two, [1.0, 0.0, 0.0, 1.0]))
    a.start(); b.start(); a.join(); b.join()
    bags = {k: read_bag(v.bag) for k, v in results.items()}
    from nonfragile_tracker.control.simulation.gains import read_gain_file
    from nonfragile_tracker.control.simulation.tracker import TrackerConfig
    from nonfragile_tracker.interface.scenario import paper_plant_config
    from nonfragile_tracker.control.simulation.reference import circle
    from nonfragile_tracker.control.simulation.simulate import simulate_tracking
    K = read_gain_file(CONFIG / 'tracker_gains.yaml')
    F = np.full((2, 4), 0.5)
    for name, pert in (('a', None), ('b', F)):
        sim = simulate_tracking(paper_plant_config(), TrackerConfig(K=K, perturbation=pert), circle(), 500)
        assert bags[name].counts['/odom'] == 501
        np.testing.assert_allclose(bags[name].run.pose.x, sim.x, atol=1e-9)


def test_a_node_process_stops_on_sigint_and_a_hung_one_is_killed_with_its_stacks(tmp_path):
    """runner.NodeProcess, the lifecycle of the runner's nodes and the replayer's tracker:
    SIGINT ends a running node cleanly (exit 0); a node that does not end within the wait
    is asked for its stacks (SIGUSR1) and killed."""
    env = runner.isolated_env(dict(os.environ, ROS_DOMAIN_ID=str(unique_domain_id('nodeproc'))))
    pfile = runner.write_parameter_file(params(5.0), tmp_path / 'p.yaml')
    nodes = [runner.NodeProcess('tracker', pfile, tmp_path / f'{name}.log', env)
             for name in ('clean', 'hung')]
    try:
        for node in nodes:
            end = time.monotonic() + 60
            while 'tracker' not in node.log.read_text() and time.monotonic() < end:
                assert node.poll() is None, node.log.read_text()
                time.sleep(0.1)
        clean, hung = nodes
        assert clean.stop(timeout=30) and clean.poll() == 0, clean.log.read_text()
        # a stopped node ends neither on SIGINT nor on SIGUSR1: killed after the wait
        os.kill(hung.proc.pid, signal.SIGSTOP)
        start = time.monotonic()
        assert not hung.stop(timeout=1.0)
        assert hung.poll() == -signal.SIGKILL and time.monotonic() - start < 10
    finally:
        for node in nodes:
            if node.poll() is None:
                node.proc.kill()
                node.proc.wait()
            node.close()
