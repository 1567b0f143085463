"""Readers for public tactile data sets (no ROS)."""

__all__: list[str] = []
