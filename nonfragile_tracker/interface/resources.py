"""Where the package's shipped files are: ``config/`` and, in a source checkout, its root.

Library modules (``runner``, ``reproduce``, ``golden``) and the command modules find
the shipped configuration here; nothing in this module writes anything.

See doc/developing.md, section "Layout" (``config/``).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ['PACKAGE_DIR', 'config_dir', 'source_root', 'load_paper_gains']

#: The installed or checked-out ``nonfragile_tracker`` Python package directory.
PACKAGE_DIR = Path(__file__).resolve().parent.parent


def source_root() -> Path | None:
    """The source checkout's root (holding ``package.xml`` and ``config/``), else ``None``.

    Returns
    -------
    pathlib.Path or None
        ``None`` when the package runs from an install (``site-packages`` or an
        ament ``install/`` tree): callers must then be given explicit paths to write.
    """
    root = PACKAGE_DIR.parent
    if (root / 'package.xml').is_file() and (root / 'config').is_dir():
        return root
    return None


def config_dir() -> Path:
    """The ``config/`` directory: source tree, or ``share/nonfragile_tracker/config`` installed.

    Returns
    -------
    pathlib.Path
        The directory holding ``paper_problem.yaml``, ``paper_scenario.yaml`` etc.
    """
    src = PACKAGE_DIR.parent / 'config'
    if src.is_dir():
        return src
    try:
        from ament_index_python.packages import get_package_share_directory
        return Path(get_package_share_directory('nonfragile_tracker')) / 'config'
    except Exception:  # noqa: BLE001 - ament index absent or package not installed
        return src


def load_paper_gains(path: Path | None = None) -> dict[str, np.ndarray]:
    """The paper's printed gains (``config/paper_gains.yaml``) as arrays by name.

    Parameters
    ----------
    path : pathlib.Path, optional
        Another file of the same form (``name: [[...], [...]]``).

    Returns
    -------
    dict of str to numpy.ndarray
        ``{'K_nf': ..., 'K_normal': ...}`` for the shipped file.
    """
    from ..control.validate import as_matrix
    from ..files import read_yaml
    path = Path(path) if path is not None else config_dir() / 'paper_gains.yaml'
    data = read_yaml(path, 'gain table', mapping=True)
    return {k: as_matrix(v, f'{path.name}: {k}') for k, v in data.items()}
