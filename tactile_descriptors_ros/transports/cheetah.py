"""Total Phase Cheetah USB-SPI adapter, through Total Phase's own Python API.

The API (``cheetah_py.py`` plus its shared library) may not be
redistributed, so it is not part of this package: download it from Total
Phase and put it on ``PYTHONPATH``.  It is imported only in :meth:`open`;
without it :class:`~..errors.TransportUnavailableError` says what to do.

SPI mode 0, MSB first, chip selects active low, as SynTouch's example code
configures it.  Chip select index -> SS pin mask follows SynTouch's BioTac
board: ``0x01 0x02 0x04`` for three BioTacs and ``0x05 0x06`` for the fourth
and fifth (a decoded 3-bit select), ``0x07`` selects all (broadcast).
"""

from __future__ import annotations

import importlib
from array import array
from collections.abc import Sequence
from typing import Any

from ..errors import ConfigError, TransportError, TransportUnavailableError
from .base import SpiSegment, SpiTransport

__all__ = ["CheetahTransport", "CHIP_SELECT_MASKS", "CS_ALL_MASK"]

#: SS pin mask of chip selects 0..4 (SynTouch BioTac board).
CHIP_SELECT_MASKS: tuple[int, ...] = (0x01, 0x02, 0x04, 0x05, 0x06)
#: SS mask selecting every BioTac.
CS_ALL_MASK = 0x07

_MISSING_API = (
    "the Total Phase Cheetah Python API 'cheetah_py' is not installed; it may not be "
    "redistributed: download the Cheetah API from totalphase.com and put cheetah_py.py and "
    "its cheetah.so/.dll on PYTHONPATH")


class CheetahTransport(SpiTransport):
    """SPI through a Cheetah adapter.

    Parameters
    ----------
    port : int
        Cheetah port number (``ch_find_devices``); ``-1`` opens the first free one.
    bitrate_khz : int
        SPI clock [kHz] (SynTouch: 4400).
    target_power : bool
        Power the BioTacs from the adapter.
    module : str
        Name of the API module (tests substitute a fake).
    """

    name = "cheetah"

    def __init__(self, port: int = -1, bitrate_khz: int = 4400, target_power: bool = True,
                 module: str = "cheetah_py") -> None:
        super().__init__()
        self.port = int(port)
        self.bitrate_khz = int(bitrate_khz)
        self.target_power = bool(target_power)
        self.module = module
        self._ch: Any = None
        self._handle: Any = None

    def _open(self) -> None:
        try:
            ch = importlib.import_module(self.module)
        except ImportError as exc:
            raise TransportUnavailableError(_MISSING_API) from exc
        port = self.port
        if port < 0:
            found = ch.ch_find_devices(16)
            n, ports = found[0], list(found[1])[: max(found[0], 0)]
            free = [p for p in ports if not p & ch.CH_PORT_NOT_FREE]
            if n <= 0 or not free:
                raise TransportUnavailableError("no free Cheetah adapter found (is it plugged in?)")
            port = free[0]
        handle = ch.ch_open(port)
        if handle <= 0:
            raise TransportError(f"cannot open Cheetah on port {port}: {ch.ch_status_string(handle)}")
        try:
            ch.ch_spi_configure(handle, 0, 0, ch.CH_SPI_BITORDER_MSB, 0x0)
            if self.target_power:
                ch.ch_target_power(handle, ch.CH_TARGET_POWER_ON)
                ch.ch_sleep_ms(100)
            got = ch.ch_spi_bitrate(handle, self.bitrate_khz)
            if got <= 0:
                raise TransportError(f"Cheetah refused bitrate {self.bitrate_khz} kHz: {ch.ch_status_string(got)}")
            ch.ch_spi_queue_clear(handle)
            ch.ch_spi_queue_oe(handle, 1)
        except Exception:
            ch.ch_close(handle)
            raise
        self._ch, self._handle, self.port = ch, handle, port

    def _close(self) -> None:
        ch, handle = self._ch, self._handle
        self._ch = self._handle = None
        if ch is not None and handle is not None:
            try:
                ch.ch_spi_queue_clear(handle)
                ch.ch_spi_queue_oe(handle, 0)
                if self.target_power:
                    ch.ch_target_power(handle, ch.CH_TARGET_POWER_OFF)
            finally:
                ch.ch_close(handle)

    @staticmethod
    def _mask(cs: int | None) -> int:
        if cs is None:
            return CS_ALL_MASK
        if not 0 <= int(cs) < len(CHIP_SELECT_MASKS):
            raise ConfigError(f"chip select must be 0..{len(CHIP_SELECT_MASKS) - 1} or None, got {cs}")
        return CHIP_SELECT_MASKS[int(cs)]

    def transfer(self, cs: int | None, data: bytes) -> bytes:
        return self.transfer_batch([SpiSegment(cs, bytes(data))])[0]

    def transfer_batch(self, segments: Sequence[SpiSegment]) -> list[bytes]:
        self._require_open()
        ch, h = self._ch, self._handle
        total = 0
        ch.ch_spi_queue_clear(h)
        for seg in segments:
            ch.ch_spi_queue_ss(h, self._mask(seg.cs))
            if seg.data:
                ch.ch_spi_queue_array(h, array("B", seg.data))
            ch.ch_spi_queue_ss(h, 0)
            if seg.delay_after_ns > 0:
                ch.ch_spi_queue_delay_ns(h, int(seg.delay_after_ns))
            total += len(seg.data)
        count, data_in = ch.ch_spi_batch_shift(h, total)
        if count < 0:
            raise TransportError(f"Cheetah SPI batch failed: {ch.ch_status_string(count)}")
        raw = bytes(data_in)[:total]
        if len(raw) < total:
            raise TransportError(f"Cheetah returned {len(raw)} of {total} bytes")
        out, pos = [], 0
        for seg in segments:
            out.append(raw[pos: pos + len(seg.data)])
            pos += len(seg.data)
        return out

    def describe(self) -> dict[str, Any]:
        return {"transport": self.name, "port": self.port, "bitrate_khz": self.bitrate_khz}
