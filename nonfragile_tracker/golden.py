"""Golden bags: the scenarios that pin the package's behaviour, and their regeneration.

``nonfragile_tracker golden`` re-runs every scenario through the three ROS nodes
(separate processes, lockstep), compares each new bag with the committed one in
``test/data/`` and prints what changed; ``--write`` replaces the golden bags
(never silently: the diff is printed first).  The tests re-run the same
scenarios and require agreement within :data:`ATOL`.
"""
from __future__ import annotations

import shutil
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from . import topics
from .errors import RunError

#: Tolerance of the regression comparison.  Lockstep runs are deterministic and
#: bit-identical to the in-process simulation on one machine; 1e-9 leaves room
#: only for libm differences between machines.
ATOL = 1e-9
#: Recorded topics (``/clock`` and ``pose`` repeat ``odom``'s stamps and pose: left out
#: to keep the golden bags small).
TOPICS = list(topics.RUN_TOPICS)
DURATION = 2.5


@dataclass(frozen=True)
class Scenario:
    name: str
    description: str
    overrides: dict = field(default_factory=dict)


SCENARIOS = {
    'paper': Scenario('paper', "paper's circle with the pinned synthesized non-fragile K "
                      '(test/data/golden_gains.yaml)'),
    'delta2': Scenario('delta2', 'same, with the perturbation E Delta_2 F injected in the tracker',
                       {'tracker': {'ros__parameters': {'Delta': [1.0, 0.0, 0.0, 1.0]}}}),
}


def data_dir() -> Path:
    return Path(__file__).resolve().parent.parent / 'test' / 'data'


def golden_bag(name: str) -> Path:
    return data_dir() / f'golden_{name}'


def golden_gains() -> Path:
    """The gain file the golden scenarios run with, pinned next to the golden bags.

    The golden bags pin behaviour, not the shipped default: ``config/tracker_gains.yaml``
    may change (a better certified design) without touching them.
    """
    return data_dir() / 'golden_gains.yaml'


def scenario_params(scenario: Scenario, duration: float = DURATION) -> dict:
    from .resources import config_dir
    from .runner import merge, scenario_parameters
    ov = {'plant': {'ros__parameters': {'duration': duration}}}
    merge(ov, scenario.overrides)
    return scenario_parameters(config_dir() / 'paper_scenario.yaml', golden_gains(), ov)


def run_scenario(scenario: Scenario, run_dir: Path, *, composed: bool = False,
                 env: dict | None = None) -> Path:
    """Run a scenario in lockstep and return its bag directory."""
    from .runner import run_composed, run_processes
    params = scenario_params(scenario)
    run_dir.mkdir(parents=True, exist_ok=True)
    if composed:
        res = run_composed(params, run_dir, record=True, recorder_topics=TOPICS)
    else:
        res = run_processes(params, run_dir, record=True, env=env, progress=lambda s: None,
                            recorder_topics=TOPICS)
    bad = {k: v for k, v in res.exit_codes.items() if v not in (0, None)}
    if bad:
        raise RunError(f'scenario {scenario.name!r} failed: exit codes {bad}; logs in '
                           f'{run_dir}')
    return res.bag


def check_golden(write: bool = False) -> int:
    """Re-run every scenario, print what changed against its golden bag; 1 if any differs.

    Parameters
    ----------
    write : bool
        Replace the golden bags that changed (the differences are printed first).

    Returns
    -------
    int
        0 when every bag is unchanged (or was written), 1 otherwise.
    """
    from .bag.compare import compare_bags, format_differences
    changed = 0
    with tempfile.TemporaryDirectory() as tmp:
        for name, sc in SCENARIOS.items():
            new = run_scenario(sc, Path(tmp) / name)
            old = golden_bag(name)
            if old.exists():
                cmp = compare_bags(old, new, atol=ATOL)
                if cmp.equal:
                    print(f'{name}: unchanged ({sum(cmp.messages.values())} messages)')
                    continue
                print(f'{name}: CHANGED\n{format_differences(cmp)}')
            else:
                print(f'{name}: new golden bag')
            changed += 1
            if write:
                if old.exists():
                    shutil.rmtree(old)
                old.parent.mkdir(parents=True, exist_ok=True)
                shutil.copytree(new, old)
                print(f'  wrote {old}')
    if changed and not write:
        print('golden bags differ; re-run with --write to replace them', file=sys.stderr)
        return 1
    return 0

