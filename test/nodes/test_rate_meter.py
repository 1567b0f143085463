"""RateMeter: a driver's reader thread adds while the diagnostics timer reads."""

from __future__ import annotations

import threading

from tactile_descriptors_ros.nodes.common import RateMeter


def test_reading_the_rate_while_another_thread_adds_never_fails():
    meter = RateMeter(window_s=60.0)  # nothing expires: every read sums a long, growing deque
    for _ in range(5000):
        meter.add(1)
    done = threading.Event()
    errors: list[BaseException] = []

    def writer() -> None:
        try:
            for _ in range(200_000):
                meter.add(1)
        finally:
            done.set()

    thread = threading.Thread(target=writer)
    thread.start()
    reads = 0
    while not done.is_set():
        try:
            meter.rate_hz  # noqa: B018 - the read is the test
        except RuntimeError as exc:  # "deque mutated during iteration" without the lock
            errors.append(exc)
            break
        reads += 1
    thread.join()
    assert not errors and reads > 0
    assert meter.total == 205_000
