"""Problem files: the paper's example loads; each malformed file gives one clear error."""
import numpy as np
import pytest
import yaml

from nonfragile_tracker.control.synthesis.problem import (ProblemError, is_stabilizable,
                                                          load_problem, problem_from_mapping)


def test_paper_problem_loads(paper_problem):
    p = paper_problem
    assert (p.n, p.m, p.tau) == (4, 2, 0.2)
    np.testing.assert_array_equal(np.diag(p.A_tau), [0.01, 0, 0.02, 0])
    assert set(p.perturbations) == {'Delta_1', 'Delta_2'}
    assert p.options['gain_bound'] == pytest.approx(8.67)


def _paper_dict(paper_problem):
    p = paper_problem
    return dict(A=p.A.tolist(), B=p.B.tolist(), A_tau=p.A_tau.tolist(), tau=p.tau,
                E=p.E.tolist(), F=p.F.tolist())


@pytest.mark.parametrize('change, message', [
    ({'A': [[0, 1], [0, 0]]}, 'B: expected shape (2, *), got (4, 2)'),
    ({'B': [[0, 0], [1, 0], [0, 0]]}, 'B: expected shape (4, *)'),
    ({'F': [[0.5, 0.5, 0.5]]}, 'F: expected shape (*, 4)'),
    ({'A_tau': [[float('nan'), 0, 0, 0]] + [[0] * 4] * 3}, 'A_tau: entry [0][0] is nan'),
    ({'E': [['a', 0], [0, 1]]}, 'E: expected a matrix of numbers'),
    ({'tau': -0.1}, 'tau must be a finite number >= 0'),
    ({'tau': 'fast'}, 'tau must be a finite number'),
    ({'E': 'identity'}, 'E: expected a matrix'),
    ({'A': [[0, 1, 0], [0, 0]]}, 'A: expected a matrix of numbers'),
    ({'Gain': 1}, 'unknown key(s) Gain'),
])
def test_bad_fields_name_the_field(paper_problem, change, message):
    data = _paper_dict(paper_problem)
    data.update(change)
    with pytest.raises(ProblemError) as err:
        problem_from_mapping(data, source='bad.yaml')
    assert message in str(err.value)
    assert str(err.value).startswith('bad.yaml: ')


def test_missing_keys(paper_problem):
    data = _paper_dict(paper_problem)
    del data['E'], data['tau']
    with pytest.raises(ProblemError, match=r'missing key\(s\) tau, E'):
        problem_from_mapping(data)


def test_unstabilizable_is_rejected_on_load(paper_problem):
    data = _paper_dict(paper_problem)
    A = np.zeros((5, 5))
    A[:4, :4] = paper_problem.A
    A[4, 4] = 0.5                                   # unstable mode that B does not reach
    data.update(A=A.tolist(), B=np.vstack([paper_problem.B, [0, 0]]).tolist(),
                A_tau=np.zeros((5, 5)).tolist(), F=np.hstack([paper_problem.F, [[0], [0]]]).tolist())
    with pytest.raises(ProblemError, match='not stabilizable: eigenvalue.*0.5'):
        problem_from_mapping(data)


def test_pbh():
    assert is_stabilizable(np.array([[-1.0]]), np.zeros((1, 1)))[0]
    ok, bad = is_stabilizable(np.array([[1.0]]), np.zeros((1, 1)))
    assert not ok and bad == [1.0]


def test_file_errors(tmp_path):
    with pytest.raises(ProblemError, match='cannot read problem file'):
        load_problem(tmp_path / 'nope.yaml')
    (tmp_path / 'bad.yaml').write_text('A: [[1, 2]\n')
    with pytest.raises(ProblemError, match='not valid YAML'):
        load_problem(tmp_path / 'bad.yaml')
    (tmp_path / 'list.yaml').write_text(yaml.safe_dump([1, 2]))
    with pytest.raises(ProblemError, match='expected a mapping'):
        load_problem(tmp_path / 'list.yaml')
