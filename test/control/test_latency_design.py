"""latency-design: library figures, lagged loop, gain file design record, CLI exit codes."""
import subprocess
import sys

import numpy as np
import pytest
import yaml

from nonfragile_tracker.cli import main
from nonfragile_tracker.control.synthesis.delay import delay_margin
from nonfragile_tracker.control.simulation.gains import (DESIGN_SECTION, read_gain_design,
                                                         read_gain_file, write_gain_file)
from nonfragile_tracker.control.synthesis.input_delay import certify_input_delay
from nonfragile_tracker.control.synthesis.latency_design import (design_for_latency, lagged_problem,
                                                                 perturbation_set)
from nonfragile_tracker.control.synthesis.problem import Problem
from nonfragile_tracker.errors import InputError

from conftest import CONFIG, ROOT, DI_PROBLEM

#: Depends on linear algebra: make test runs it again under a second BLAS kernel (Makefile).
pytestmark = pytest.mark.numerical

PAPER = str(CONFIG / 'paper_problem.yaml')


@pytest.fixture(scope='module')
def di(tmp_path_factory):
    path = tmp_path_factory.mktemp('di') / 'di.yaml'
    path.write_text(DI_PROBLEM)
    return path


def di_problem():
    return Problem(A=np.array([[0.0, 1.0], [0.0, 0.0]]), B=np.array([[0.0], [1.0]]),
                   A_tau=np.zeros((2, 2)), tau=0.1, E=np.eye(1), F=np.array([[0.2, 0.2]]),
                   name='di', perturbations={'minus': -np.eye(1), 'plus': np.eye(1)})


def test_lagged_problem_structure():
    p = di_problem()
    lp = lagged_problem(p, 0.05)
    assert lp.A.shape == (3, 3) and lp.B.shape == (3, 1) and lp.F.shape == (1, 3)
    np.testing.assert_array_equal(lp.A[:2, 2:], p.B)
    assert lp.A[2, 2] == pytest.approx(-20.0) and lp.B[2, 0] == pytest.approx(20.0)
    with pytest.raises(InputError):
        lagged_problem(p, 0.0)


def test_max_delay_design_with_lag_is_checked_exactly():
    p = di_problem()
    r = design_for_latency(p, 0.02, 0.1, gain_bound=3.0, objective='max-delay', lag=0.05,
                           tol=0.01)
    assert r.certified_h_max >= 0.15 and r.lag_certified_h_max >= 0.1
    assert r.gain_norm <= 3.0 * (1 + 1e-9) and r.synthesis.verification.ok
    # exact delay margins exceed the certified figures, without and with the lag
    lp = lagged_problem(p, 0.05)
    K_aug = np.hstack([r.K, np.zeros((1, 1))])
    for D in perturbation_set(p):
        assert delay_margin(p.A, p.B @ (r.K + p.E @ D @ p.F)) > r.certified_h_max
        assert delay_margin(lp.A, lp.B @ (K_aug + lp.E @ D @ lp.F)) > r.lag_certified_h_max
    # the exact figures are the lagged loop's (the robot's), above its certified latency
    assert r.true_delay_margin > r.lag_certified_h_max and r.abscissa_at_h_max < 0
    # the lagged certificate is a real one (verified in numpy)
    c = certify_input_delay(lp, K_aug, 0.02, 0.1)
    assert c.certified and c.verification.ok


def test_design_record_round_trip(tmp_path):
    K = np.array([[-1.0, -2.0]])
    meta = {'latency_interval': [0.0, 0.1], 'certified_h_max': 0.3, 'objective': 'decay',
            'state_delay_in_certificate': False}
    out = write_gain_file(tmp_path / 'g.yaml', K, comment='hello', design=meta)
    # exact by construction: the same K written and read back in this process (YAML floats
    # round-trip exactly)
    np.testing.assert_array_equal(read_gain_file(out), K)
    assert read_gain_design(out) == meta
    data = yaml.safe_load(out.read_text())
    assert set(data) == {'/**/tracker', DESIGN_SECTION}
    assert read_gain_design(CONFIG / 'paper_problem.yaml') is None
    with pytest.raises(InputError):
        write_gain_file(tmp_path / 'h.yaml', K, design={'bad': None})


@pytest.mark.ros
def test_gain_file_with_design_record_loads_as_ros_params_file(tmp_path):
    out = write_gain_file(tmp_path / 'g.yaml', np.array([[-1.0, -2.0]]),
                          design={'certified_h_max': 0.3, 'latency_interval': [0.0, 0.1]})
    code = ('import sys, rclpy\nfrom rclpy.node import Node\n'
            "rclpy.init(args=['--ros-args', '--params-file', sys.argv[1]])\n"
            "n = Node('tracker')\nn.declare_parameter('K', [0.0])\n"
            "print(n.get_parameter('K').value)\nn.destroy_node()\nrclpy.shutdown()\n")
    proc = subprocess.run([sys.executable, '-c', code, str(out)], capture_output=True,
                          text=True, timeout=60, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == '[-1.0, -2.0]'


def test_cli_writes_gain_file_with_record(tmp_path, di, capsys):
    out = tmp_path / 'gains.yaml'
    assert main(['latency-design', str(di), '--delay-interval', '0', '0.1', '--objective',
                 'max-delay', '-o', str(out)]) == 0
    text = capsys.readouterr().out
    assert 'certified: every latency in [0,' in text and '-> OK' in text
    meta = read_gain_design(out)
    K = np.array(yaml.safe_load(out.read_text())['/**/tracker']['ros__parameters']['K'])
    assert meta['latency_interval'] == [0.0, 0.1] and meta['objective'] == 'max-delay'
    assert meta['certified_h_max'] >= 0.1 and meta['gain_bound'] == 3.0
    assert meta['true_delay_margin'] > meta['certified_h_max']
    assert np.linalg.norm(K.reshape(1, 2), 2) == pytest.approx(meta['gain_norm'])
    assert main(['latency-design', str(di), '--delay-interval', '0', '0.1', '-o',
                 str(out)]) == 2                                     # never overwrites
    assert 'pass --force' in capsys.readouterr().err


@pytest.mark.parametrize('args', [
    ['--delay-interval', '0.2', '0.1'], ['--delay-interval', 'nan', '0.1'],
    ['--delay-interval', '0', '0'], ['--delay-interval', '0', 'inf'],
    ['--delay-interval', '0', '0.1', '--gain-bound', '-1'],
    ['--delay-interval', '0', '0.1', '--gain-bound', 'nan'],
    ['--delay-interval', '0', '0.1', '--lag', '-0.1'],
    ['--delay-interval', '0', '0.1', '--objective', 'fast'],
    ['--delay-interval', '0', 'x'], []])
def test_cli_bad_numbers_exit_2(args, capsys):
    with pytest.raises(SystemExit) as exc:
        rc = main(['latency-design', PAPER] + args)
        raise SystemExit(rc)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert 'error' in err and 'Traceback' not in err


def test_cli_infeasible_exits_3(tmp_path, di, capsys):
    out = tmp_path / 'g.yaml'
    rc = main(['latency-design', str(di), '--delay-interval', '0', '5',
               '--objective', 'max-delay', '-o', str(out)])
    assert rc == 3 and not out.exists()
    assert 'below the 5 s asked for' in capsys.readouterr().err


def delayed_problem():
    """The double integrator with a state delay (exact figures must include it)."""
    p = di_problem()
    return Problem(A=p.A, B=p.B, A_tau=np.array([[0.0, 0.0], [-0.3, 0.0]]), tau=0.1, E=p.E,
                   F=p.F, name='di-tau', perturbations=dict(p.perturbations),
                   options={'gain_bound': 3.0})


def test_exact_abscissa_matches_the_one_delay_analysis_and_converges_with_a_state_delay():
    from nonfragile_tracker.control.synthesis.delay import spectral_abscissa
    from nonfragile_tracker.control.synthesis.latency_design import exact_abscissa
    p = delayed_problem()
    K = np.array([[-2.0, -2.5]])
    A1 = p.B @ K
    for h in (0.02, 0.15, 0.4):
        assert exact_abscissa(p.A, np.zeros((2, 2)), 0.1, A1, h) == pytest.approx(
            spectral_abscissa(p.A, A1, h), abs=1e-9)
        two = exact_abscissa(p.A, p.A_tau, p.tau, A1, h)
        assert two == pytest.approx(exact_abscissa(p.A, p.A_tau, p.tau, A1, h, N=40), abs=1e-9)
        # the state delay moves the roots: the figure is not the one-delay one
        assert abs(two - spectral_abscissa(p.A, A1, h)) > 1e-3
    # h = 0 and no delay at all: the eigenvalues of the delay-free matrix
    assert exact_abscissa(p.A, np.zeros((2, 2)), 0.1, A1, 0.0) == pytest.approx(
        max(np.linalg.eigvals(p.A + A1).real))


def test_exact_figures_include_the_state_delay_and_cover_the_interval():
    from nonfragile_tracker.control.synthesis.latency_design import exact_abscissa, exact_figures
    p = delayed_problem()
    K = np.array([[-2.0, -2.5]])
    margin, at_max, worst = exact_figures(p, K, 0.05, 0.2, samples=5)
    A1s = [p.B @ (K + p.E @ D @ p.F) for D in perturbation_set(p, K, 0.2)]
    # a root on the imaginary axis at the margin for the worst D, none just below it
    ab = [exact_abscissa(p.A, p.A_tau, p.tau, A1, margin + 2e-4) for A1 in A1s]
    assert max(ab) >= 0
    assert max(exact_abscissa(p.A, p.A_tau, p.tau, A1, margin - 2e-4) for A1 in A1s) < 0
    # differs from the margin without A_tau (the figure before the fix)
    assert abs(margin - min(delay_margin(p.A, A1) for A1 in A1s)) > 1e-3
    hs = np.linspace(0.05, 0.2, 5)
    assert worst == pytest.approx(max(exact_abscissa(p.A, p.A_tau, p.tau, A1, h)
                                      for A1 in A1s for h in hs))
    assert at_max == pytest.approx(max(exact_abscissa(p.A, p.A_tau, p.tau, A1, 0.2)
                                       for A1 in A1s))
    assert worst >= at_max


def test_a_design_with_a_lag_prints_only_the_lagged_loops_figures():
    p = delayed_problem()
    r = design_for_latency(p, 0.0, 0.05, gain_bound=3.0, lag=0.05)
    text = r.summary()
    lp = lagged_problem(p, 0.05)
    K_aug = np.hstack([r.K, np.zeros((1, 1))])
    from nonfragile_tracker.control.synthesis.latency_design import exact_figures
    margin, _, worst = exact_figures(lp, K_aug, 0.0, 0.05)
    assert r.true_delay_margin == pytest.approx(margin) and r.worst_abscissa == worst < 0
    assert f'{r.lag_certified_h_max:.4g}' in text and 'lagged loop' in text
    # the no-lag latency is not printed (it is not the robot's) and every printed latency
    # is below the lagged loop's exact margin
    assert 'certified: every latency' not in text
    assert text.count('every latency in') == 1 and 'certified (with the actuator lag' in text
    assert r.lag_certified_h_max < r.true_delay_margin
    meta = r.metadata()
    assert meta['state_delay_in_exact_check'] is True and meta['exact_figures_loop'] == 'lagged'
    assert meta['true_delay_margin'] == pytest.approx(margin)


def test_congruent_verification_accepts_a_strict_point_the_relative_test_refuses(paper_problem):
    """[0, 0.2] s at alpha 0.71: t = 0.01 in the solver's coordinates, max eig Psi = -1.5e-7
    against 1e-9 ||Psi|| = 1.05e-6 in the original ones (cond(X) about 50)."""
    from nonfragile_tracker.control.synthesis import input_delay as idm
    p = paper_problem
    r = idm.synthesize_input_delay(p, 0.0, 0.2, alpha=0.71, eps=0.31622776601683794,
                                   gain_bound=8.67)
    v = r.verification
    assert v.ok and v.congruent and r.margin_achieved > 1e-3
    assert -v.tolerance * v.scale < v.max_eig_Psi < 0         # fails only the relative test
    # the certificate itself: Psi < 0 (inertia is that of the congruent matrix)
    Psi = idm.input_delay_verification_matrix(p.A, p.B, p.A_tau, p.tau, p.E, p.F, r.K, 0.0,
                                              0.2, 0.71, r.certificate)
    assert np.linalg.eigvalsh(Psi)[-1] < 0


@pytest.mark.parametrize('kw, match', [
    (dict(h_min=-0.1), 'h_min: expected a number >= 0, got -0.1'),
    (dict(h_min=True), 'h_min: expected a number, got True'),
    (dict(h_max=0.0), 'h_max: expected a number > 0, got 0.0'),
    (dict(h_max=float('inf')), 'h_max: expected a finite number, got inf'),
    (dict(lag=False), 'lag: expected a number, got False'),
    (dict(lag='x'), "lag: expected a number, got 'x'"),
    (dict(gain_bound=0), 'gain bound: expected a number > 0, got 0'),
])
def test_design_refuses_bad_numbers_with_the_validators_messages(kw, match):
    """One number rule (control.validate.as_finite_float): bools are not numbers."""
    args = dict(h_min=0.0, h_max=0.1, lag=0.0) | kw
    with pytest.raises(InputError, match=match):
        design_for_latency(di_problem(), args.pop('h_min'), args.pop('h_max'), **args)
