"""Thin rclpy adapters over the control core: reference, plant, tracker, recorder."""
