"""Performance measurement of the descriptor path (``tactile bench``).

:mod:`.bench` holds synthetic windows of the paper's robots and of larger
skins, the naive per-signal baseline, the agreement check, and the timing
functions; :mod:`.latency` measures sensor-stamp-to-prediction latency
through the ROS node graph.  Numbers and how to read them:
``lab/docs/performance.md``.
"""

__all__: list[str] = []
