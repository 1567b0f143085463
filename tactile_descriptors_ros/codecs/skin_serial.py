"""Serial framing for skin-cell samples (our definition).

For skin patches connected by a UART/USB-serial link instead of CAN.  One
sample per frame, big-endian fields::

    offset  size  field
    0       2     sync        0xC3 0x5A
    2       1     length      payload bytes N (see the table in :mod:`.skin`)
    3       1     sequence    0..255 per (cell, modality), wraps
    4       2     cell_id     0..65535
    6       1     modality    1 accel, 2 force, 3 proximity, 4 temperature
    7       N     payload     as in :mod:`.skin` (same bytes as CAN data bytes 1..)
    7+N     4     crc         CRC-32/ISO-HDLC over bytes 2 .. 7+N-1

:class:`SkinSerialDecoder` is a resynchronising streaming decoder
(``feed(bytes) -> list[SkinSample]``) with the counters of
:class:`~.framing.StreamStats`; frames with a good CRC but an unknown
modality or a length that does not fit it are counted in ``bad_payloads``
(by reason in ``reject_reasons``); frames of cells not in ``known_cell_ids``
are counted per id in ``unknown_cell_ids`` and not returned.
"""

from __future__ import annotations

import struct
from collections import Counter
from collections.abc import Iterable, Mapping

import numpy as np

from ..errors import CodecError, FrameError
from .framing import SequenceTracker, StreamDecoder, crc32
from .skin import (
    NOMINAL_RATE_HZ,
    PAYLOAD_SIZE_BY_NUMBER,
    Modality,
    SkinSample,
    SkinSampleBatch,
    check_batch_ids,
    pack_values,
    pack_values_batch,
    unpack_values,
)

__all__ = ["SYNC", "HEADER_SIZE", "MAX_PAYLOAD", "encode_skin_frame", "encode_skin_frames", "crc32_rows",
           "SkinSerialEncoder", "SkinSerialDecoder"]

SYNC = b"\xc3\x5a"
HEADER_SIZE = 5
#: Longest payload accepted by the header check.
MAX_PAYLOAD = 16
_HEADER = struct.Struct(">BBHB")


def encode_skin_frame(sample: SkinSample) -> bytes:
    """Wire bytes of one sample."""
    if not 0 <= int(sample.sequence) <= 255:
        raise CodecError(f"sequence must be 0..255, got {sample.sequence}")
    if not 0 <= int(sample.cell_id) <= 0xFFFF:
        raise CodecError(f"cell id must be 0..65535, got {sample.cell_id}")
    payload = pack_values(sample.modality, sample.values)
    body = _HEADER.pack(len(payload), int(sample.sequence), int(sample.cell_id),
                        int(Modality(sample.modality))) + payload
    return SYNC + body + crc32(body).to_bytes(4, "big")


def _crc_table() -> np.ndarray:
    table = np.arange(256, dtype=np.uint32)
    for _ in range(8):
        table = np.where(table & 1, (table >> 1) ^ np.uint32(0xEDB88320), table >> 1).astype(np.uint32)
    return table


_CRC_TABLE = _crc_table()


def crc32_rows(rows: np.ndarray) -> np.ndarray:
    """CRC-32/ISO-HDLC of every row of a 2-D uint8 array (same as :func:`~.framing.crc32` of each row's bytes).

    Table-driven, one array operation per column, for many short frames of
    equal length at once.
    """
    rows = np.asarray(rows, dtype=np.uint8)
    crc = np.full(rows.shape[0], 0xFFFFFFFF, dtype=np.uint32)
    for k in range(rows.shape[1]):
        crc = _CRC_TABLE[(crc ^ rows[:, k]) & 0xFF] ^ (crc >> 8)
    return crc ^ np.uint32(0xFFFFFFFF)


def encode_skin_frames(samples: SkinSampleBatch, corrupt: np.ndarray | None = None) -> tuple[bytes, np.ndarray]:
    """Wire bytes of many samples at once: the concatenation of :func:`encode_skin_frame` of each.

    Parameters
    ----------
    samples : SkinSampleBatch
    corrupt : array of bool, optional
        Frames garbled on the line after their CRC was computed (the
        simulator's ``corrupt_frames``: the last payload byte XOR 0x5A).

    Returns
    -------
    data : bytes
    offsets : numpy.ndarray of int64, shape (n + 1,)
        Frame ``i`` is ``data[offsets[i]:offsets[i + 1]]``.

    Raises
    ------
    CodecError
        A cell id, sequence number or value out of range, or an unknown modality.
    """
    n = len(samples)
    cell, mod, seq = samples.cell_id, samples.modality, samples.sequence
    check_batch_ids(samples)
    payload = pack_values_batch(mod, samples.values)
    size = PAYLOAD_SIZE_BY_NUMBER[mod] if n else np.zeros(0, dtype=np.int64)
    frame = np.zeros((n, 7 + 5 + 4), dtype=np.uint8)
    frame[:, 0], frame[:, 1] = SYNC[0], SYNC[1]
    frame[:, 2] = size
    frame[:, 3] = seq
    frame[:, 4] = cell >> 8
    frame[:, 5] = cell & 0xFF
    frame[:, 6] = mod
    frame[:, 7:12] = payload
    rows = np.arange(n)
    for length in np.unique(size).tolist():
        sel = rows[size == length]
        crc = crc32_rows(frame[sel, 2:7 + length])
        for k in range(4):
            frame[sel, 7 + length + k] = (crc >> (24 - 8 * k)) & 0xFF
    if corrupt is not None:
        bad = rows[np.asarray(corrupt, dtype=bool)]
        frame[bad, 6 + size[bad]] ^= 0x5A
    total = 11 + size
    keep = np.arange(frame.shape[1])[None, :] < total[:, None]
    offsets = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(total, out=offsets[1:])
    return frame[keep].tobytes(), offsets


class SkinSerialEncoder:
    """Encoder numbering frames per (cell, modality)."""

    def __init__(self) -> None:
        self._seq: dict[tuple[int, int], int] = {}

    def encode(self, cell_id: int, modality: Modality, values: Iterable[int]) -> bytes:
        """Wire bytes of the next sample of a cell and modality."""
        key = (int(cell_id), int(Modality(modality)))
        seq = self._seq.get(key, 0)
        self._seq[key] = (seq + 1) & 0xFF
        return encode_skin_frame(SkinSample(int(cell_id), Modality(modality), seq,
                                            tuple(int(v) for v in values)))


def _parse_header(header: bytes) -> int | None:
    length = header[0]
    return length if length <= MAX_PAYLOAD else None


class _UnknownCell(CodecError):
    def __init__(self, cell: int) -> None:
        self.cell = cell
        super().__init__(f"unknown cell {cell}")


class _UnknownModality(CodecError):
    pass


class SkinSerialDecoder(StreamDecoder[SkinSample]):
    """Streaming decoder of the skin serial framing.

    Parameters
    ----------
    known_cell_ids : iterable of int, optional
        Configured cells; others are counted in ``unknown_cell_ids`` and dropped.
    duplicate_window : int
        Recent sequence numbers remembered per (cell, modality) (< 128).
    rates_hz : mapping of Modality to float, optional
        Sample rate per modality (default :data:`~.skin.NOMINAL_RATE_HZ`):
        with the arrival times given to :meth:`feed`, a cell silent for
        longer than half a wrap (128 frames) is a gap of the right length.

    Attributes
    ----------
    stats : StreamStats
    reject_reasons : collections.Counter
        ``bad_payloads`` broken down: ``"unknown_modality"``, ``"bad_length"``,
        ``"bad_payload"``, ``"unknown_cell"``.
    unknown_cell_ids : collections.Counter
        Frames per unknown cell id.
    """

    def __init__(self, known_cell_ids: Iterable[int] | None = None, duplicate_window: int = 32,
                 rates_hz: Mapping[Modality, float] | None = None) -> None:
        self.known_cell_ids = None if known_cell_ids is None else frozenset(int(c) for c in known_cell_ids)
        self.reject_reasons: Counter = Counter()
        self.unknown_cell_ids: Counter = Counter()
        rates = {**NOMINAL_RATE_HZ, **(rates_hz or {})}
        periods_ns = {int(m): 1e9 / float(r) for m, r in rates.items()}
        super().__init__(SYNC, HEADER_SIZE, _parse_header, self._build_sample,
                         lambda s: ((s.cell_id, int(s.modality)), s.sequence),
                         SequenceTracker(256, duplicate_window), lambda s: periods_ns[int(s.modality)])

    def _build_sample(self, header: bytes, payload: bytes) -> SkinSample:
        _length, seq, cell, mod = _HEADER.unpack(header)
        try:
            modality = Modality(mod)
        except ValueError:
            raise _UnknownModality(f"unknown skin modality {mod}") from None
        values = unpack_values(modality, payload)
        if self.known_cell_ids is not None and cell not in self.known_cell_ids:
            raise _UnknownCell(cell)
        return SkinSample(cell, modality, seq, values)

    def feed_batch(self, data: bytes | bytearray | memoryview, t_ns: int | None = None) -> SkinSampleBatch:
        """:meth:`feed` returning the samples as one :class:`~.skin.SkinSampleBatch`."""
        return SkinSampleBatch.from_samples(self.feed(data, t_ns))

    def _on_bad_payload(self, exc: CodecError) -> None:
        if isinstance(exc, _UnknownCell):
            self.reject_reasons["unknown_cell"] += 1
            self.unknown_cell_ids[exc.cell] += 1
        elif isinstance(exc, FrameError):
            self.reject_reasons["bad_length"] += 1
        elif isinstance(exc, _UnknownModality):
            self.reject_reasons["unknown_modality"] += 1
        else:
            self.reject_reasons["bad_payload"] += 1
