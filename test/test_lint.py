"""Lint: ruff (pyflakes, pycodestyle, pydocstyle numpy convention; ruff.toml) over the package;
pyflakes alone over the tests, benchmarks, docs examples and the Sphinx project (doc/)."""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

from conftest import ROOT


def _ruff() -> list[str]:
    """The ruff of this interpreter's environment (pinned in requirements.txt)."""
    exe = Path(sys.executable).with_name('ruff')
    if exe.exists():
        return [str(exe)]
    found = shutil.which('ruff')
    assert found, 'ruff is not installed: pip install -r requirements.txt'
    return [found]


def test_ruff_passes_on_the_package():
    proc = subprocess.run([*_ruff(), 'check', '--no-cache', '--output-format', 'concise',
                           'nonfragile_tracker'], cwd=ROOT, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert 'All checks passed' in proc.stdout


def test_pyflakes_passes_on_tests_and_benchmarks():
    proc = subprocess.run([*_ruff(), 'check', '--no-cache', '--output-format', 'concise',
                           '--select', 'F', 'test', 'benchmarks', 'doc'], cwd=ROOT,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert 'All checks passed' in proc.stdout


def test_ruff_configuration_is_the_one_described():
    text = (ROOT / 'ruff.toml').read_text()
    assert 'line-length = 100' in text and 'convention = "numpy"' in text
    assert 'select = ["F", "E", "W", "D"]' in text
    assert 'per-file-ignores' not in text
    assert any(line.strip() == 'ruff==0.17.6'
               for line in (ROOT / 'requirements.txt').read_text().splitlines())
