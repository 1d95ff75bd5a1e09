"""``run --robot NAME`` (issue 39 item 4): a physics base's scenario, refusals before any node."""
from __future__ import annotations

from nonfragile_tracker.cli import main


def test_unknown_base_and_scenario_together_are_refused(capsys):
    assert main(['run', '--robot', 'husky']) == 2
    assert 'not a physics base; choose one of jackal, jackal_skid, turtlebot3' in \
        capsys.readouterr().err
    assert main(['run', '--robot', 'jackal', '--scenario', 'x.yaml']) == 2
    assert 'leave out --scenario' in capsys.readouterr().err
