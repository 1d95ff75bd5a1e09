"""The shipped default gain is the package's best certified design, regenerable by one command."""
import numpy as np
import pytest
import yaml

from nonfragile_tracker.control.delay import worst_case_abscissa
from nonfragile_tracker.control.gains import read_gain_design, read_gain_file
from nonfragile_tracker.control.lmi import certify_gain

from conftest import CONFIG, SHIPPED_DESIGN_ARGV

PAPER = str(CONFIG / 'paper_problem.yaml')


def test_shipped_gain_file_is_what_design_writes(shipped_design):
    # `design config/paper_problem.yaml --objective decay --norm 8.67 -o FILE` (conftest)
    assert shipped_design.code == 0
    assert SHIPPED_DESIGN_ARGV == ['design', PAPER, '--objective', 'decay', '--norm', '8.67']
    out = shipped_design.path
    np.testing.assert_allclose(read_gain_file(out), read_gain_file(CONFIG / 'tracker_gains.yaml'),
                               atol=1e-6)
    got, shipped = read_gain_design(out), read_gain_design(CONFIG / 'tracker_gains.yaml')
    assert set(got) == set(shipped)
    for k, v in shipped.items():
        assert got[k] == (pytest.approx(v, rel=1e-6) if isinstance(v, float) else v), k


def test_shipped_gain_beats_the_papers_gain(paper_problem):
    """Same ||K||_2 budget, certified by Theorem 1, faster worst-case decay than K_nf."""
    p = paper_problem
    K = read_gain_file(CONFIG / 'tracker_gains.yaml')
    K_nf = read_gain_file(CONFIG / 'paper_gains_tracker.yaml')
    printed = np.array(yaml.safe_load((CONFIG / 'paper_gains.yaml').read_text())['K_nf'])
    np.testing.assert_array_equal(K_nf, printed)
    assert np.linalg.norm(K, 2) <= 8.67
    assert certify_gain(p, K).certified
    rec = read_gain_design(CONFIG / 'tracker_gains.yaml')
    assert rec['gain_bound'] == 8.67 and rec['certified_value'] > 1.7
    ours = worst_case_abscissa(p.A, p.B, K, p.A_tau, p.tau, p.E, p.F)[0]
    theirs = worst_case_abscissa(p.A, p.B, K_nf, p.A_tau, p.tau, p.E, p.F)[0]
    assert ours < -1.8 and -1.1 < theirs < -1.05
    # and it tolerates more command latency (exact, recorded in the design record)
    assert rec['true_latency_margin'] > 0.22 > rec['certified_latency'] > 0.19
