"""`golden` on a user's scenario file, golden bags where the user says; never into an install."""
from __future__ import annotations

import pytest
import yaml

from conftest import CONFIG
from nonfragile_tracker import cli
from nonfragile_tracker.workflows import golden

#: Not marked ``numerical``: every comparison here is of two runs of the same scenario on the
#: same machine and kernel (exact by construction), so a second BLAS kernel checks nothing new.


def test_golden_refuses_to_write_into_an_installed_package(monkeypatch, capsys):
    monkeypatch.setattr(golden, 'source_root', lambda: None)
    with pytest.raises(golden.InputError, match='package is installed, so pass --out'):
        golden.golden_bag('paper')
    assert cli.main(['golden']) == 2
    assert 'never writes into an installed package' in capsys.readouterr().err


def test_user_scenario_needs_out(tmp_path, capsys):
    assert cli.main(['golden', '--scenario', str(CONFIG / 'paper_scenario.yaml')]) == 2
    assert 'say where their golden bags live with --out DIR' in capsys.readouterr().err
    assert cli.main(['golden', '--scenario', str(tmp_path / 'nope.yaml'), '--out',
                     str(tmp_path)]) == 2
    assert 'does not exist' in capsys.readouterr().err


@pytest.mark.ros
@pytest.mark.slow
def test_golden_on_a_user_scenario(tmp_path, capsys):
    data = yaml.safe_load((CONFIG / 'paper_scenario.yaml').read_text())
    data['/**/reference']['ros__parameters']['radius'] = 0.8
    scen = tmp_path / 'my_robot.yaml'
    scen.write_text(yaml.safe_dump(data))
    out = tmp_path / 'goldens'
    args = ['golden', '--scenario', str(scen), '--out', str(out), '--duration', '0.5']
    assert cli.main(args + ['--write']) == 0
    assert 'my_robot: new golden bag' in capsys.readouterr().out
    assert (out / 'golden_my_robot' / 'metadata.yaml').exists()
    written = (out / 'golden_my_robot' / 'metadata.yaml').read_bytes()
    assert cli.main(args) == 0
    assert 'my_robot: unchanged (255 messages' in capsys.readouterr().out   # 51 steps x 5
    data['/**/tracker']['ros__parameters']['Delta'] = [1.0, 0.0, 0.0, 1.0]
    scen.write_text(yaml.safe_dump(data))
    assert cli.main(args) == 1
    text = capsys.readouterr().out
    # (the first command is the measured speed whatever the gain: they part at the second)
    assert 'my_robot: CHANGED' in text and '/cmd_vel[1] linear.x: expected' in text
    assert (out / 'golden_my_robot' / 'metadata.yaml').read_bytes() == written  # no --write
