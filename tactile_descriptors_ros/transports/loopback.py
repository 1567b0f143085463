"""In-process byte loopback: what is written is read back (tests, demos without hardware)."""

from __future__ import annotations

import threading
import time

from .base import ByteTransport

__all__ = ["LoopbackTransport"]


class LoopbackTransport(ByteTransport):
    """Bytes written are read back in order; thread-safe.

    Parameters
    ----------
    timeout_s : float
        Default wait of :meth:`read` for the first byte.
    """

    name = "loopback"

    def __init__(self, timeout_s: float = 0.0) -> None:
        super().__init__()
        self.timeout_s = float(timeout_s)
        self._buf = bytearray()
        self._cond = threading.Condition()

    def _open(self) -> None:
        with self._cond:
            self._buf.clear()

    def _close(self) -> None:
        with self._cond:
            self._buf.clear()
            self._cond.notify_all()

    def read(self, max_bytes: int = 4096, timeout_s: float | None = None) -> bytes:
        self._require_open()
        wait = self.timeout_s if timeout_s is None else float(timeout_s)
        deadline = time.monotonic() + wait
        with self._cond:
            while not self._buf:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return b""
                self._cond.wait(remaining)
            out = bytes(self._buf[:max_bytes])
            del self._buf[:max_bytes]
            return out

    def write(self, data: bytes) -> int:
        self._require_open()
        with self._cond:
            self._buf += data
            self._cond.notify_all()
        return len(data)
