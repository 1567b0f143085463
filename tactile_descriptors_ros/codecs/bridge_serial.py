"""USB-serial bridge framing for BioTac frames (our definition; no public one exists).

A microcontroller bridge runs the SPI side (one frame pattern, up to five
BioTacs) and forwards, for every frame and BioTac, the SPI reply bytes in one
serial frame.  All multi-byte fields are big-endian::

    offset  size  field
    0       2     sync             0xB1 0x4E
    2       1     type             0x01 sample frame, 0x02 serial number
    3       1     chip_select      0..4
    4       2     sequence         frame counter per chip select, wraps at 65536
    6       4     t_us             bridge clock at the frame's first word [us], wraps
    10      2     length           payload bytes N (0..1024)
    12      N     payload          type 0x01: the SPI reply bytes of the frame
                                   (2 per word, pattern order, exactly as on the wire);
                                   type 0x02: the ASCII serial number
    12+N    4     crc              CRC-32/ISO-HDLC over bytes 2 .. 12+N-1

Both sync bytes have even parity, so neither can occur in a valid BioTac
reply byte (those all have odd parity).  The payload is not interpreted
here: :class:`~.biotac_spi.BiotacFrameDecoder` decodes it, so SPI-level
faults (parity, error words) stay visible after the serial hop.

:class:`BridgeDecoder` is a streaming decoder (``feed(bytes) -> frames``)
that resynchronises after garbage, counts CRC errors, truncations, bad
headers, sequence gaps, duplicates and resyncs (:class:`~.framing.StreamStats`).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum

from ..errors import CodecError
from .biotac_spi import MAX_SENSORS
from .framing import SequenceTracker, StreamDecoder, StreamStats, crc32

__all__ = [
    "SYNC",
    "HEADER_SIZE",
    "MAX_PAYLOAD",
    "BridgeFrameType",
    "BridgeFrame",
    "encode_bridge_frame",
    "BridgeEncoder",
    "BridgeDecoder",
]

SYNC = b"\xb1\x4e"
#: Header bytes between the sync and the payload.
HEADER_SIZE = 10
#: Largest payload accepted (a longer length field is a bad header).
MAX_PAYLOAD = 1024
_HEADER = struct.Struct(">BBHIH")


class BridgeFrameType(IntEnum):
    """Payload kinds of the bridge framing."""

    SAMPLE = 0x01  #: SPI reply bytes of one frame of one BioTac
    SERIAL_NUMBER = 0x02  #: ASCII serial number of the BioTac on this chip select


@dataclass(frozen=True)
class BridgeFrame:
    """One bridge frame.

    Attributes
    ----------
    kind : BridgeFrameType
    chip_select : int
        0..4.
    sequence : int
        0..65535, per chip select and kind.
    t_us : int
        Bridge clock at the first word [us], 32-bit wrapping.
    payload : bytes
    """

    kind: BridgeFrameType
    chip_select: int
    sequence: int
    t_us: int
    payload: bytes


def encode_bridge_frame(frame: BridgeFrame) -> bytes:
    """Wire bytes of one frame.

    Raises
    ------
    CodecError
        If a field is out of range.
    """
    if not 0 <= frame.chip_select < MAX_SENSORS:
        raise CodecError(f"chip select must be 0..{MAX_SENSORS - 1}, got {frame.chip_select}")
    if len(frame.payload) > MAX_PAYLOAD:
        raise CodecError(f"payload of {len(frame.payload)} bytes exceeds {MAX_PAYLOAD}")
    if not 0 <= frame.sequence <= 0xFFFF:
        raise CodecError(f"sequence must be 0..65535, got {frame.sequence}")
    body = _HEADER.pack(int(BridgeFrameType(frame.kind)), frame.chip_select, frame.sequence,
                        frame.t_us & 0xFFFFFFFF, len(frame.payload)) + bytes(frame.payload)
    return SYNC + body + crc32(body).to_bytes(4, "big")


class BridgeEncoder:
    """Frame encoder that numbers frames per chip select (for bridge firmware models and simulators)."""

    def __init__(self) -> None:
        self._seq: dict[tuple[int, int], int] = {}

    def encode(self, chip_select: int, payload: bytes, t_us: int = 0,
               kind: BridgeFrameType = BridgeFrameType.SAMPLE) -> bytes:
        """Wire bytes of the next frame of ``chip_select``."""
        key = (int(kind), int(chip_select))
        seq = self._seq.get(key, 0)
        self._seq[key] = (seq + 1) & 0xFFFF
        return encode_bridge_frame(BridgeFrame(BridgeFrameType(kind), int(chip_select), seq, int(t_us),
                                               bytes(payload)))


def _parse_header(header: bytes) -> int | None:
    kind, cs, _seq, _t, length = _HEADER.unpack(header)
    if kind not in (1, 2) or cs >= MAX_SENSORS or length > MAX_PAYLOAD:
        return None
    return length


def _build(header: bytes, payload: bytes) -> BridgeFrame:
    kind, cs, seq, t_us, _length = _HEADER.unpack(header)
    return BridgeFrame(BridgeFrameType(kind), cs, seq, t_us, payload)


def _sequence_of(frame: BridgeFrame) -> tuple[tuple[int, int], int]:
    return (int(frame.kind), frame.chip_select), frame.sequence


class BridgeDecoder(StreamDecoder[BridgeFrame]):
    """Streaming decoder of the bridge framing.

    ``feed(data) -> list[BridgeFrame]`` accepts bytes in any pieces; frames
    come out whole, CRC-checked, with duplicates dropped.  ``stats`` holds
    the counters (:class:`~.framing.StreamStats`); ``finish()`` counts a
    partial frame left at the end of the stream as truncated.
    """

    stats: StreamStats

    def __init__(self, duplicate_window: int = 64) -> None:
        super().__init__(SYNC, HEADER_SIZE, _parse_header, _build, _sequence_of,
                         SequenceTracker(65536, duplicate_window))
