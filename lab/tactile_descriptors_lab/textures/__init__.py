"""Texture models: fitting them to real recordings, and checking the simulator against those recordings."""
