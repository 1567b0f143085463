"""Skin-cell samples and their payload encoding, shared by the CAN and serial framings.

A skin cell (TUM Cellular skin / HEX-o-SKIN style, SPEC section 3) has a
3-axis accelerometer (1 kHz, +-2 g, 10-bit signed), three normal-force
sensors (250 Hz, 0..10 N, 12-bit), a proximity sensor (250 Hz) and a
temperature sensor.  Each modality travels in its own frame with a
sequence number per (cell, modality), so lost and repeated frames are seen.

Payload bytes after the sequence number (big-endian):

=============  =====  ================================================================
modality       bytes  layout
=============  =====  ================================================================
ACCEL (1)      4      32-bit word ``x << 20 | y << 10 | z``, each 10-bit two's
                      complement (-512..511); bits 31..30 must be 0
FORCE (2)      5      40-bit word ``f0 << 28 | f1 << 16 | f2 << 4``, each 12-bit
                      unsigned (0..4095); bits 3..0 must be 0
PROXIMITY (3)  2      unsigned 16-bit count 0..65534 (0xFFFF reserved)
TEMPERATURE(4) 2      signed 16-bit, centi-degrees Celsius (-32768 reserved)
=============  =====  ================================================================
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from ..errors import CodecError, FrameError

__all__ = [
    "Modality",
    "PAYLOAD_SIZE",
    "VALUE_COUNT",
    "NOMINAL_RATE_HZ",
    "ACCEL_MPS2_PER_COUNT",
    "FORCE_N_PER_COUNT",
    "TEMPERATURE_C_PER_COUNT",
    "SkinSample",
    "pack_values",
    "unpack_values",
    "validate_values",
]


class Modality(IntEnum):
    """Frame types, one per modality (the number is on the wire)."""

    ACCEL = 1
    FORCE = 2
    PROXIMITY = 3
    TEMPERATURE = 4


#: Payload bytes after the sequence number, per modality.
PAYLOAD_SIZE: dict[Modality, int] = {Modality.ACCEL: 4, Modality.FORCE: 5,
                                     Modality.PROXIMITY: 2, Modality.TEMPERATURE: 2}
#: Values per sample, per modality.
VALUE_COUNT: dict[Modality, int] = {Modality.ACCEL: 3, Modality.FORCE: 3,
                                    Modality.PROXIMITY: 1, Modality.TEMPERATURE: 1}
#: Usual sample rates (the codec does not depend on them).
NOMINAL_RATE_HZ: dict[Modality, float] = {Modality.ACCEL: 1000.0, Modality.FORCE: 250.0,
                                          Modality.PROXIMITY: 250.0, Modality.TEMPERATURE: 10.0}
#: +-2 g over 10 bits.
ACCEL_MPS2_PER_COUNT: float = 2 * 9.80665 / 512
#: 0..10 N over 12 bits.
FORCE_N_PER_COUNT: float = 10.0 / 4095
#: Temperature is sent in centi-degrees.
TEMPERATURE_C_PER_COUNT: float = 0.01

_MODALITIES: dict[int, Modality] = {int(m): m for m in Modality}
_RANGES: dict[Modality, tuple[int, int]] = {
    Modality.ACCEL: (-512, 511), Modality.FORCE: (0, 4095),
    Modality.PROXIMITY: (0, 0xFFFE), Modality.TEMPERATURE: (-32767, 32767)}


@dataclass(frozen=True, slots=True)
class SkinSample:
    """One sample of one modality of one cell.

    Attributes
    ----------
    cell_id : int
        Unique cell id, 0..65535.
    modality : Modality
    sequence : int
        0..255, per (cell, modality), wraps.
    values : tuple of int
        Counts: (x, y, z) accelerometer, (f0, f1, f2) force, (p,) proximity,
        (centi-degC,) temperature.
    stamp_ns : int or None
        Receive time from the bus [ns], when known.
    """

    cell_id: int
    modality: Modality
    sequence: int
    values: tuple[int, ...]
    stamp_ns: int | None = None


def validate_values(modality: Modality, values: tuple[int, ...] | list[int]) -> tuple[int, ...]:
    """Check a sample's values against its modality's range; return them as a tuple of int.

    Raises
    ------
    CodecError
        Wrong number of values or a value out of range.
    """
    m = Modality(modality)
    vals = tuple(int(v) for v in values)
    if len(vals) != VALUE_COUNT[m]:
        raise CodecError(f"{m.name} needs {VALUE_COUNT[m]} values, got {len(vals)}")
    lo, hi = _RANGES[m]
    for v in vals:
        if not lo <= v <= hi:
            raise CodecError(f"{m.name} value {v} outside {lo}..{hi}")
    return vals


def pack_values(modality: Modality, values: tuple[int, ...] | list[int]) -> bytes:
    """Payload bytes (without the sequence number) of one sample."""
    m = Modality(modality)
    vals = validate_values(m, values)
    if m is Modality.ACCEL:
        x, y, z = (v & 0x3FF for v in vals)
        return ((x << 20) | (y << 10) | z).to_bytes(4, "big")
    if m is Modality.FORCE:
        f0, f1, f2 = vals
        return ((f0 << 28) | (f1 << 16) | (f2 << 4)).to_bytes(5, "big")
    if m is Modality.PROXIMITY:
        return vals[0].to_bytes(2, "big")
    return vals[0].to_bytes(2, "big", signed=True)


def _s10(v: int) -> int:
    return v - 1024 if v & 0x200 else v


def unpack_values(modality: int, data: bytes) -> tuple[int, ...]:
    """Values of one sample from its payload bytes (without the sequence number).

    Raises
    ------
    CodecError
        Unknown modality, or must-be-zero bits set, or a reserved value.
    FrameError
        Payload length wrong for the modality.
    """
    m = _MODALITIES.get(modality)
    if m is None:
        raise CodecError(f"unknown skin modality {modality}")
    if len(data) != PAYLOAD_SIZE[m]:
        raise FrameError(f"{m.name} payload must be {PAYLOAD_SIZE[m]} bytes, got {len(data)}")
    w = int.from_bytes(data, "big")
    if m is Modality.ACCEL:
        if w >> 30:
            raise CodecError("ACCEL payload has its two must-be-zero bits set")
        return (_s10((w >> 20) & 0x3FF), _s10((w >> 10) & 0x3FF), _s10(w & 0x3FF))
    if m is Modality.FORCE:
        if w & 0xF:
            raise CodecError("FORCE payload has its four must-be-zero bits set")
        return ((w >> 28) & 0xFFF, (w >> 16) & 0xFFF, (w >> 4) & 0xFFF)
    if m is Modality.PROXIMITY:
        if w == 0xFFFF:
            raise CodecError("PROXIMITY value 0xFFFF is reserved")
        return (w,)
    v = int.from_bytes(data, "big", signed=True)
    if v == -32768:
        raise CodecError("TEMPERATURE value -32768 is reserved")
    return (v,)
