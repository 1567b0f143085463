"""Serial ports through pyserial (devices, ``loop://``, ``socket://``, ptys)."""

from __future__ import annotations

from typing import Any

from ..errors import TransportError, TransportUnavailableError
from .base import ByteTransport

__all__ = ["SerialTransport"]

_SERIAL_OPTIONS = frozenset({"bytesize", "parity", "stopbits", "xonxoff", "rtscts", "dsrdtr",
                             "write_timeout", "inter_byte_timeout", "exclusive"})


class SerialTransport(ByteTransport):
    """A serial port opened with :func:`serial.serial_for_url`.

    Parameters
    ----------
    port : str
        Device (``/dev/ttyACM0``) or pyserial URL (``loop://``, ``socket://host:port``).
    baudrate : int
        Line rate (ignored by USB CDC devices and ``loop://``).
    timeout_s : float
        Default wait of :meth:`read` for the first byte.
    **options
        Further keyword arguments of :class:`serial.Serial` (``parity``, ``rtscts``, ...).
    """

    name = "serial"

    def __init__(self, port: str, baudrate: int = 921600, timeout_s: float = 0.05, **options: Any) -> None:
        super().__init__()
        if not port:
            from ..errors import ConfigError
            raise ConfigError("a serial port or URL is required", key="port")
        self.port = str(port)
        self.baudrate = int(baudrate)
        self.timeout_s = float(timeout_s)
        unknown = sorted(set(options) - _SERIAL_OPTIONS)
        if unknown:
            from ..errors import ConfigError
            raise ConfigError(f"unknown serial option(s) {unknown}; known: {sorted(_SERIAL_OPTIONS)}",
                              key="transport")
        self.options = options
        self._serial: Any = None

    def _open(self) -> None:
        try:
            import serial
        except ImportError as exc:  # pragma: no cover - pyserial is a dependency
            raise TransportUnavailableError("pyserial is not installed (pip install pyserial)") from exc
        try:
            self._serial = serial.serial_for_url(self.port, baudrate=self.baudrate, timeout=self.timeout_s,
                                                 **self.options)
        except (serial.SerialException, ValueError, OSError) as exc:
            raise TransportError(f"cannot open serial port {self.port!r}: {exc}") from exc

    def _close(self) -> None:
        ser, self._serial = self._serial, None
        if ser is not None:
            ser.close()

    def read(self, max_bytes: int = 4096, timeout_s: float | None = None) -> bytes:
        self._require_open()
        import serial
        ser = self._serial
        try:
            timeout = self.timeout_s if timeout_s is None else float(timeout_s)
            if ser.timeout != timeout:  # setting it reconfigures a real port: only on change
                ser.timeout = timeout
            first = ser.read(1)
            if not first or max_bytes <= 1:
                return first
            more = min(ser.in_waiting, max_bytes - 1)
            return first + (ser.read(more) if more else b"")
        except (serial.SerialException, OSError) as exc:
            raise TransportError(f"serial port {self.port!r} failed: {exc}") from exc

    def write(self, data: bytes) -> int:
        self._require_open()
        import serial
        try:
            n = self._serial.write(data)
            self._serial.flush()
            return int(n or 0)
        except (serial.SerialException, OSError) as exc:
            raise TransportError(f"serial port {self.port!r} failed: {exc}") from exc

    def describe(self) -> dict[str, Any]:
        return {"transport": self.name, "port": self.port, "baudrate": self.baudrate}
