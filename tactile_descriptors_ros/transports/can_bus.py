"""CAN buses through python-can (SocketCAN, PCAN, Kvaser, ..., and ``virtual`` for tests)."""

from __future__ import annotations

from typing import Any

from ..errors import TransportError, TransportUnavailableError
from .base import MessageTransport

__all__ = ["CanTransport"]


class CanTransport(MessageTransport):
    """A python-can bus.

    Parameters
    ----------
    interface : str
        python-can interface name (``socketcan``, ``pcan``, ``virtual``, ...).
    channel : str
        Interface channel (``can0``; any name for ``virtual``: buses with the
        same channel name see each other's messages).
    bitrate : int, optional
        Bus bitrate, where the interface sets it.
    timeout_s : float
        Default wait of :meth:`recv`.
    **options
        Further keyword arguments of :class:`can.Bus` (``receive_own_messages``, ...).
    """

    name = "can"

    def __init__(self, interface: str = "socketcan", channel: str = "can0", bitrate: int | None = None,
                 timeout_s: float = 0.05, **options: Any) -> None:
        super().__init__()
        self.interface = str(interface)
        self.channel = str(channel)
        self.bitrate = bitrate
        self.timeout_s = float(timeout_s)
        self.options = options
        self._bus: Any = None

    def _open(self) -> None:
        try:
            import can
        except ImportError as exc:  # pragma: no cover - python-can is a dependency
            raise TransportUnavailableError("python-can is not installed (pip install python-can)") from exc
        kwargs = dict(self.options)
        if self.bitrate is not None:
            kwargs["bitrate"] = int(self.bitrate)
        try:
            self._bus = can.Bus(interface=self.interface, channel=self.channel, **kwargs)
        except (can.CanInterfaceNotImplementedError, ImportError) as exc:
            raise TransportUnavailableError(
                f"CAN interface {self.interface!r} is not available here: {exc}") from exc
        except (can.CanError, OSError, ValueError) as exc:
            raise TransportError(f"cannot open CAN {self.interface}:{self.channel}: {exc}") from exc

    def _close(self) -> None:
        bus, self._bus = self._bus, None
        if bus is not None:
            bus.shutdown()

    def recv(self, timeout_s: float | None = None):  # type: ignore[override]
        self._require_open()
        import can
        try:
            return self._bus.recv(self.timeout_s if timeout_s is None else float(timeout_s))
        except (can.CanError, OSError) as exc:
            raise TransportError(f"CAN {self.interface}:{self.channel} failed: {exc}") from exc

    def send(self, msg) -> None:  # type: ignore[override]
        self._require_open()
        import can
        try:
            self._bus.send(msg)
        except (can.CanError, OSError) as exc:
            raise TransportError(f"CAN {self.interface}:{self.channel} send failed: {exc}") from exc

    def describe(self) -> dict[str, Any]:
        return {"transport": self.name, "interface": self.interface, "channel": self.channel,
                "bitrate": self.bitrate}
