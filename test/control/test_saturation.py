"""The saturation certificate (control.synthesis.saturation): a region of attraction of the tracking
loop whose input saturates (|w| and |dv/dt| limits), by the generalized sector condition;
checked in numpy and against simulations of the saturated loop."""
import math

import numpy as np
import pytest

from conftest import CONFIG
from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.control.synthesis.problem import load_problem
from nonfragile_tracker.control.synthesis.saturation import (SaturationLimits, check_by_simulation,
                                                             saturation_certificate,
                                                             simulate_saturated, verify_saturation)
from nonfragile_tracker.errors import InputError

#: Depends on linear algebra: make test runs it again under a second BLAS kernel (Makefile).
pytestmark = pytest.mark.numerical

#: The paper scenario's circle: r = 0.5 m at 0.01 rad/s -> |v| = 0.005 m/s, |u_d| = r w^2
PAPER = SaturationLimits(max_angular_speed=2.0, min_speed=0.005, max_reference_accel=5e-5)


@pytest.fixture(scope='module')
def paper():
    """The paper problem, the shipped gain and its saturation certificate (|w| <= 2)."""
    p = load_problem(CONFIG / 'paper_problem.yaml')
    K = read_gain_file(CONFIG / 'tracker_gains.yaml')
    return p, K, saturation_certificate(p.A, p.B, K, p.A_tau, p.tau, PAPER)


def test_region_is_not_empty_for_the_shipped_gain_with_w_limit_2(paper):
    """Non-empty and verified in numpy (first LMI negative, ellipsoid in the sector region)."""
    p, K, cert = paper
    assert cert.verified and cert.max_eig < 0 and cert.inclusion <= 1.0
    assert 1e-3 < cert.radius < 0.1                # millimetres at 5 mm/s: |u| <= 7 mm/s^2
    # the numpy check rejects a point that is not a certificate
    bad = verify_saturation(p.A, p.B, K, p.A_tau, p.tau, PAPER, cert.P, cert.Q,
                            cert.G + 5.0, cert.T)
    assert not bad.verified and bad.radius == 0.0


def test_every_simulated_start_inside_converges(paper):
    """Starts inside the certified set (boundary of the position disc, and random error
    states with velocity errors scaled into the set) converge under saturation."""
    p, K, cert = paper
    chk = check_by_simulation(cert, p.A, p.B, K, p.A_tau, directions=8)
    assert chk.inside_converged == chk.inside_total == 8
    rng = np.random.default_rng(3)
    Pt = cert.P + cert.tau * cert.Q
    for _ in range(6):
        e0 = rng.normal(size=4)
        e0 *= 0.999 / math.sqrt(e0 @ Pt @ e0)       # on the certified level set
        assert cert.contains(e0)
        out = simulate_saturated(p.A, p.B, K, p.A_tau, p.tau, PAPER, e0, duration=20.0,
                                 u_d=lambda t: 5e-5 * np.array([math.cos(t), math.sin(t)]))
        assert np.linalg.norm(out[-1]) < 1e-3 * np.linalg.norm(e0)


def test_saturation_matters_far_outside(paper):
    """Far outside the certified radius the saturated loop need not converge (it does not
    from some directions): the certificate is about the saturated loop."""
    p, K, cert = paper
    chk = check_by_simulation(cert, p.A, p.B, K, p.A_tau, directions=8, outside=20.0)
    assert chk.inside_converged == 8 and chk.outside_converged < 8


def test_radius_scales_with_the_level_and_reference_acceleration(paper):
    """Homogeneous in the dead-zone level: the radius per level is the same for a faster
    reference; the largest reference acceleration for a radius follows; a reference that
    uses the whole box certifies nothing."""
    p, K, cert = paper
    fast = SaturationLimits(2.0, 0.4, 1.0, 0.1)
    c2 = saturation_certificate(p.A, p.B, K, p.A_tau, p.tau, fast)
    assert c2.verified
    assert c2.radius_per_level == pytest.approx(cert.radius_per_level, rel=1e-3)
    d = c2.max_reference_accel(c2.radius / 2)
    assert d == pytest.approx(fast.box - c2.radius / 2 / c2.radius_per_level, rel=1e-12)
    assert d > fast.max_reference_accel
    none = saturation_certificate(p.A, p.B, K, p.A_tau, p.tau,
                                  SaturationLimits(2.0, 0.005, 0.0, 0.01))
    assert not none.verified and 'whole input box' in none.status
    with pytest.raises(InputError, match='min_speed'):
        SaturationLimits(2.0, 0.0)


def test_cli_analyse_reports_the_saturation_certificate(capsys, paper):
    """`analyse --min-speed` prints the certified radius (the library's, in mm) and the
    reference acceleration."""
    from nonfragile_tracker.cli import main
    assert main(['analyse', str(CONFIG / 'paper_problem.yaml'), '--gains',
                 str(CONFIG / 'tracker_gains.yaml'), '--no-margins', '--min-speed', '0.005',
                 '--reference-accel', '5e-5']) == 0
    out = capsys.readouterr().out
    assert 'saturation (|w| <= 2 rad/s at |v| >= 0.005 m/s' in out
    radius_mm = paper[2].radius * 1e3
    assert f'every initial position error up to {radius_mm:.4g} mm' in out, out
    assert 'numpy check' in out
