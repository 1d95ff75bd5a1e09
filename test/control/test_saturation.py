"""The saturation certificate (control.synthesis.saturation): a region of attraction of the
tracker under its own clamps (|dv/dt|, |w| at |v| >= V), the speed premise kept inside the
certified set, Delta included; checked in numpy, refused with the failed premise named, and
run against the nonlinear robot (region_check) with latency and lag."""
import math

import numpy as np
import pytest

from conftest import CONFIG
from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.control.simulation.reference import circle
from nonfragile_tracker.control.synthesis.problem import load_problem
from nonfragile_tracker.control.synthesis.saturation import (SaturationLimits, premise_failure,
                                                             saturation_certificate,
                                                             verify_saturation)
from nonfragile_tracker.errors import InputError
from nonfragile_tracker.control.simulation.region_check import (RobotSetup, check_region, reference_speeds,
                                             simulate_start)

#: Depends on linear algebra: make test runs it again under a second BLAS kernel (Makefile).
pytestmark = pytest.mark.numerical


@pytest.fixture(scope='module')
def paper():
    """The paper problem, the shipped gain, the robot (paper circle, 150 ms latency, 50 ms
    lag) and the certificate with Delta for the reference the tracker follows."""
    p = load_problem(CONFIG / 'paper_problem.yaml')
    K = read_gain_file(CONFIG / 'tracker_gains.yaml')
    setup = RobotSetup(circle(), p.A_tau, p.tau, cmd_latency=0.15, lag=0.05, duration=40.0)
    lo, hi, acc = reference_speeds(setup)
    lim = SaturationLimits(2.0, 0.0, max_reference_accel=acc * 1.01, cruise_speed=lo * 0.999,
                           max_linear_speed=1.0, max_reference_speed=hi)
    cert = saturation_certificate(p.A, p.B, K, p.A_tau, p.tau, lim, E=p.E, F=p.F)
    return p, K, setup, cert


def test_the_shipped_gain_is_certified_with_delta_and_the_speed_premise_kept(paper):
    """Verified in numpy; the velocity error over the set stays below cruise - V, so |v| >= V;
    V is at least the tracker's speed floor; the radius is millimetres at 6.5 mm/s."""
    p, K, _, cert = paper
    lim = cert.limits
    assert cert.verified and cert.delta and not cert.refusal
    assert cert.max_eig < 0 and cert.inclusion_eig >= 0
    assert lim.speed_floor <= lim.min_speed < lim.cruise_speed
    assert cert.speed_bound <= lim.speed_error * (1 + 1e-9)
    assert 1e-3 < cert.radius < 2e-2
    # the numpy check rejects a point that is not a certificate
    bad = verify_saturation(p.A, p.B, K, p.A_tau, p.tau, lim, cert.P, cert.Q, cert.G + 5.0,
                            cert.t, E=p.E, F=p.F, eps=cert.eps, mu=cert.mu)
    assert not bad.verified and bad.radius == 0.0
    # and the set is the one stated: a boundary point is in, a bit further is out
    e = np.array([cert.radius, 0.0, 0.0, 0.0])
    assert cert.contains(0.999 * e) or cert.contains(np.array([0.0, 0.0, 0.999 * cert.radius,
                                                               0.0]))
    assert not cert.contains(1.01 * e) or not cert.contains(
        np.array([0.0, 0.0, 1.01 * cert.radius, 0.0]))


def test_the_radius_is_of_the_set_the_second_solve_optimizes(paper):
    """The second solve maximizes the radius of e0'(P + tau Q) e0 <= 1 itself: never below the
    first solve's figure (which bounded E(P, 1) and read the radius from P + tau Q)."""
    cert = paper[3]
    assert cert.radius_first > 0 and cert.radius >= cert.radius_first * (1 - 1e-6)
    C = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
    lam = np.linalg.eigvalsh(C @ (cert.P + cert.tau * cert.Q) @ C.T)[-1]
    assert cert.radius == pytest.approx(1 / math.sqrt(lam), rel=1e-12)


def test_the_model_line_states_the_scope(paper):
    """Gain, saturation, delay and initial set in one line; latency and lag not covered."""
    line = paper[3].model()
    assert line.startswith('model: gain K + E Delta F, ||Delta|| <= 1')
    for words in ("the tracker's separate clamps", '|w| <= 2 rad/s at |v| >= V',
                  'NO command latency, NO actuator lag', 'constant history',
                  'constant state delay tau = 0.2 s'):
        assert words in line, line
    nominal = saturation_certificate(paper[0].A, paper[0].B, paper[1], paper[0].A_tau,
                                     paper[0].tau, paper[3].limits)
    assert nominal.verified and '(nominal: no Delta)' in nominal.model()
    assert nominal.radius > paper[3].radius          # Delta costs radius


@pytest.mark.parametrize('kw, words', [
    ({'min_speed': 0.003}, 'no cruise speed given'),
    ({'min_speed': 0.005, 'cruise_speed': 0.005}, 'is not above V'),
    ({'min_speed': 5e-4, 'cruise_speed': 0.005}, "below the tracker's min_speed"),
    ({'min_speed': 0.003, 'cruise_speed': 0.005, 'max_reference_accel': 0.01},
     'uses the whole saturation level'),
    ({'min_speed': 0.003, 'cruise_speed': 0.005, 'max_linear_speed': 0.006},
     'exceeds the tracker\'s max_linear_speed'),
])
def test_each_refusal_names_its_premise(paper, kw, words):
    """No radius when a premise cannot hold; the refusal says which."""
    p, K, _, _ = paper
    lim = SaturationLimits(2.0, **kw)
    assert words in premise_failure(lim)
    cert = saturation_certificate(p.A, p.B, K, p.A_tau, p.tau, lim, E=p.E, F=p.F)
    assert not cert.verified and cert.radius == 0.0 and words in cert.refusal
    with pytest.raises(InputError, match='cruise_speed'):
        SaturationLimits(2.0, cruise_speed=-1.0)


def test_a_search_with_no_room_for_v_refuses(paper):
    """Cruise speed below the tracker's floor: no V fits, refused."""
    p, K, _, _ = paper
    cert = saturation_certificate(p.A, p.B, K, p.A_tau, p.tau,
                                  SaturationLimits(2.0, cruise_speed=5e-4))
    assert not cert.verified and 'is not above V' in cert.refusal


def test_boundary_starts_converge_on_the_nonlinear_robot_with_latency_and_lag(paper):
    """A handful of starts on the certified boundary (benchmarks/saturation_region.py runs
    100): the tracker's clamps, 150 ms latency, 50 ms lag; all converge and the speed stays
    above V (the premise holds along the runs)."""
    p, K, setup, cert = paper
    chk = check_region(cert.P + cert.tau * cert.Q, K, setup, count=4, seed=5)
    assert chk.converged == 4
    assert chk.lowest_speed >= cert.limits.min_speed
    # far outside, the premise fails on the robot: the speed drops below V or w clamps
    far = simulate_start(K, 20 * chk.starts[0].e0, setup)
    assert far.lowest_speed < cert.limits.min_speed or far.w_clamped


def test_cli_analyse_prints_the_model_and_the_radius_or_the_refusal(capsys, paper):
    """`analyse --cruise-speed` prints the model line and the radius; `--min-speed` alone
    refuses, naming the premise."""
    from nonfragile_tracker.cli import main
    args = ['analyse', str(CONFIG / 'paper_problem.yaml'), '--gains',
            str(CONFIG / 'tracker_gains.yaml'), '--no-margins']
    assert main(args + ['--cruise-speed', '0.0065', '--min-speed', '0.003',
                        '--reference-accel', '1.2e-4']) == 0
    out = capsys.readouterr().out
    assert 'model: gain K + E Delta F' in out and 'NO command latency' in out
    assert 'certified: every initial position error up to' in out, out
    assert main(args + ['--min-speed', '0.005']) == 0
    out = capsys.readouterr().out
    assert 'NO radius certified: speed premise |v| >= V: no cruise speed given' in out


def test_every_sampled_delta_satisfies_the_nominal_conditions(paper):
    """Petersen's step checked without it: for sampled ||Delta|| <= 1 (rotations,
    reflections, rank one, scaled) the decrease LMI with K + E Delta F is negative and the
    ellipsoid lies where ||(K + E Delta F - G) e|| <= l."""
    from nonfragile_tracker.control.synthesis.worst_delta import extreme_deltas
    p, K, _, cert = paper
    P, Q, G, t, lev = cert.P, cert.Q, cert.G, cert.t, cert.limits.level
    rng = np.random.default_rng(0)
    deltas = extreme_deltas(2, 2, samples=12)
    deltas += [np.outer(a, b) / np.linalg.norm(a) / np.linalg.norm(b)
               for a, b in rng.normal(size=(8, 2, 2))]
    for D in deltas + [0.5 * D for D in deltas]:
        KD = K + p.E @ D @ p.F
        Acl = p.A + p.B @ KD
        L = np.block([[Acl.T @ P + P @ Acl + Q, P @ p.A_tau, -P @ p.B + t * G.T],
                      [p.A_tau.T @ P, -Q, np.zeros((4, 2))],
                      [-p.B.T @ P + t * G, np.zeros((2, 4)), -2 * t * np.eye(2)]])
        assert np.linalg.eigvalsh(0.5 * (L + L.T))[-1] < 0
        H = KD - G
        assert np.linalg.eigvalsh(H @ np.linalg.inv(P) @ H.T)[-1] <= lev ** 2 * (1 + 1e-9)


def test_the_trackers_clamps_satisfy_the_sector_condition_at_any_heading(paper):
    """The scalar-multiplier sector inequality psi'(psi - G e) <= 0 for the tracker's own
    clamps (|a| <= A tangential, |w| <= W at a speed |v| >= V), sampled over the certified
    ellipsoid, headings, speeds, Delta and reference accelerations ||u_d|| <= d."""
    p, K, _, cert = paper
    lim = cert.limits
    A_lim, W = 0.004, lim.max_angular_speed        # a tangential clamp above u_max binds too
    rng = np.random.default_rng(1)
    L = np.linalg.cholesky(np.linalg.inv(cert.P))
    worst, clamped = -np.inf, 0
    for _ in range(4000):
        z = rng.normal(size=4)
        e = L @ (z / np.linalg.norm(z) * rng.uniform() ** 0.25)      # in E(P, 1)
        th, v = rng.uniform(0, 2 * np.pi), lim.min_speed * (1 + 2 * rng.uniform())
        D = np.linalg.svd(rng.normal(size=(2, 2)))[0]
        ud = rng.normal(size=2)
        ud *= lim.max_reference_accel * rng.uniform() / np.linalg.norm(ud)
        u = ud + (K + p.E @ D @ p.F) @ e
        t_, n_ = np.array([np.cos(th), np.sin(th)]), np.array([-np.sin(th), np.cos(th)])
        a = np.clip(u @ t_, -max(A_lim, lim.u_max), max(A_lim, lim.u_max))
        w = np.clip((u @ n_) / v, -W, W)
        applied = a * t_ + v * w * n_
        psi = (u - ud) - (applied - ud)
        clamped += bool(np.any(psi != 0))
        worst = max(worst, float(psi @ (psi - cert.G @ e)))
    assert worst <= 1e-15 and clamped > 400         # the clamps bind in many samples
