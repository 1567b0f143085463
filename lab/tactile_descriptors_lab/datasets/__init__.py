"""Readers for public tactile data sets (no ROS)."""

__all__: list[str] = []  # see the modules: recording, mapping, tables, bagfiles, sources
