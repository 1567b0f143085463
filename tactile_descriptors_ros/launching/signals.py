"""Ctrl-C and SIGTERM as a stop request that a signal handler can make without taking a lock.

Python runs a signal handler in the main thread, between two bytecodes of
whatever that thread is doing.  A handler that calls
:meth:`threading.Event.set` takes the event's (non-re-entrant) lock; when the
main thread itself holds that lock at that moment -- for a few bytecodes of
every :meth:`threading.Event.wait`, which is how a supervising loop sleeps --
the handler waits for a lock its own thread will never release, and the
process hangs.  :class:`SignalStop` separates the two: the handler only
assigns a flag (:meth:`SignalStop.request`), which every reader sees at once,
and waiting polls that flag in short slices.  Written here because the
standard alternative, ``signal.set_wakeup_fd``, is one file descriptor per
process and needs a reader thread, where the loops that stop already poll.
"""

from __future__ import annotations

import contextlib
import signal
import threading
import time
from collections.abc import Iterator
from typing import Any

__all__ = ["SignalStop", "stop_on_signals"]


class SignalStop:
    """A stop flag with :class:`threading.Event`'s reading interface that a signal handler may set.

    Parameters
    ----------
    poll_s
        Longest time :meth:`wait` goes without looking at a request made by
        a signal handler [s].
    """

    def __init__(self, poll_s: float = 0.05) -> None:
        self._event = threading.Event()
        self._requested = False
        self.poll_s = float(poll_s)

    def request(self) -> None:
        """Ask to stop; takes no lock, so it is safe inside a signal handler."""
        self._requested = True

    def set(self) -> None:
        """Ask to stop and wake every thread in :meth:`wait` at once (not from a signal handler)."""
        self._requested = True
        self._event.set()

    def is_set(self) -> bool:
        """Whether a stop was asked for (by :meth:`request` or :meth:`set`)."""
        return self._requested or self._event.is_set()

    def wait(self, timeout: float | None = None) -> bool:
        """Block until a stop is asked for or ``timeout`` seconds pass; returns :meth:`is_set`."""
        deadline = None if timeout is None else time.monotonic() + max(0.0, timeout)
        while not self.is_set():
            left = self.poll_s if deadline is None else min(self.poll_s, deadline - time.monotonic())
            if left <= 0:
                break
            self._event.wait(left)
        return self.is_set()


@contextlib.contextmanager
def stop_on_signals(stop: SignalStop | None = None, *, second_raises: bool = True) -> Iterator[SignalStop]:
    """Turn SIGINT and SIGTERM into a stop request while inside the block (main thread only).

    A recorder, player or launcher then finishes its current step and closes
    cleanly, also when started in the background by a shell that ignores
    SIGINT, or stopped by ``kill`` (SIGTERM).  With ``second_raises``, a
    second signal while stopping raises ``KeyboardInterrupt``.  Outside the
    main thread no handler can be installed: the flag is yielded unwatched.
    """
    stop = stop if stop is not None else SignalStop()
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return
    watched = (signal.SIGINT, signal.SIGTERM)
    previous = {s: signal.getsignal(s) for s in watched}

    def handler(signum: int, frame: Any) -> None:
        if second_raises and stop.is_set():
            raise KeyboardInterrupt
        stop.request()

    for s in watched:
        signal.signal(s, handler)
    try:
        yield stop
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
