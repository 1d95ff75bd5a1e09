"""The shipped scenario files as library objects: the paper's numbers come from ``config/``.

Code defaults are neutral (no delay term, zero perturbation, robot at the origin at
rest): the paper's Section IV scenario - ``tau = 0.2 s``, ``A_tau = diag(0.01, 0,
0.02, 0)``, ``F = 0.5 ones(2, 4)``, the initial pose ``(0.7, 0.1, pi/2)`` at 0.05
m/s - lives only in ``config/paper_scenario.yaml`` (node parameters) and
``config/paper_problem.yaml`` (synthesis data, ``Delta_1``/``Delta_2``).  The
simulation, the reproduction and the tests read it from there through this module.

See doc/ros-interface.md, section "Executables and defaults", and
doc/reproduction/paper_reproduction.md.
"""
from __future__ import annotations

import copy
import os
from collections.abc import Mapping
from functools import lru_cache
from pathlib import Path
from typing import Any, cast

from ..control.simulation.errors import LoopConfigError
from ..control.simulation.plant import PlantConfig
from ..control.validate import as_matrix
from ..errors import InputError
from ..files import read_yaml
from .resources import config_dir

__all__ = ['scenario_file', 'node_parameters', 'plant_config', 'paper_plant_config',
           'paper_perturbations', 'PLANT_FIELDS']

#: The plant parameters that are :class:`.PlantConfig` fields of the same name and unit.
PLANT_FIELDS = ('dt', 'tau', 'cmd_latency', 'lag_v', 'lag_w', 'max_linear_accel',
                'max_angular_accel', 'odom_latency', 'odom_rate', 'odom_noise', 'noise_seed',
                'odom_jitter', 'cmd_latency_jitter', 'stalls')

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


def _load(path: str) -> dict[str, Any]:
    """The file's mapping, a copy of its own for each caller.

    The parse is cached per version of the file: a file written again is read again.
    """
    try:
        st = os.stat(path)
        version = (st.st_mtime_ns, st.st_size)
    except OSError:
        version = (0, 0)                    # read_yaml says what is wrong with the path
    return copy.deepcopy(_parse(path, version))


@lru_cache(maxsize=8)
def _parse(path: str, version: tuple[int, int]) -> dict[str, Any]:
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


def plant_config(params: Mapping[str, Any], **overrides: Any) -> PlantConfig:
    """:class:`.PlantConfig` from the plant node's parameters (the same names and units).

    The one mapping from the plant's parameters to its configuration: the plant node's
    settings and every scenario file read in process (``run``, ``study --scenario``) use it.

    Parameters
    ----------
    params : mapping
        ``dt``, ``tau``, ``A_tau`` (16 doubles, row-major), ``initial_pose``
        ``[x, y, yaw]``, ``initial_speed``, ``cmd_latency_schedule`` and the parameters
        named as the fields of :data:`PLANT_FIELDS`; absent ones keep the neutral defaults.
    **overrides
        :class:`.PlantConfig` fields replacing the file's values (``x0=...``, ``dt=...``).

    Returns
    -------
    PlantConfig

    Raises
    ------
    InputError
        For a malformed ``A_tau`` or ``initial_pose`` (and ``PlantConfig``'s own checks).
    """
    kw: dict[str, Any] = {name: params[name] for name in PLANT_FIELDS if name in params}
    if 'A_tau' in params:
        kw['A_tau'] = tuple(map(tuple, as_matrix(params['A_tau'], 'A_tau', (4, 4), flat=True,
                                                 error=LoopConfigError)))
    if 'initial_pose' in params:
        pose = list(params['initial_pose'])
        if len(pose) != 3:
            raise InputError(f'initial_pose needs [x, y, yaw], got {pose}')
        kw['x0'], kw['y0'], kw['th0'] = pose
    if 'initial_speed' in params:
        kw['v0'] = params['initial_speed']
    if params.get('cmd_latency_schedule') is not None:
        kw['cmd_latency_schedule'] = tuple(params['cmd_latency_schedule'])
    kw.update(overrides)
    return PlantConfig(**kw)


def paper_plant_config(**overrides: Any) -> PlantConfig:
    """The paper scenario's plant (``config/paper_scenario.yaml``), with ``overrides``.

    Parameters
    ----------
    **overrides
        :class:`.PlantConfig` fields replacing the file's values.

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
