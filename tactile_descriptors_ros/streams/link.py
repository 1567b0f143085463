"""A device link that survives an unplugged device: reopen by itself, report the time it was gone.

A USB-serial bridge or a USB-CAN adapter that is unplugged makes every read
fail (a pty whose other end closed, ``EIO`` on a tty, a vanished socket).
Reading on from the dead handle fails forever; only closing it and opening
the device again brings the data back once the device returns.
:class:`DeviceLink` does exactly that from the reader loop, without a
lifecycle transition: a :class:`~..errors.TransportError` marks the link
down and closes the transport; :meth:`DeviceLink.poll_reopen` tries to open
it again every ``retry_s`` until it works, then reports how long the device
was gone (the gap the streams then count as lost time).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from ..errors import TactileError

__all__ = ["DeviceLink"]


class DeviceLink:
    """One device transport with automatic reopening.

    Parameters
    ----------
    make : callable() -> Transport
        Builds a new, unopened transport (called for the first open and for
        every reopen, so a device that comes back under the same name is
        found again).
    retry_s : float
        Pause between reopen attempts while the device is gone [s].
    clock : callable() -> float
        Monotonic clock [s] (tests may pass their own).

    Attributes
    ----------
    transport : Transport or None
        The open transport, ``None`` while down.
    disconnects, reconnects, reopen_failures : int
        Times the device was lost, found again, and failed to reopen.
    last_error : str or None
        The newest transport error.
    down_s_total : float
        Total time without the device [s].
    last_gap_s : float or None
        Length of the most recent absence [s].
    """

    def __init__(self, make: Callable[[], Any], retry_s: float = 0.25,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._make = make
        self.retry_s = float(retry_s)
        self._clock = clock
        self.transport: Any = None
        self.disconnects = 0
        self.reconnects = 0
        self.reopen_failures = 0
        self.last_error: str | None = None
        self.down_s_total = 0.0
        self.last_gap_s: float | None = None
        self._down_since: float | None = None
        self._next_try = 0.0
        #: start times of the reopen attempts that failed during the current or last absence
        self.failed_attempts: list[float] = []

    @property
    def connected(self) -> bool:
        """True while the transport is open."""
        return self.transport is not None

    @property
    def down_for_s(self) -> float:
        """How long the device has been gone [s] (0 while connected)."""
        return 0.0 if self._down_since is None else self._clock() - self._down_since

    def open(self) -> None:
        """First open (raises :class:`~..errors.TactileError` like the transport's ``open``)."""
        transport = self._make()
        try:
            transport.open()
        except TactileError:
            transport.close()
            raise
        self.transport = transport

    def lost(self, exc: BaseException) -> None:
        """The transport failed: close it and start reopening."""
        self.last_error = str(exc)
        if self.transport is None:
            return
        self.disconnects += 1
        self.failed_attempts = []
        self._down_since = self._clock()
        self._next_try = self._down_since + self.retry_s
        self._close_quietly()

    def poll_reopen(self) -> bool:
        """While down: try to reopen when due.  True when the device is back (just now)."""
        if self.transport is not None or self._down_since is None:
            return False
        now = self._clock()
        if now < self._next_try:
            return False
        self._next_try = now + self.retry_s
        transport = self._make()
        try:
            transport.open()
        except TactileError as exc:
            self.reopen_failures += 1
            self.failed_attempts.append(now)
            self.last_error = f"reopening: {exc}"
            try:
                transport.close()
            except TactileError:
                pass
            return False
        self.transport = transport
        gap = self._clock() - self._down_since
        self.last_gap_s = gap
        self.down_s_total += gap
        self._down_since = None
        self.reconnects += 1
        return True

    def wait_s(self) -> float:
        """Time until the next reopen attempt is due [s] (0 when connected)."""
        if self.transport is not None:
            return 0.0
        return max(0.0, self._next_try - self._clock())

    def close(self) -> None:
        """Close the transport (no reopening afterwards)."""
        self._down_since = None
        self._close_quietly()

    def _close_quietly(self) -> None:
        transport, self.transport = self.transport, None
        if transport is not None:
            try:
                transport.close()
            except (TactileError, OSError):
                pass

    def as_dict(self) -> dict[str, Any]:
        """Counters for diagnostics."""
        return {"connected": self.connected, "disconnects": self.disconnects, "reconnects": self.reconnects,
                "reopen_failures": self.reopen_failures, "down_s_total": round(self.down_s_total, 3),
                "last_gap_s": None if self.last_gap_s is None else round(self.last_gap_s, 3)}
