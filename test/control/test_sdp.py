"""Shared SDP plumbing: status classification, the one bounded program cache."""
import numpy as np
import pytest

from nonfragile_tracker.control.synthesis import sdp
from nonfragile_tracker.control.synthesis.lmi import synthesize
from nonfragile_tracker.control.synthesis.problem import Problem

#: Depends on linear algebra: make test runs it again under a second BLAS kernel (Makefile).
pytestmark = pytest.mark.numerical


def test_classify_statuses():
    assert sdp.classify('optimal', 1e-3, 1e-6) == 'ok'
    assert sdp.classify('optimal_inaccurate', 1e-3, 1e-6) == 'ok'
    assert sdp.classify('optimal', 1e-7, 1e-6) == 'infeasible'
    assert sdp.classify('optimal', None, 1e-6) == 'infeasible'
    assert sdp.classify('infeasible', None, 1e-6) == 'infeasible'
    assert sdp.classify('unbounded', 1.0, 1e-6) == 'failed'


def test_sym_is_symmetric_part():
    M = np.array([[1.0, 2.0], [0.0, 3.0]])
    assert np.array_equal(sdp.sym(M), np.array([[1.0, 1.0], [1.0, 3.0]]))


def test_cache_is_bounded_lru_and_clearable():
    sdp.clear_cache()
    built = []
    for i in range(sdp.CACHE_SIZE + 5):
        sdp.cached_program(('test', i), lambda i=i: built.append(i) or i)
    keys = [k for k, _ in sdp.cached_programs()]
    assert len(keys) == sdp.CACHE_SIZE
    assert keys[0] == ('test', 5) and keys[-1] == ('test', sdp.CACHE_SIZE + 4)
    # a hit does not rebuild and moves the key to the most recent end
    assert sdp.cached_program(('test', 5), lambda: built.append('x')) == 5
    assert 'x' not in built and sdp.cached_programs()[-1][0] == ('test', 5)
    sdp.clear_cache()
    assert sdp.cached_programs() == []


def test_synthesis_uses_the_shared_cache_and_gives_the_same_gain():
    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    p = Problem(A=A, B=np.array([[0.0], [1.0]]), A_tau=0.1 * np.eye(2), E=np.array([[1.0]]),
                F=np.array([[0.1, 0.1]]), tau=0.1, name='di')
    sdp.clear_cache()
    k1 = synthesize(p, gain_bound=5.0).K
    keys = [k for k, _ in sdp.cached_programs()]
    assert keys == [('theorem1', 2, 1, 1, 1, False, True)]
    sdp.clear_cache()
    k2 = synthesize(p, gain_bound=5.0).K
    np.testing.assert_allclose(k1, k2, rtol=0, atol=1e-12)
