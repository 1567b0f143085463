"""The transport interface: open, close, read/write bytes, SPI transfers, CAN messages.

A transport owns one device.  It is created unopened (cheap, no I/O), opened
by :meth:`Transport.open` and released by :meth:`Transport.close`, which maps
onto a ROS 2 lifecycle node: ``on_configure`` opens, ``on_cleanup`` closes
(the pattern of ros2/demos ``lifecycle_py``).  Every transport is also a
context manager.  Three kinds exist:

* :class:`ByteTransport`: a byte stream (serial port, loopback, simulated):
  ``read(max_bytes, timeout_s) -> bytes`` and ``write(data) -> int``;
* :class:`SpiTransport`: an SPI master (Cheetah, simulated):
  ``transfer(cs, data) -> bytes`` and ``transfer_batch(segments)``;
* :class:`MessageTransport`: a message bus (CAN, simulated):
  ``recv(timeout_s) -> can.Message | None``, ``send(msg)`` and
  ``recv_batch(max_frames, timeout_s)`` (every queued frame as one numpy
  frame array, :mod:`~..codecs.can_frames`).

Device failures raise :class:`~..errors.TransportError`; a missing library or
device raises :class:`~..errors.TransportUnavailableError`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import TYPE_CHECKING, Any

from ..errors import TransportError

if TYPE_CHECKING:  # pragma: no cover
    import can
    import numpy as np

__all__ = ["Transport", "ByteTransport", "SpiSegment", "SpiTransport", "MessageTransport"]


class Transport(ABC):
    """Base of all transports: lifecycle and context management.

    Subclasses implement :meth:`_open` and :meth:`_close`; :meth:`open` and
    :meth:`close` are idempotent.
    """

    #: Registry name of the backend.
    name: str = ""

    def __init__(self) -> None:
        self._is_open = False

    @property
    def is_open(self) -> bool:
        """True between :meth:`open` and :meth:`close`."""
        return self._is_open

    def open(self) -> None:
        """Acquire the device (no-op when already open)."""
        if not self._is_open:
            self._open()
            self._is_open = True

    def close(self) -> None:
        """Release the device (no-op when closed)."""
        if self._is_open:
            try:
                self._close()
            finally:
                self._is_open = False

    def _require_open(self) -> None:
        if not self._is_open:
            raise TransportError(f"{self.name or type(self).__name__} transport is not open")

    @abstractmethod
    def _open(self) -> None: ...

    @abstractmethod
    def _close(self) -> None: ...

    def describe(self) -> dict[str, Any]:
        """Parameters worth showing in diagnostics."""
        return {"transport": self.name}

    def __enter__(self) -> Transport:
        self.open()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


class ByteTransport(Transport):
    """A byte stream."""

    @abstractmethod
    def read(self, max_bytes: int = 4096, timeout_s: float | None = None) -> bytes:
        """Bytes available now, at most ``max_bytes``; wait at most ``timeout_s`` for the first
        (``None``: the transport's default).  Returns ``b""`` on timeout."""

    @abstractmethod
    def write(self, data: bytes) -> int:
        """Send bytes; return how many were written."""


@dataclass(frozen=True)
class SpiSegment:
    """One chip-select-active SPI transfer in a batch.

    Attributes
    ----------
    cs : int or None
        Chip select 0..4; ``None`` selects all BioTacs at once (broadcast).
    data : bytes
        MOSI bytes; as many MISO bytes come back.
    delay_after_ns : int
        Pause after the chip select is released [ns].
    """

    cs: int | None
    data: bytes
    delay_after_ns: int = 0


class SpiTransport(Transport):
    """An SPI master with chip selects."""

    @abstractmethod
    def transfer(self, cs: int | None, data: bytes) -> bytes:
        """Select ``cs`` (``None``: all), shift ``data`` out, return the bytes shifted in."""

    def transfer_batch(self, segments: Sequence[SpiSegment]) -> list[bytes]:
        """Run many transfers as one batch (one USB round trip on adapters that queue);
        return the MISO bytes of each segment."""
        return [self.transfer(seg.cs, seg.data) for seg in segments]


class MessageTransport(Transport):
    """A message bus (CAN)."""

    @abstractmethod
    def recv(self, timeout_s: float | None = None) -> can.Message | None:
        """The next message, or ``None`` after ``timeout_s``."""

    @abstractmethod
    def send(self, msg: can.Message) -> None:
        """Send one message."""

    def recv_batch(self, max_frames: int = 65536, timeout_s: float | None = None) -> np.ndarray:
        """Every message available now (at most ``max_frames``) as one frame array.

        Waits up to ``timeout_s`` for the first message, then drains what is
        already queued without waiting.  Returns a
        :data:`~..codecs.can_frames.CAN_FRAME_DTYPE` array (empty on timeout).
        This default receives message by message; backends that can hand
        over frames in bulk (the simulator) override it.
        """
        from ..codecs.can_frames import frames_from_messages

        msgs = []
        msg = self.recv(timeout_s)
        while msg is not None:
            msgs.append(msg)
            if len(msgs) >= max_frames:
                break
            msg = self.recv(0.0)
        return frames_from_messages(msgs)
