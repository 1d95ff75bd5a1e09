"""Golden bags: scenarios that pin a tracker's behaviour, their runs and their comparison.

``nonfragile_tracker golden`` re-runs scenarios through the three ROS nodes (separate
processes, lockstep), compares each new bag with its golden bag and prints what
changed; ``--write`` replaces the golden bags (never silently: the diff is printed
first).  The package's own scenarios (``SCENARIOS``) keep their golden bags in the
source tree's ``test/data``; a user names any scenario file (``--scenario FILE``,
a ROS 2 parameter file for plant, reference and tracker) and where its golden bag
lives (``--out DIR``).  An installed package never writes into itself.
The tests re-run the same scenarios and require agreement within :data:`ATOL`.

See doc/bags.md, sections "Recording and golden bags" and "Bag regression for your own
robot or scenario".
"""
from __future__ import annotations

import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import yaml

from ..interface import topics
from ..errors import InputError, RunError
from ..interface.resources import config_dir, source_root

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
    """A golden scenario: a parameter file (default the paper's), gains and overrides."""

    name: str
    description: str
    overrides: dict[str, Any] = field(default_factory=dict)
    path: Path | None = None           # scenario parameter file (None: config/paper_scenario)
    gains: Path | None = None          # gain file (None: config/tracker_gains.yaml)


SCENARIOS = {
    'paper': Scenario('paper', "paper's circle with the pinned synthesized non-fragile K "
                      '(test/data/golden_gains.yaml)'),
    'delta2': Scenario('delta2', 'same, with the perturbation E Delta_2 F injected in the tracker',
                       {'tracker': {'ros__parameters': {'Delta': [1.0, 0.0, 0.0, 1.0]}}}),
}


def data_dir() -> Path | None:
    """``test/data`` of the source checkout, or None when the package is installed."""
    root = source_root()
    return None if root is None else root / 'test' / 'data'


def golden_gains() -> Path:
    """The gain file of the package's golden scenarios.

    ``test/data/golden_gains.yaml`` when the checkout pins one next to the golden bags,
    else ``config/tracker_gains.yaml``.  The golden bags pin behaviour, not the shipped
    default: ``config/tracker_gains.yaml`` may change (a better certified design)
    without touching them.
    """
    base = data_dir()
    pinned = base / 'golden_gains.yaml' if base is not None else None
    return pinned if pinned is not None and pinned.is_file() \
        else config_dir() / 'tracker_gains.yaml'


def golden_bag(name: str, out: Path | None = None) -> Path:
    """Where the golden bag of scenario ``name`` lives (``out`` or the source tree).

    Parameters
    ----------
    name : str
        The scenario's name (the bag is ``golden_<name>``).
    out : pathlib.Path, optional
        The folder of the golden bags; the checkout's ``test/data`` when ``None``.

    Returns
    -------
    pathlib.Path
        The bag directory (it may not exist yet).

    Raises
    ------
    InputError
        Without ``out`` when the package is installed (no source tree).
    """
    base = Path(out) if out is not None else data_dir()
    if base is None:
        raise InputError(f'no place for the golden bag of {name!r}: the package is installed, '
                         'so pass --out DIR (it never writes into an installed package)')
    return base / f'golden_{name}'


def _overrides(scenario: Scenario, duration: float) -> dict[str, Any]:
    ov: dict[str, Any] = {node: {'ros__parameters': {'mode': 'lockstep'}}
                for node in ('plant', 'reference', 'tracker')}
    ov['plant']['ros__parameters']['duration'] = float(duration)
    for node, section in scenario.overrides.items():
        ov.setdefault(node, {}).setdefault('ros__parameters', {}).update(
            section.get('ros__parameters', {}))
    return ov


def scenario_params(scenario: Scenario, duration: float = DURATION) -> dict[str, Any]:
    """Node parameters of a scenario (its file, its gains, lockstep, ``duration`` s).

    Parameters
    ----------
    scenario : Scenario
        The scenario (its parameter file, gain file and overrides).
    duration : float, optional
        Simulated time of the run [s].

    Returns
    -------
    dict
        ``{node: {'ros__parameters': {...}}}`` for plant, reference and tracker.

    Raises
    ------
    InputError
        If a file is missing or is not a ROS 2 parameter file.
    """
    from .runner import scenario_parameters
    path = scenario.path if scenario.path is not None else config_dir() / 'paper_scenario.yaml'
    gains = scenario.gains if scenario.gains is not None else golden_gains()
    for f in (path, gains):
        if not Path(f).is_file():
            raise InputError(f'scenario {scenario.name!r}: file {f} does not exist')
    try:
        return scenario_parameters(Path(path), Path(gains), _overrides(scenario, duration))
    except (yaml.YAMLError, AttributeError, TypeError) as exc:
        raise InputError(f'scenario {scenario.name!r}: {path} or {gains} is not a ROS 2 '
                         f'parameter file ({exc})') from None


def scenario_from_file(path: str | Path, gains: str | Path | None = None) -> Scenario:
    """A user's scenario: a parameter file (plant, reference, tracker sections) and gains.

    Parameters
    ----------
    path : str or pathlib.Path
        The ROS 2 parameter file; its stem names the scenario (letters, digits, ``-``,
        ``_``).
    gains : str or pathlib.Path, optional
        A gain file; the golden gains (:func:`golden_gains`) when ``None``.

    Returns
    -------
    Scenario

    Raises
    ------
    InputError
        If the file does not exist or its name is not usable for a bag.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f'scenario file {p} does not exist')
    name = p.stem
    if not name.replace('_', '').replace('-', '').isalnum():
        raise InputError(f'scenario file name {p.name!r}: use letters, digits, - and _ '
                         '(the golden bag is named golden_<stem>)')
    return Scenario(name, f'scenario file {p}', path=p,
                    gains=Path(gains) if gains is not None else None)


def run_scenario(scenario: Scenario, run_dir: Path, *, composed: bool = False,
                 env: dict[str, str] | None = None, duration: float = DURATION) -> Path:
    """Run a scenario in lockstep and return its bag directory.

    Parameters
    ----------
    scenario : Scenario
        The scenario to run.
    run_dir : pathlib.Path
        Folder of the run (created): logs, parameter file and the bag.
    composed : bool, optional
        Run the nodes in one process (:func:`.runner.run_composed`) instead of separate
        processes.
    env : dict, optional
        Environment of the node processes (separate processes only).
    duration : float, optional
        Simulated time of the run [s].

    Returns
    -------
    pathlib.Path
        The recorded bag directory.

    Raises
    ------
    InputError
        If the scenario's files are missing or malformed.
    RunError
        If a node fails (the end of its log is in the message) or no bag is recorded.
    """
    from .runner import log_tail, run_composed, run_processes
    params = scenario_params(scenario, duration)
    run_dir.mkdir(parents=True, exist_ok=True)
    if composed:
        res = run_composed(params, run_dir, record=True, recorder_topics=TOPICS)
    else:
        res = run_processes(params, run_dir, record=True, env=env, progress=lambda s: None,
                            recorder_topics=TOPICS)
    bad = {k: v for k, v in res.exit_codes.items() if v not in (0, None)}
    if bad:
        tails = ''.join(f'\n--- {name}.log (end) ---\n{tail}' for name in bad
                        if (tail := log_tail(run_dir, name)))
        raise RunError(f'scenario {scenario.name!r} failed: exit codes {bad}; logs in '
                       f'{run_dir}{tails}')
    if res.bag is None:
        raise RunError(f'scenario {scenario.name!r} recorded no bag; logs in {run_dir}')
    return res.bag


def check_golden(scenarios: list[Scenario], *, out: Path | None = None, write: bool = False,
                 duration: float = DURATION, atol: float = ATOL,
                 echo: Callable[[str], object] = print) -> int:
    """Re-run ``scenarios``, compare with their golden bags, optionally replace them.

    Parameters
    ----------
    scenarios : list of Scenario
        The scenarios to run.
    out : pathlib.Path, optional
        The folder of the golden bags; required for scenarios from user files.
    write : bool, optional
        Replace a new or changed golden bag by the new run's (after printing the diff).
    duration : float, optional
        Simulated time of each run [s].
    atol : float, optional
        Absolute tolerance of the comparison.
    echo : callable, optional
        Called with each line of the report.

    Returns
    -------
    int
        The number of scenarios whose golden bag is new or changed.

    Raises
    ------
    InputError
        For a user scenario without ``out``, or no place for a golden bag.
    RunError
        If a run fails.
    """
    from ..bag.compare import compare_bags, format_differences
    own = [sc.name for sc in scenarios if sc.path is not None]
    if own and out is None:
        raise InputError(f'scenario(s) {", ".join(own)} come from your files: say where their '
                         'golden bags live with --out DIR (only the package\'s own scenarios '
                         'default to its source tree)')
    targets = [(sc, golden_bag(sc.name, out)) for sc in scenarios]   # fail early: no place
    changed = 0
    with tempfile.TemporaryDirectory() as tmp:
        for sc, old in targets:
            new = run_scenario(sc, Path(tmp) / sc.name, duration=duration)
            if old.exists():
                cmp = compare_bags(old, new, atol=atol)
                if cmp.equal:
                    echo(f'{sc.name}: unchanged ({sum(cmp.messages.values())} messages, {old})')
                    continue
                echo(f'{sc.name}: CHANGED ({old})\n{format_differences(cmp)}')
            else:
                echo(f'{sc.name}: new golden bag ({old})')
            changed += 1
            if write:
                if old.exists():
                    shutil.rmtree(old)
                old.parent.mkdir(parents=True, exist_ok=True)
                shutil.copytree(new, old)
                echo(f'  wrote {old}')
    return changed
