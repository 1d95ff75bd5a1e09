"""Thin rclpy adapters over the control core: reference, plant, tracker, recorder.

See doc/ros-interface.md and doc/developing.md, sections "Node shape" and "Layout".
"""
