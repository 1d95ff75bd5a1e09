"""Batch simulation and the robustness study: a case of a batch is the single run."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from batch_checks import single_runs, trace_deviation
from conftest import ROOT
from nonfragile_tracker import cli
from nonfragile_tracker.control.simulation import study as study_mod
from nonfragile_tracker.control.simulation.batch import (BatchCases, BatchError, PathBatch,
                                                         perturbation_schedule, sample_deltas,
                                                         segment_index, simulate_batch,
                                                         simulate_delay_loop_batch)
from nonfragile_tracker.control.simulation.gains import read_gain_design, read_gain_file
from nonfragile_tracker.control.simulation.plant import PlantConfig
from nonfragile_tracker.control.simulation.tracker import TrackerConfig
from nonfragile_tracker.control.synthesis.problem import load_problem
from nonfragile_tracker.control.simulation.reference import circle
from nonfragile_tracker.control.simulation.simulate import simulate_delay_loop, simulate_tracking
from nonfragile_tracker.control.simulation.study import StudySpec, run_study, summarize
from nonfragile_tracker.interface.scenario import paper_plant_config

CONFIG = ROOT / 'config'
GAINS = CONFIG / 'max_decay_gains.yaml'     # its record: Theorem 1's certified_latency


def K():
    return read_gain_file(GAINS)


def paper_EF():
    p = load_problem(CONFIG / 'paper_problem.yaml')
    return p.E, p.F


def worst_deviation(plant, tracker, path, steps, cases, exact):
    """Largest |batch - single run| over every case and logged field; settling times."""
    br = simulate_batch(plant, tracker, path, steps, cases, record=True, exact=exact)
    worst = 0.0
    for i, run in single_runs(plant, tracker, path, steps, cases):
        worst = max(worst, trace_deviation(run, br, i))
        if exact:
            m = run.metrics(tolerance=br.tolerance)
            assert m.settling_time == pytest.approx(br.settling_time[i], abs=1e-12, nan_ok=True)
            assert m.final_error == pytest.approx(br.final_error[i], abs=1e-12)
            assert m.rms_error == pytest.approx(br.rms_error[i], rel=1e-9)
    return worst


@pytest.mark.parametrize('exact', [True, False])
def test_paper_scenario_cases_equal_single_runs(exact):
    """Paper plant (A_tau, tau = 0.2 s), per-case Delta, pose and speed; with and without
    delay compensation."""
    rng = np.random.default_rng(3)
    n = 4
    pc = paper_plant_config()
    E, F = paper_EF()
    P = perturbation_schedule(E, F, sample_deltas(rng, n, 1, (2, 2)))
    cases = BatchCases(n, perturbation=P, x0=0.7 + rng.uniform(-0.2, 0.2, n),
                       th0=rng.uniform(-3.0, 3.0, n), v0=rng.uniform(0.0, 0.2, n))
    assert worst_deviation(pc, TrackerConfig(K=K()), circle(), 1500, cases, exact) < 1e-12
    comp = TrackerConfig(K=K(), delay_compensation=True, A_tau=pc.A_tau, tau=pc.tau)
    assert worst_deviation(pc, comp, circle(), 1500, cases, exact) < 1e-12


@pytest.mark.parametrize('exact', [True, False])
def test_latency_lag_and_decimated_noisy_odometry_cases_equal_single_runs(exact):
    """Issue 11's base (latency, lag, 50 Hz noisy odometry) with per-case latencies, lags,
    acceleration limits, odometry latencies, noise and figure-eight parameters."""
    rng = np.random.default_rng(4)
    n = 5
    pc = PlantConfig(dt=0.01, x0=0.0, y0=-0.1, th0=math.pi / 4, v0=0.0, cmd_latency=0.1,
                     lag_v=0.05, lag_w=0.05, odom_rate=50.0, odom_noise=(1e-3,) * 3,
                     noise_seed=1)
    tc = TrackerConfig(K=K(), dt=0.02)
    E, F = paper_EF()
    cases = BatchCases(
        n, cmd_latency=[0.0, 0.03, 0.1, 0.2, 0.1], lag_v=rng.uniform(0, 0.1, n),
        lag_w=[0.0, 0.05, 0.1, 0.02, 0.0], max_linear_accel=[0.0, 0.5, 2.0, 0.0, 1.0],
        max_angular_accel=[0.0, 1.0, 5.0, 2.0, 0.0], odom_latency=[0.0, 0.02, 0.05, 0.0, 0.03],
        odom_noise=np.abs(rng.normal(0, 2e-3, (n, 3))) * np.array([[0], [1], [1], [0], [1]]),
        noise_seed=np.arange(n),
        perturbation=perturbation_schedule(E, F, sample_deltas(rng, n, 1, (2, 2))))
    path = PathBatch('figure_eight', radius=rng.uniform(0.5, 1.5, n),
                     rate=rng.uniform(0.1, 0.3, n), phase=rng.uniform(0, 1, n))
    assert worst_deviation(pc, tc, path, 1500, cases, exact) < 1e-12
    # odometry rates differing between cases (each tracker at its odometry period)
    mixed = BatchCases(n, odom_rate=[0.0, 50.0, 25.0, 50.0, 20.0],
                       odom_latency=[0.0, 0.02, 0.05, 0.0, 0.1], cmd_latency=[0, 0.05, 0, 0.1, 0])
    assert worst_deviation(PlantConfig(dt=0.01, x0=0.1, v0=0.05), TrackerConfig(K=K()), path,
                           800, mixed, exact) < 1e-12


def test_a_shared_waypoint_trajectory_to_rest_equals_single_runs():
    """The lap of config/trajectories/lap.csv, started at rest and tracked to its end (where
    the speed returns to 0 and w = ../v amplifies round-off): the default exact mode."""
    from nonfragile_tracker.control.simulation.trajectory import load_waypoints
    traj = load_waypoints(CONFIG / 'trajectories' / 'lap.csv')
    s0 = traj.sample(traj.t_start)
    pc = PlantConfig(x0=s0.x, y0=s0.y, th0=s0.heading)
    cases = BatchCases(3, x0=s0.x + np.array([0.0, 0.05, -0.05]), th0=s0.heading + 0.1)
    assert worst_deviation(pc, TrackerConfig(K=K()), traj, 1500, cases, True) < 1e-12


def test_switching_perturbation_acts_from_its_switch_time():
    """Two segments: identical to the first constant perturbation until the switch, then
    not; identical segments are a constant perturbation."""
    pc = paper_plant_config()
    E, F = paper_EF()
    Pa = perturbation_schedule(E, F, -np.eye(2))
    Pb = perturbation_schedule(E, F, np.eye(2))
    tc = TrackerConfig(K=K())
    sched = BatchCases(2, perturbation=np.array([[Pa, Pb], [Pa, Pa]]), hold=2.0)
    const = BatchCases(2, perturbation=np.array([Pa, Pa]))
    a = simulate_batch(pc, tc, circle(), 600, sched, record=True)
    b = simulate_batch(pc, tc, circle(), 600, const, record=True)
    switch = 200                                    # t = 2 s
    assert np.array_equal(a.trace['cmd_w'][:switch], b.trace['cmd_w'][:switch])
    assert np.max(np.abs(a.trace['cmd_w'][switch:, 0] - b.trace['cmd_w'][switch:, 0])) > 1e-4
    assert np.array_equal(a.trace['x'][:, 1], b.trace['x'][:, 1])
    assert [segment_index(k, 0.01, 2_000_000_000, 2) for k in (0, 199, 200, 399, 400)] == \
        [0, 0, 1, 1, 0]
    with pytest.raises(BatchError, match='time-varying'):
        sched.configs(0, pc, tc)


def test_sampled_deltas_are_within_the_unit_ball():
    rng = np.random.default_rng(0)
    D = sample_deltas(rng, 2000, 3, (2, 2))
    norms = np.linalg.norm(D, ord=2, axis=(-2, -1))
    assert norms.max() <= 1.0 + 1e-12
    assert norms.min() >= 0.0 and norms.max() > 0.99      # the whole range is sampled
    edge = np.linalg.norm(sample_deltas(rng, 500, 1, (2, 3), radius=(1.0, 1.0)), ord=2,
                          axis=(-2, -1))
    assert np.max(np.abs(edge - 1.0)) < 1e-12
    E, F = paper_EF()
    P = perturbation_schedule(E, F, D[:5, 0])
    assert np.max(np.abs(P - np.array([E @ d @ F for d in D[:5, 0]]))) < 1e-15


def test_batched_delay_loop_equals_single_runs():
    rng = np.random.default_rng(2)
    A1 = np.diag([0.01, 0.0, 0.02, 0.0])
    base = np.array([[0, 1, 0, 0], [-2, -3, 0, 0], [0, 0, 0, 1], [0, 0, -2, -3.0]])
    A0 = base + 0.3 * rng.standard_normal((3, 4, 4))
    xi0 = rng.standard_normal((3, 4))
    t, xi = simulate_delay_loop_batch(A0, A1, 0.2, xi0, 2.0, dt=1e-3)
    for i in range(3):
        one = simulate_delay_loop(A0[i], A1, 0.2, xi0[i], 2.0, dt=1e-3)
        assert np.array_equal(one.t, t)
        assert np.max(np.abs(one.xi - xi[:, i])) < 1e-12


def test_unsupported_and_bad_inputs_are_refused():
    pc, k = paper_plant_config(), K()
    with pytest.raises(BatchError, match='predictor'):
        simulate_batch(pc, TrackerConfig(K=k, predict_latency=0.1), circle(), 10)
    with pytest.raises(BatchError, match=r'x0\[1\]'):
        simulate_batch(pc, TrackerConfig(K=k), circle(), 10, BatchCases(2, x0=[0.0, math.nan]))
    with pytest.raises(BatchError, match='cmd_latency'):
        simulate_batch(pc, TrackerConfig(K=k), circle(), 10, BatchCases(2, cmd_latency=-0.1))
    with pytest.raises(BatchError, match='hold'):
        simulate_batch(pc, TrackerConfig(K=k), circle(), 10,
                       BatchCases(1, perturbation=np.zeros((1, 2, 2, 4))))
    with pytest.raises(BatchError, match='3 numbers'):
        simulate_batch(pc, TrackerConfig(K=k), circle(), 10, BatchCases(3, y0=[0.0, 1.0]))


def study_setup():
    pc = paper_plant_config()
    tc = TrackerConfig(K=K())
    path = PathBatch('circle', 0.5, 0.01)
    return pc, tc, path


def test_study_fractions_and_percentiles_match_single_runs(monkeypatch):
    """Every case re-simulated alone: the same settling times, steady errors,
    percentiles and fraction inside the certified region; two processes give the
    same numbers as one."""
    pc, tc, path = study_setup()
    E, F = paper_EF()
    design = read_gain_design(GAINS)
    spec = StudySpec(cases=12, seed=7, duration=8.0, latency=(0.0, 0.35),
                     pose_spread=(0.1, 0.3), delta_norm=(0.0, 1.3))
    res = run_study(spec, pc, tc, path, E, F, design, jobs=1)
    summ = summarize(res)
    h = design['certified_latency']
    steps = res.run.steps
    D = sample_deltas(np.random.default_rng(7), 12, 1, (2, 2), radius=(0.0, 1.3))  # its draw
    assert np.array_equal(res.cases.batch.perturbation, perturbation_schedule(E, F, D))
    settle, steady, inside = [], [], []
    for i in range(spec.cases):
        pci, tci = res.cases.batch.configs(i, pc, tc)
        run = simulate_tracking(pci, tci, circle(), steps)
        settle.append(run.metrics(tolerance=0.01).settling_time)
        steady.append(run.error[run.t >= 4.0].max())
        inside.append(np.linalg.norm(D[i, 0], 2) <= 1.0 and pci.cmd_latency <= h)
    settle, steady, inside = np.array(settle), np.array(steady), np.array(inside)
    assert np.allclose(res.run.settling_time, settle, atol=1e-12, equal_nan=True)
    assert np.max(np.abs(res.run.steady_error - steady)) < 1e-12
    assert np.array_equal(res.inside, inside) and 0 < inside.sum() < spec.cases
    assert summ['inside_fraction'] == pytest.approx(inside.mean(), abs=0)
    ok = np.isfinite(settle)
    for p in (50, 90, 99):
        assert summ['all']['settling_time'][f'p{p}'] == pytest.approx(
            np.percentile(settle[ok], p), abs=1e-12)
        assert summ['all']['steady_error'][f'p{p}'] == pytest.approx(
            np.percentile(steady, p), abs=1e-12)
        assert summ['inside']['steady_error'][f'p{p}'] == pytest.approx(
            np.percentile(steady[inside], p), abs=1e-12)
    assert summ['worst_steady_error']['index'] == int(np.argmax(steady))
    assert summ['all']['settled_fraction'] == pytest.approx(ok.mean(), abs=0)
    monkeypatch.setattr(study_mod, 'MIN_CASES_PER_JOB', 1)
    two = run_study(spec, pc, tc, path, E, F, design, jobs=2)
    assert two.jobs == 2
    assert np.array_equal(two.run.steady_error, res.run.steady_error)
    assert np.array_equal(two.run.settling_time, res.run.settling_time, equal_nan=True)


def test_study_on_a_dask_local_cluster_equals_the_local_run(monkeypatch):
    """The study's shares through Dask (an in-process LocalCluster, the executor
    abstraction of ``nonfragile_tracker.parallel``) give the numbers of one process."""
    import distributed          # pinned in requirements.txt: the suite runs the Dask path
    pc, tc, path = study_setup()
    E, F = paper_EF()
    spec = StudySpec(cases=6, seed=3, duration=3.0, latency=(0.0, 0.2))
    one = run_study(spec, pc, tc, path, E, F, None, jobs=1)
    monkeypatch.setattr(study_mod, 'MIN_CASES_PER_JOB', 1)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        got = run_study(spec, pc, tc, path, E, F, None, jobs=2, executor=client.get_executor())
    assert got.jobs == 2
    assert np.array_equal(got.run.steady_error, one.run.steady_error)
    assert np.array_equal(got.run.settling_time, one.run.settling_time, equal_nan=True)
    assert np.array_equal(got.inside, one.inside)


def test_study_command_writes_json_and_plot(tmp_path, capsys):
    out, png = tmp_path / 's.json', tmp_path / 's.png'
    code = cli.main(['study', str(GAINS), '--cases', '30', '--duration', '3', '--jobs', '1',
                     '--latency', '0', '0.3', '--delta', 'random', '--hold', '0.5',
                     '--json', str(out), '--plot', str(png)])
    assert code == 0
    data = json.loads(out.read_text())
    assert len(data['cases']) == 30 and data['spec']['delta'] == 'random'
    inside = [c['inside'] for c in data['cases']]
    assert data['inside_fraction'] == pytest.approx(np.mean(inside), abs=0)
    assert all(c['delta_norm'] <= 1.0 + 1e-12 for c in data['cases'])
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    assert 'inside the certified region' in capsys.readouterr().out


@pytest.mark.parametrize('argv', [
    ['study', 'no/such/gains.yaml', '--cases', '2'],
    ['study', str(GAINS), '--cases', '0'],
    ['study', str(GAINS), '--latency', '0.3', '0.1', '--cases', '2'],
    ['study', str(GAINS), '--duration', 'nan'],
    ['study', str(GAINS), '--problem', str(CONFIG / 'paper_scenario.yaml'), '--cases', '2'],
    ['study', str(CONFIG / 'paper_problem.yaml'), '--cases', '2'],
    ['study', str(GAINS), '--cases', '2', '--scheduler', 'tcp://127.0.0.1:1'],
    ['study', str(GAINS), '--cases', '2', '--executor', 'ray'],
])
def test_study_bad_input_exits_2(argv, capsys):
    try:
        code = cli.main(argv)
    except SystemExit as exc:                 # argparse usage errors
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    assert 'error' in err and 'Traceback' not in err
