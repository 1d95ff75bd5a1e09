"""The control core's three parts: each package holds only its docstring (names are imported
from their modules), and the simulation (what the nodes import) never loads the synthesis or
cvxpy."""
from __future__ import annotations

import ast
import importlib
import subprocess
import sys

import pytest

from conftest import ROOT

PARTS = ('synthesis', 'simulation', 'identification')


def _run(code: str) -> str:
    """Run ``code`` in a fresh interpreter (nothing imported yet) and return its stdout."""
    proc = subprocess.run([sys.executable, '-c', code], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout


def test_the_simulation_runs_without_the_synthesis_or_cvxpy():
    """A tracking run of the shipped gain (the nodes' step functions), plus the tracker
    node's monitor: no synthesis module, no cvxpy."""
    out = _run(
        'import sys\n'
        'from nonfragile_tracker.control.simulation.gains import read_gain_file\n'
        'from nonfragile_tracker.control.simulation.plant import PlantConfig\n'
        'from nonfragile_tracker.control.simulation.tracker import TrackerConfig\n'
        'from nonfragile_tracker.control.simulation.reference import circle\n'
        'from nonfragile_tracker.control.simulation.simulate import simulate_tracking\n'
        'from nonfragile_tracker.control.identification import monitor\n'
        "K = read_gain_file('config/tracker_gains.yaml')\n"
        'run = simulate_tracking(PlantConfig(), TrackerConfig(K=K), circle(), 500)\n'
        'print(run.error.shape[0])\n'
        "print(sorted(m for m in sys.modules if m == 'cvxpy' or '.synthesis' in m))\n")
    assert out.split('\n')[:2] == ['501', '[]'], out


@pytest.mark.parametrize('part', PARTS)
def test_importing_a_part_imports_none_of_its_modules(part):
    out = _run(f'import sys\nimport nonfragile_tracker.control.{part}\n'
               "print(sorted(m for m in sys.modules if m.startswith('nonfragile_tracker')))\n")
    assert out.strip() == str(['nonfragile_tracker', 'nonfragile_tracker.control',
                               f'nonfragile_tracker.control.{part}'])


@pytest.mark.parametrize('part', PARTS + ('',))
def test_a_part_package_is_its_docstring_only(part):
    """No re-exports, no import machinery: a name is imported from the module defining it."""
    tree = ast.parse((ROOT / 'nonfragile_tracker' / 'control' / part / '__init__.py')
                     .read_text())
    assert len(tree.body) == 1 and isinstance(tree.body[0], ast.Expr), part


#: Each part's errors: class -> (builtin it derives from, exit code, modules that import it
#: for their own use and so keep it importable from there, as before the move).
ERRORS = {
    'synthesis': {'ProblemError': (ValueError, 2, ['problem']),
                  'LmiError': (RuntimeError, 4, ['lmi', 'design', 'sweep']),
                  'InfeasibleError': (RuntimeError, 3, ['lmi', 'design', 'delay_dependent',
                                                        'input_delay', 'latency_design']),
                  'SolverFailure': (RuntimeError, 4, ['lmi', 'sdp']),
                  'CertificateError': (RuntimeError, 4, ['lmi', 'delay_dependent'])},
    'simulation': {'PathError': (ValueError, 2, ['reference']),
                   'TrajectoryError': (ValueError, 2, ['trajectory', 'limits']),
                   'LoopConfigError': (ValueError, 2, ['tracker', 'plant', 'gains']),
                   'BatchError': (ValueError, 2, ['batch', 'study'])},
    'identification': {'IdentificationError': (ValueError, 2, ['identify']),
                       'NotEnoughDataError': (ValueError, 2, ['identify']),
                       'InsufficientExcitationError': (ValueError, 2, ['identify']),
                       'PoorFitError': (ValueError, 2, ['identify']),
                       'MonitorError': (ValueError, 2, ['monitor'])},
}


@pytest.mark.parametrize('part', PARTS)
def test_each_part_has_its_errors_under_the_root_error(part):
    from nonfragile_tracker.errors import NonfragileError, exit_code
    errors = importlib.import_module(f'nonfragile_tracker.control.{part}.errors')
    assert sorted(errors.__all__) == sorted(ERRORS[part])
    for name, (builtin, code, modules) in ERRORS[part].items():
        cls = getattr(errors, name)
        assert cls.__module__ == errors.__name__
        assert issubclass(cls, NonfragileError) and issubclass(cls, builtin), name
        assert exit_code(cls('message')) == code, name
        for module in modules:
            where = importlib.import_module(f'nonfragile_tracker.control.{part}.{module}')
            assert getattr(where, name) is cls, (module, name)


def test_the_subclass_order_of_the_errors():
    from nonfragile_tracker.control.synthesis.errors import (CertificateError, InfeasibleError,
                                                             LmiError, SolverFailure)
    assert all(issubclass(c, LmiError) for c in (InfeasibleError, SolverFailure,
                                                 CertificateError))
