"""Where the package's shipped files are: ``config/`` and, in a source checkout, ``test/data``.

Library code (golden bags, replay defaults) uses these instead of importing the CLI.
"""
from __future__ import annotations

from pathlib import Path

__all__ = ['PACKAGE_DIR', 'config_dir', 'source_root']

PACKAGE_DIR = Path(__file__).resolve().parent


def source_root() -> Path | None:
    """The source checkout holding this package (with ``package.xml`` and ``test/``), or
    None when the package is installed (site-packages / install space)."""
    root = PACKAGE_DIR.parent
    if (root / 'package.xml').is_file() and (root / 'test').is_dir() \
            and (root / 'setup.py').is_file():
        return root
    return None


def config_dir() -> Path:
    """The ``config/`` directory: source tree, or ``share/nonfragile_tracker/config`` installed."""
    src = PACKAGE_DIR.parent / 'config'
    if src.is_dir():
        return src
    try:
        from ament_index_python.packages import get_package_share_directory
        return Path(get_package_share_directory('nonfragile_tracker')) / 'config'
    except Exception:  # noqa: BLE001 - ament index absent or package not installed
        return src
