"""A transport whose device is a Python object: the simulator's wire-byte sources.

The source is given at construction and decides what the "device" sends;
the transport adds the lifecycle and the interface, so a driver cannot tell
it from hardware.  A source may provide any of:

* ``read(max_bytes) -> bytes`` (or be a plain callable ``f(max_bytes) -> bytes``):
  a byte stream, for :meth:`SimulatedTransport.read`;
* ``write(data)``: receives what the driver writes (else it is kept in ``written``);
* ``transfer(cs, data) -> bytes``: an SPI device (e.g. :class:`~..codecs.biotac_spi.BiotacSpiResponder`
  instances behind a chip-select map, see :class:`SpiBus`);
* ``recv(timeout_s) -> can.Message | None`` and ``send(msg)``: a CAN bus;
  optionally ``recv_batch(max_frames, timeout_s)`` returning a CAN frame
  array (:mod:`~..codecs.can_frames`) for bulk reads;
* ``open()`` / ``close()``: called with the transport's.

Sources should emit real wire bytes made with this package's encoders.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import Any

from ..errors import TransportError
from .base import ByteTransport, MessageTransport, SpiTransport

__all__ = ["SimulatedTransport", "SpiBus"]


class SpiBus:
    """An SPI source made of per-chip-select devices with ``transfer(mosi) -> miso``.

    A broadcast (``cs=None``) goes to every device; the MISO of a broadcast is
    all zeros (BioTacs do not drive MISO together).
    """

    def __init__(self, devices: Mapping[int, Any]) -> None:
        self.devices = dict(devices)

    def transfer(self, cs: int | None, data: bytes) -> bytes:
        if cs is None:
            for dev in self.devices.values():
                dev.transfer(data)
            return bytes(len(data))
        dev = self.devices.get(int(cs))
        if dev is None:
            return b"\xff" * len(data)  # nothing selected: MISO pulled up
        return bytes(dev.transfer(data))


class SimulatedTransport(ByteTransport, SpiTransport, MessageTransport):
    """Transport over a simulator source (see the module docstring).

    Parameters
    ----------
    source : object or callable
        The simulated device.
    poll_s : float
        When a byte source has nothing and a read has a timeout, wait this
        long once before returning ``b""`` (keeps driver loops from spinning).
    """

    name = "simulated"

    def __init__(self, source: Any, poll_s: float = 0.001) -> None:
        super().__init__()
        if source is None:
            from ..errors import ConfigError
            raise ConfigError("the simulated transport needs a source", key="source")
        self.source = source
        self.poll_s = float(poll_s)
        self.written = bytearray()
        self.sent: list[Any] = []

    def _call(self, name: str) -> Callable[..., Any]:
        fn = getattr(self.source, name, None)
        if fn is None:
            raise TransportError(f"simulated source {type(self.source).__name__} has no {name}()")
        return fn

    def _open(self) -> None:
        fn = getattr(self.source, "open", None)
        if callable(fn):
            fn()

    def _close(self) -> None:
        fn = getattr(self.source, "close", None)
        if callable(fn):
            fn()

    def read(self, max_bytes: int = 4096, timeout_s: float | None = None) -> bytes:
        self._require_open()
        fn = getattr(self.source, "read", None) or (self.source if callable(self.source) else None)
        if fn is None:
            raise TransportError(f"simulated source {type(self.source).__name__} has no read()")
        data = bytes(fn(max_bytes))
        if not data and timeout_s:
            time.sleep(min(float(timeout_s), self.poll_s))
            data = bytes(fn(max_bytes))
        if len(data) > max_bytes:
            raise TransportError(f"simulated source returned {len(data)} bytes for max_bytes={max_bytes}")
        return data

    def write(self, data: bytes) -> int:
        self._require_open()
        fn = getattr(self.source, "write", None)
        if fn is not None:
            fn(bytes(data))
        else:
            self.written += data
        return len(data)

    def transfer(self, cs: int | None, data: bytes) -> bytes:
        self._require_open()
        out = bytes(self._call("transfer")(cs, bytes(data)))
        if len(out) != len(data):
            raise TransportError(f"simulated SPI returned {len(out)} bytes for {len(data)} sent")
        return out

    def recv(self, timeout_s: float | None = None):  # type: ignore[override]
        self._require_open()
        return self._call("recv")(timeout_s)

    def recv_batch(self, max_frames: int = 65536, timeout_s: float | None = None):  # type: ignore[override]
        """Every due frame as one frame array: straight from a source with ``recv_batch`` (no python-can
        objects), else message by message from its ``recv``."""
        self._require_open()
        fn = getattr(self.source, "recv_batch", None)
        if fn is None:
            return super().recv_batch(max_frames, timeout_s)
        frames = fn(max_frames, timeout_s)
        if len(frames) > max_frames:
            raise TransportError(f"simulated source returned {len(frames)} frames for max_frames={max_frames}")
        return frames

    def send(self, msg) -> None:  # type: ignore[override]
        self._require_open()
        fn = getattr(self.source, "send", None)
        if fn is not None:
            fn(msg)
        else:
            self.sent.append(msg)

    def describe(self) -> dict[str, Any]:
        """Name and source; for a simulated scene also the CPU its simulation took so far (``simulator_cpu_s``)
        and, paced, the native id of the thread simulating it (``simulator_thread_id``), which is not the
        driver's work: a robot's bus has no simulator in the driver's process."""
        out: dict[str, Any] = {"transport": self.name, "source": type(self.source).__name__}
        cpu_s = getattr(self.source, "simulate_cpu_s", None)
        if cpu_s is not None:
            out["simulator_cpu_s"] = round(float(cpu_s), 3)
        thread_id = getattr(self.source, "thread_id", None)
        if thread_id is not None:
            out["simulator_thread_id"] = int(thread_id)
        return out

