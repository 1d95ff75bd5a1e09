"""Types: mypy (pinned in requirements.txt) over the public modules listed in setup.cfg."""
from __future__ import annotations

import configparser
import subprocess
import sys

from conftest import ROOT

#: The public API that must stay type-checked (the ``files`` of ``[mypy]`` may list more).
PUBLIC = ('nonfragile_tracker/errors.py', 'nonfragile_tracker/control/validate.py',
          'nonfragile_tracker/control/simulation/model.py',
          'nonfragile_tracker/control/synthesis/problem.py',
          'nonfragile_tracker/control/simulation/gains.py',
          'nonfragile_tracker/control/simulation/loop.py',
          'nonfragile_tracker/control/simulation/trajectory.py',
          'nonfragile_tracker/control/identification/identify.py',
          'nonfragile_tracker/bag/compare.py', 'nonfragile_tracker/control/synthesis/delay.py',
          'nonfragile_tracker/control/synthesis/input_delay.py',
          'nonfragile_tracker/bag/reader.py', 'nonfragile_tracker/bag/writer.py',
          'nonfragile_tracker/msgconv.py', 'nonfragile_tracker/scenario.py',
          'nonfragile_tracker/runner.py', 'nonfragile_tracker/topics.py',
          'nonfragile_tracker/control/synthesis/sdp.py',
          'nonfragile_tracker/control/synthesis/lmi.py',
          'nonfragile_tracker/control/simulation/follow.py',
          'nonfragile_tracker/control/simulation/study.py',
          'nonfragile_tracker/control/synthesis/latency_design.py',
          'nonfragile_tracker/control/simulation/batch.py',
          'nonfragile_tracker/control/synthesis/delay_dependent.py',
          'nonfragile_tracker/control/synthesis/design.py',
          'nonfragile_tracker/control/synthesis/analysis.py',
          'nonfragile_tracker/control/synthesis/search.py', 'nonfragile_tracker/golden.py',
          'nonfragile_tracker/bag/report.py', 'nonfragile_tracker/bag/repair.py',
          'nonfragile_tracker/bag/motion.py', 'nonfragile_tracker/bag/replay.py',
          'nonfragile_tracker/reproduce.py', 'nonfragile_tracker/cli.py',
          'nonfragile_tracker/commands/argtypes.py',
          *(f'nonfragile_tracker/nodes/{n}.py' for n in ('entry', 'common', 'reference',
                                                          'plant', 'tracker', 'recorder')))


def _checked_files() -> list[str]:
    cfg = configparser.ConfigParser()
    cfg.read(ROOT / 'setup.cfg')
    return [f.strip() for f in cfg['mypy']['files'].split(',') if f.strip()]


def test_mypy_passes_on_the_public_modules():
    files = _checked_files()
    proc = subprocess.run([sys.executable, '-m', 'mypy'], cwd=ROOT, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert f'Success: no issues found in {len(files)} source files' in proc.stdout, proc.stdout


def test_mypy_configuration_covers_the_public_api():
    files = _checked_files()
    assert set(PUBLIC) <= set(files), sorted(set(PUBLIC) - set(files))
    assert all((ROOT / f).is_file() for f in files), files
    assert any(line.strip() == 'mypy==2.4.1'
               for line in (ROOT / 'requirements.txt').read_text().splitlines())
