"""``drain_frames`` takes every queued frame, keeps the newest ``limit`` of a backlog and counts the rest as shed."""

from __future__ import annotations

import numpy as np

from tactile_descriptors_ros.streams.skin import drain_frames


class _Queue:
    """A transport holding ``n`` frames (their index as the frame), handed out ``recv_batch`` by ``recv_batch``."""

    def __init__(self, n: int) -> None:
        self.frames = np.arange(n)
        self.calls = 0

    def recv_batch(self, max_frames: int, timeout_s: float) -> np.ndarray:
        self.calls += 1
        out, self.frames = self.frames[:max_frames], self.frames[max_frames:]
        return out


def test_a_queue_within_the_limit_is_read_whole():
    q = _Queue(2_500)
    frames, shed = drain_frames(q, 0.05, chunk=1_000, limit=4_000)
    assert frames.tolist() == list(range(2_500)) and shed == 0 and q.calls == 3


def test_a_backlog_beyond_the_limit_keeps_its_newest_frames_and_counts_the_shed():
    n, limit = 1_000_000, 65_536  # e.g. 8 s of a 116-cell skin behind a driver that was stopped
    q = _Queue(n)
    frames, shed = drain_frames(q, 0.05, chunk=4_096, limit=limit)
    assert shed == n - limit and frames.size == limit
    assert np.array_equal(frames, np.arange(n - limit, n))  # the newest, in order: they time the clock
    assert not q.frames.size  # the read ended with the newest frame the transport held
