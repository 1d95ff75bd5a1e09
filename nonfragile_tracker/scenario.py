"""The shipped scenario files as library objects: the paper's numbers come from ``config/``.

Code defaults are neutral (no delay term, zero perturbation, robot at the origin at
rest): the paper's Section IV scenario - ``tau = 0.2 s``, ``A_tau = diag(0.01, 0,
0.02, 0)``, ``F = 0.5 ones(2, 4)``, the initial pose ``(0.7, 0.1, pi/2)`` at 0.05
m/s - lives only in ``config/paper_scenario.yaml`` (node parameters) and
``config/paper_problem.yaml`` (synthesis data, ``Delta_1``/``Delta_2``).  The
simulation, the reproduction and the tests read it from there through this module.
"""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Any, cast

from .control.simulation.loop import PlantConfig
from .control.validate import as_matrix
from .errors import InputError
from .files import read_yaml
from .resources import config_dir

__all__ = ['scenario_file', 'node_parameters', 'plant_config', 'paper_plant_config',
           'paper_perturbations']

#: The paper's scenario (node parameters) and synthesis problem, in ``config/``.
PAPER_SCENARIO = 'paper_scenario.yaml'
PAPER_PROBLEM = 'paper_problem.yaml'


def scenario_file(name: str = PAPER_SCENARIO) -> Path:
    """Path of a shipped file in ``config/``.

    Parameters
    ----------
    name : str, optional
        The file name (default: the paper scenario).

    Returns
    -------
    pathlib.Path
        The path (not checked to exist).
    """
    return config_dir() / name


@lru_cache(maxsize=8)
def _load(path: str) -> dict[str, Any]:
    return cast(dict[str, Any], read_yaml(path, 'ROS 2 parameter file', mapping=True))


def node_parameters(node: str, path: str | Path | None = None) -> dict[str, Any]:
    """The ``ros__parameters`` of ``node`` in a parameter file (default: the paper scenario).

    Keys ``node``, ``/node`` and ``/**/node`` are accepted, as ROS 2 does.

    Parameters
    ----------
    node : str
        The node name (``plant``, ``tracker``, ...).
    path : str or pathlib.Path, optional
        The ROS 2 parameter file; the paper scenario when ``None``.

    Returns
    -------
    dict
        A copy of the node's ``ros__parameters`` (empty if the section has none).

    Raises
    ------
    InputError
        If the file has no section for ``node`` (or cannot be read as a mapping).
    """
    path = str(path if path is not None else scenario_file())
    data = _load(path)
    for key in (f'/**/{node}', f'/{node}', node):
        section = data.get(key)
        if isinstance(section, dict):
            return dict(section.get('ros__parameters') or {})
    raise InputError(f'{path}: no parameters for node {node!r}')


def plant_config(params: dict[str, Any], **overrides: Any) -> PlantConfig:
    """:class:`PlantConfig` from the plant node's parameters (the same names and units).

    Parameters
    ----------
    params : dict
        ``dt``, ``tau``, ``A_tau`` (16 doubles, row-major), ``initial_pose``
        ``[x, y, yaw]`` and ``initial_speed``; absent ones keep the neutral defaults.
    **overrides
        :class:`PlantConfig` fields replacing the file's values (``x0=...``, ``dt=...``).

    Returns
    -------
    PlantConfig

    Raises
    ------
    InputError
        For a malformed ``A_tau`` or ``initial_pose`` (and ``PlantConfig``'s own checks).
    """
    kw: dict[str, Any] = {}
    for name in ('dt', 'tau'):
        if name in params:
            kw[name] = params[name]
    if 'A_tau' in params:
        kw['A_tau'] = as_matrix(params['A_tau'], 'A_tau', (4, 4), flat=True)
    if 'initial_pose' in params:
        pose = list(params['initial_pose'])
        if len(pose) != 3:
            raise InputError(f'initial_pose needs [x, y, yaw], got {pose}')
        kw['x0'], kw['y0'], kw['th0'] = pose
    if 'initial_speed' in params:
        kw['v0'] = params['initial_speed']
    kw.update(overrides)
    return PlantConfig(**kw)


def paper_plant_config(**overrides: Any) -> PlantConfig:
    """The paper scenario's plant (``config/paper_scenario.yaml``), with ``overrides``.

    Parameters
    ----------
    **overrides
        :class:`PlantConfig` fields replacing the file's values.

    Returns
    -------
    PlantConfig
    """
    return plant_config(node_parameters('plant'), **overrides)


def paper_perturbations() -> dict[str, list[float]]:
    """The paper's ``Delta_1``, ``Delta_2`` (``config/paper_problem.yaml``), row-major lists."""
    data = read_yaml(scenario_file(PAPER_PROBLEM), 'problem file', mapping=True)
    return {str(k): as_matrix(v, f'perturbations.{k}').ravel().tolist()
            for k, v in (data.get('perturbations') or {}).items()}
