"""The command line: gain files, exit codes, clear messages."""
import subprocess
import sys

import numpy as np
import pytest
import yaml

from nonfragile_tracker.cli import main
from nonfragile_tracker.control.simulation.gains import read_gain_file

from conftest import CONFIG, ROOT

PAPER = str(CONFIG / 'paper_problem.yaml')
HARDER = str(CONFIG / 'harder_delay_problem.yaml')


def test_synthesize_writes_a_tracker_parameter_file(tmp_path, capsys):
    out = tmp_path / 'gains.yaml'
    assert main(['synthesize', PAPER, '-o', str(out)]) == 0
    data = yaml.safe_load(out.read_text())
    params = data['/**/tracker']['ros__parameters']
    assert params['K_shape'] == [2, 4]
    assert len(params['K']) == 8 and all(isinstance(v, float) for v in params['K'])
    K = read_gain_file(out)
    assert np.linalg.norm(K, 2) <= 8.67 * (1 + 1e-6)
    text = capsys.readouterr().out
    assert 'feasible' in text and '-> OK' in text
    assert main(['synthesize', PAPER, '-o', str(out)]) == 2          # never overwrites
    assert 'pass --force' in capsys.readouterr().err
    assert main(['synthesize', PAPER, '-o', str(out), '--force', '--nominal']) == 0




def test_infeasible_exits_3_and_writes_nothing(tmp_path):
    out = tmp_path / 'gains.yaml'
    proc = subprocess.run([sys.executable, '-m', 'nonfragile_tracker.cli', 'synthesize', HARDER,
                           '-o', str(out)], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert proc.returncode == 3
    assert "infeasible for problem 'harder_delay'" in proc.stderr and 'delay-dependent' in proc.stderr
    assert 'Traceback' not in proc.stderr and not out.exists()


@pytest.mark.parametrize('content, message', [
    ('A: [[0, 1], [0, 0]]\n', 'missing key(s)'),
    ('A: [[0, 1], [0, 0]]\nB: [[0], [1]]\nA_tau: [[0, 0], [0, nan]]\ntau: 0.1\nE: [[1]]\nF: [[1, 1]]\n',
     'A_tau: entry [1][1] is nan'),
    ('A: [[0, 1], [0, 0]]\nB: [[0], [1]]\nA_tau: [[0, 0], [0, 0]]\ntau: 0.1\nE: [[1]]\nF: [[1, 1, 1]]\n',
     'F: expected shape (*, 2)'),
    ('[1, 2', 'not valid YAML'),
])
def test_bad_problem_files_exit_2(tmp_path, capsys, content, message):
    bad = tmp_path / 'bad.yaml'
    bad.write_text(content)
    assert main(['synthesize', str(bad), '-o', str(tmp_path / 'g.yaml')]) == 2
    err = capsys.readouterr().err
    assert message in err and str(bad) in err
    assert not (tmp_path / 'g.yaml').exists()


def test_analyse_and_margins_of_the_papers_gains(tmp_path, capsys):
    js = tmp_path / 'a.json'
    assert main(['analyse', PAPER, '--paper', '--json', str(js)]) == 0
    out = capsys.readouterr().out
    assert 'paper K_nf' in out and 'abscissa, D = Delta_2' in out
    import json
    rows = {r['name']: r for r in json.loads(js.read_text())}
    assert rows['paper K_normal']['abscissa']['Delta_2'] == pytest.approx(-1.1336, abs=1e-3)
    assert rows['paper K_nf']['certified_margin'] == pytest.approx(5.63, abs=0.02)
    assert main(['margins', PAPER, '--gains', str(CONFIG / 'tracker_gains.yaml')]) == 0
    assert 'measured' in capsys.readouterr().out


def test_design_and_delay_dependent(tmp_path, capsys, monkeypatch, shipped_design):
    # the max-decay design at --norm 8.67, computed once for the session (conftest)
    assert shipped_design.code == 0
    assert np.linalg.norm(read_gain_file(shipped_design.path), 2) <= 8.67
    assert 'largest certified decay rate' in shipped_design.stdout
    # without --norm the design runs at options.gain_bound (8.67): the same call, so its
    # computed result stands in for a second identical design
    from nonfragile_tracker.control.synthesis import design
    (fn, _, norm), kw, res = shipped_design.calls[0]
    seen = []

    def same_design(*args, **kwargs):
        seen.append((args[0], args[2], kwargs))
        return res
    monkeypatch.setattr(design, 'at_gain_norm', same_design)
    out = tmp_path / 'decay.yaml'
    assert main(['design', PAPER, '--objective', 'decay', '-o', str(out)]) == 0
    assert seen == [(fn, 8.67, kw)] and norm == 8.67
    assert np.linalg.norm(read_gain_file(out), 2) <= 8.67
    assert 'largest certified decay rate' in capsys.readouterr().out
    monkeypatch.undo()
    out2 = tmp_path / 'dd.yaml'
    assert main(['delay-dependent', HARDER, '--delay', '0.2', '-o', str(out2)]) == 0
    assert 'certified for every constant delay in (0, 0.2]' in capsys.readouterr().out
    assert np.linalg.norm(read_gain_file(out2), 2) <= 3.0 * (1 + 1e-6)


def test_missing_solver_exits_4_without_a_gain_file(tmp_path, capsys):
    text = (CONFIG / 'paper_problem.yaml').read_text().replace(
        'options:\n', 'options:\n  solver: MOSEK\n')
    prob = tmp_path / 'p.yaml'
    prob.write_text(text)
    out = tmp_path / 'g.yaml'
    assert main(['synthesize', str(prob), '-o', str(out)]) == 4
    err = capsys.readouterr().err
    assert 'MOSEK' in err and 'installed' in err and not out.exists()
