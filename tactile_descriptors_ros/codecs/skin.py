"""Skin-cell samples and their payload encoding, shared by the CAN and serial framings.

A skin cell (TUM Cellular skin / HEX-o-SKIN style) has a
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

import numpy as np

from ..errors import CodecError, FrameError

__all__ = [
    "check_batch_ids",
    "Modality",
    "PAYLOAD_SIZE",
    "PAYLOAD_SIZE_BY_NUMBER",
    "VALUE_COUNT",
    "NOMINAL_RATE_HZ",
    "ACCEL_MPS2_PER_COUNT",
    "FORCE_N_PER_COUNT",
    "TEMPERATURE_C_PER_COUNT",
    "SkinSample",
    "SkinSampleBatch",
    "NO_STAMP",
    "pack_values",
    "unpack_values",
    "validate_values",
    "pack_values_batch",
    "unpack_values_batch",
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


#: ``SkinSampleBatch.stamp_ns`` of a sample without a bus time stamp (``SkinSample.stamp_ns is None``).
NO_STAMP: int = int(np.iinfo(np.int64).min)

#: :data:`PAYLOAD_SIZE` indexed by modality number (0..15; 0 where no modality has that number).
PAYLOAD_SIZE_BY_NUMBER = np.zeros(16, dtype=np.int64)
_COUNT_BY_NUMBER = np.zeros(16, dtype=np.int64)
for _m in Modality:
    PAYLOAD_SIZE_BY_NUMBER[int(_m)] = PAYLOAD_SIZE[_m]
    _COUNT_BY_NUMBER[int(_m)] = VALUE_COUNT[_m]


@dataclass(frozen=True)
class SkinSampleBatch:
    """Many skin samples as arrays (what the batch decoders return), in arrival order.

    Attributes
    ----------
    cell_id, modality, sequence : numpy.ndarray of int64, shape (n,)
    values : numpy.ndarray of int64, shape (n, 3)
        Counts; a one-value modality (proximity, temperature) uses column 0
        and has zeros in columns 1 and 2.
    stamp_ns : numpy.ndarray of int64, shape (n,)
        Bus time stamps [ns]; :data:`NO_STAMP` where the bus gave none.
    """

    cell_id: np.ndarray
    modality: np.ndarray
    sequence: np.ndarray
    values: np.ndarray
    stamp_ns: np.ndarray

    def __len__(self) -> int:
        return int(self.cell_id.size)

    @classmethod
    def empty(cls) -> SkinSampleBatch:
        """A batch of no samples."""
        z = np.zeros(0, dtype=np.int64)
        return cls(z, z.copy(), z.copy(), np.zeros((0, 3), dtype=np.int64), z.copy())

    @classmethod
    def from_samples(cls, samples: list[SkinSample]) -> SkinSampleBatch:
        """Batch of :class:`SkinSample` objects (``stamp_ns=None`` becomes :data:`NO_STAMP`)."""
        if not samples:
            return cls.empty()
        vals = np.zeros((len(samples), 3), dtype=np.int64)
        for i, s in enumerate(samples):
            vals[i, :len(s.values)] = s.values
        return cls(np.array([s.cell_id for s in samples], dtype=np.int64),
                   np.array([int(s.modality) for s in samples], dtype=np.int64),
                   np.array([s.sequence for s in samples], dtype=np.int64), vals,
                   np.array([NO_STAMP if s.stamp_ns is None else s.stamp_ns for s in samples], dtype=np.int64))

    @classmethod
    def concat(cls, parts: list[SkinSampleBatch]) -> SkinSampleBatch:
        """The samples of several batches, in order."""
        parts = [p for p in parts if len(p)]
        if not parts:
            return cls.empty()
        if len(parts) == 1:
            return parts[0]
        return cls(*(np.concatenate([getattr(p, f) for p in parts])
                     for f in ("cell_id", "modality", "sequence", "values", "stamp_ns")))

    def take(self, index: np.ndarray) -> SkinSampleBatch:
        """The samples at ``index`` (a boolean mask or integer positions)."""
        return SkinSampleBatch(self.cell_id[index], self.modality[index], self.sequence[index],
                               self.values[index], self.stamp_ns[index])

    def to_samples(self) -> list[SkinSample]:
        """The same samples as :class:`SkinSample` objects (for tests and small batches)."""
        counts = _COUNT_BY_NUMBER[self.modality].tolist()
        return [SkinSample(c, Modality(m), q, tuple(v[:k]), None if t == NO_STAMP else t)
                for c, m, q, v, k, t in zip(self.cell_id.tolist(), self.modality.tolist(), self.sequence.tolist(),
                                            self.values.tolist(), counts, self.stamp_ns.tolist())]


def check_batch_ids(samples: SkinSampleBatch) -> None:
    """Refuse a batch whose sequence numbers or cell ids do not fit the wire formats (8 and 16 bits).

    Raises
    ------
    CodecError
        Naming the first value out of range.
    """
    cell, seq = samples.cell_id, samples.sequence
    if ((seq < 0) | (seq > 255)).any():
        raise CodecError(f"sequence must be 0..255, got {int(seq[(seq < 0) | (seq > 255)][0])}")
    if ((cell < 0) | (cell > 0xFFFF)).any():
        raise CodecError(f"cell id must be 0..65535, got {int(cell[(cell < 0) | (cell > 0xFFFF)][0])}")


def pack_values_batch(modality: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Payload bytes of many samples at once, as :func:`pack_values` makes them one by one.

    Parameters
    ----------
    modality : array of int, shape (n,)
        Modality numbers (all known).
    values : array of int, shape (n, 3)
        Counts; columns beyond a modality's value count are ignored.

    Returns
    -------
    numpy.ndarray of uint8, shape (n, 5)
        Row ``i`` holds the ``PAYLOAD_SIZE`` bytes of sample ``i`` followed by zeros.

    Raises
    ------
    CodecError
        An unknown modality or a value outside its modality's range.
    """
    mod = np.asarray(modality, dtype=np.int64)
    vals = np.asarray(values, dtype=np.int64).reshape(mod.size, 3)
    known = (mod >= 1) & (mod <= 4)
    if not known.all():
        raise CodecError(f"unknown skin modality {int(mod[~known][0])}")
    word = np.zeros(mod.size, dtype=np.int64)
    for m in Modality:
        sel = mod == int(m)
        if not sel.any():
            continue
        v = vals[sel, :VALUE_COUNT[m]]
        lo, hi = _RANGES[m]
        bad = (v < lo) | (v > hi)
        if bad.any():
            raise CodecError(f"{m.name} value {int(v[bad][0])} outside {lo}..{hi}")
        if m is Modality.ACCEL:
            u = v & 0x3FF
            word[sel] = (u[:, 0] << 20) | (u[:, 1] << 10) | u[:, 2]
        elif m is Modality.FORCE:
            word[sel] = (v[:, 0] << 28) | (v[:, 1] << 16) | (v[:, 2] << 4)
        else:
            word[sel] = v[:, 0] & 0xFFFF
    size = PAYLOAD_SIZE_BY_NUMBER[mod]
    out = np.zeros((mod.size, 5), dtype=np.uint8)
    for k in range(5):
        shift = 8 * (size - 1 - k)
        inside = shift >= 0
        out[:, k] = np.where(inside, (word >> np.maximum(shift, 0)) & 0xFF, 0)
    return out


def unpack_values_batch(modality: np.ndarray, payload: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Values of many payloads at once, validated as :func:`unpack_values` validates one.

    Parameters
    ----------
    modality : array of int, shape (n,)
        Known modality numbers (1..4; lengths must already be checked).
    payload : array of uint8, shape (n, >= 5)
        Payload bytes, left aligned (``PAYLOAD_SIZE`` bytes used per row).

    Returns
    -------
    values : numpy.ndarray of int64, shape (n, 3)
    ok : numpy.ndarray of bool, shape (n,)
        False where :func:`unpack_values` raises :class:`CodecError`
        (must-be-zero bits set, a reserved value).
    """
    mod = np.asarray(modality, dtype=np.int64)
    pay = np.asarray(payload, dtype=np.int64)[:, :5]
    size = PAYLOAD_SIZE_BY_NUMBER[mod]
    word = np.zeros(mod.size, dtype=np.int64)
    for k in range(5):
        shift = 8 * (size - 1 - k)
        word |= np.where(shift >= 0, pay[:, k] << np.maximum(shift, 0), 0)
    vals = np.zeros((mod.size, 3), dtype=np.int64)
    ok = np.ones(mod.size, dtype=bool)
    acc = mod == int(Modality.ACCEL)
    if acc.any():
        w = word[acc]
        v = np.stack([(w >> 20) & 0x3FF, (w >> 10) & 0x3FF, w & 0x3FF], axis=1)
        vals[acc] = np.where(v & 0x200, v - 1024, v)
        ok[acc] = (w >> 30) == 0
    frc = mod == int(Modality.FORCE)
    if frc.any():
        w = word[frc]
        vals[frc] = np.stack([(w >> 28) & 0xFFF, (w >> 16) & 0xFFF, (w >> 4) & 0xFFF], axis=1)
        ok[frc] = (w & 0xF) == 0
    prx = mod == int(Modality.PROXIMITY)
    if prx.any():
        w = word[prx]
        vals[prx, 0] = w
        ok[prx] = w != 0xFFFF
    tmp = mod == int(Modality.TEMPERATURE)
    if tmp.any():
        w = word[tmp]
        v = np.where(w & 0x8000, w - 0x10000, w)
        vals[tmp, 0] = v
        ok[tmp] = v != -32768
    return vals, ok
