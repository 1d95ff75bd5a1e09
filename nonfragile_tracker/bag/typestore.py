"""The one ROS 2 Jazzy typestore of the ``bag`` package (rosbags).

Readers and writers share it: message definitions and RIHS01 hashes are built once.

See doc/bags.md, section "Recording and golden bags".
"""
from __future__ import annotations

from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

__all__ = ['jazzy_typestore']

_TYPESTORE: Typestore | None = None


def jazzy_typestore() -> Typestore:
    """The shared ROS 2 Jazzy typestore (message definitions and RIHS01 hashes)."""
    global _TYPESTORE
    if _TYPESTORE is None:
        _TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
    return _TYPESTORE
