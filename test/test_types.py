"""Types: mypy (pinned in requirements.txt) over the public modules listed in setup.cfg."""
from __future__ import annotations

import configparser
import subprocess
import sys

from conftest import ROOT

def _checked_files() -> list[str]:
    cfg = configparser.ConfigParser()
    cfg.read(ROOT / 'setup.cfg')
    return [f.strip() for f in cfg['mypy']['files'].split(',') if f.strip()]


def _modules() -> list[str]:
    return sorted(str(p.relative_to(ROOT)) for p in (ROOT / 'nonfragile_tracker').rglob('*.py'))


def test_mypy_passes_on_every_module():
    proc = subprocess.run([sys.executable, '-m', 'mypy'], cwd=ROOT, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert f'Success: no issues found in {len(_modules())} source files' in proc.stdout, \
        proc.stdout


def test_mypy_configuration_covers_the_whole_package():
    assert _checked_files() == ['nonfragile_tracker']
    assert len(_modules()) >= 80
    assert any(line.strip() == 'mypy==2.4.1'
               for line in (ROOT / 'requirements.txt').read_text().splitlines())
