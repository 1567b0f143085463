"""CAN frame layout for skin cells (our definition, in the spirit of the iCub skin CAN protocol).

Extended (29-bit) arbitration id::

    bits 28..20   protocol tag 0x15A (9 bits): frames without it are foreign traffic
    bits 19..16   modality: 1 accelerometer, 2 force, 3 proximity, 4 temperature
    bits 15..0    cell id (0..65535)

Lower ids win arbitration, so accelerometer frames (the 1 kHz stream) have
priority over force, proximity and temperature, and lower cell ids over
higher ones within a modality.

Data bytes: byte 0 is the sequence number (0..255, per cell and modality,
wrapping), bytes 1.. the payload of :mod:`.skin` (DLC 5 accelerometer,
6 force, 3 proximity, 3 temperature).

The CAN controller's own CRC-15 protects every frame that reaches us, so
this layout carries no checksum; what the decoder must catch are faults
above the bit level: lost, repeated and reordered frames, foreign frames,
wrong lengths, unknown modalities, and cells that are not configured.

:class:`SkinCanDecoder` turns :class:`can.Message` objects into
:class:`~.skin.SkinSample` objects and counts every rejected frame
(:class:`SkinCanStats`).  Unknown cells: with ``known_cell_ids`` given, frames
of other cells are not returned and are counted per id in
``stats.unknown_cell_ids`` (the driver reports them in diagnostics); without
it every well-formed frame is returned with its ``cell_id`` and the driver
decides.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field, fields

import can

from ..errors import CodecError
from .framing import SequenceEvent, SequenceTracker
from .skin import PAYLOAD_SIZE, Modality, SkinSample, pack_values, unpack_values

__all__ = [
    "PROTOCOL_TAG",
    "arbitration_id",
    "split_arbitration_id",
    "encode_can_message",
    "SkinCanEncoder",
    "SkinCanStats",
    "SkinCanDecoder",
]

_MODALITIES: dict[int, Modality] = {int(m): m for m in Modality}
#: 9-bit tag in bits 28..20 of our arbitration ids.
PROTOCOL_TAG = 0x15A


def arbitration_id(cell_id: int, modality: Modality) -> int:
    """29-bit arbitration id of a cell's frames of one modality."""
    if not 0 <= int(cell_id) <= 0xFFFF:
        raise CodecError(f"cell id must be 0..65535, got {cell_id}")
    return (PROTOCOL_TAG << 20) | (int(Modality(modality)) << 16) | int(cell_id)


def split_arbitration_id(arb_id: int) -> tuple[int, int, int]:
    """``(tag, modality_number, cell_id)`` of an arbitration id."""
    return (arb_id >> 20) & 0x1FF, (arb_id >> 16) & 0xF, arb_id & 0xFFFF


def encode_can_message(sample: SkinSample) -> can.Message:
    """The CAN frame of one sample (timestamp from ``stamp_ns`` when given)."""
    if not 0 <= int(sample.sequence) <= 255:
        raise CodecError(f"sequence must be 0..255, got {sample.sequence}")
    data = bytes([int(sample.sequence)]) + pack_values(sample.modality, sample.values)
    ts = 0.0 if sample.stamp_ns is None else sample.stamp_ns * 1e-9
    return can.Message(arbitration_id=arbitration_id(sample.cell_id, sample.modality),
                       is_extended_id=True, data=data, timestamp=ts)


class SkinCanEncoder:
    """Encoder that numbers frames per (cell, modality), as a cell's firmware does."""

    def __init__(self) -> None:
        self._seq: dict[tuple[int, int], int] = {}

    def next_sample(self, cell_id: int, modality: Modality, values: Iterable[int],
                    stamp_ns: int | None = None) -> SkinSample:
        """The next :class:`SkinSample` of a cell and modality (sequence assigned)."""
        key = (int(cell_id), int(Modality(modality)))
        seq = self._seq.get(key, 0)
        self._seq[key] = (seq + 1) & 0xFF
        return SkinSample(int(cell_id), Modality(modality), seq, tuple(int(v) for v in values), stamp_ns)

    def encode(self, cell_id: int, modality: Modality, values: Iterable[int],
               stamp_ns: int | None = None) -> can.Message:
        """CAN frame of the next sample of a cell and modality."""
        return encode_can_message(self.next_sample(cell_id, modality, values, stamp_ns))


@dataclass
class SkinCanStats:
    """Counters of :class:`SkinCanDecoder`.

    Attributes
    ----------
    frames : int
        Frames offered to the decoder.
    samples : int
        Samples returned.
    foreign_frames : int
        Standard-id frames or extended ids without our tag (other devices on the bus).
    remote_or_error_frames : int
        Remote-request and error frames.
    unknown_modality : int
        Our tag with a modality number we do not know.
    bad_length : int
        DLC wrong for the modality.
    bad_payload : int
        Must-be-zero bits set or a reserved value.
    unknown_cells : int
        Frames from cells not in ``known_cell_ids``.
    sequence_gaps, lost_frames, duplicates, out_of_order, sequence_resets : int
        As in :class:`~.framing.StreamStats`; duplicates are dropped.
    unknown_cell_ids : collections.Counter
        Frames per unknown cell id.
    """

    frames: int = 0
    samples: int = 0
    foreign_frames: int = 0
    remote_or_error_frames: int = 0
    unknown_modality: int = 0
    bad_length: int = 0
    bad_payload: int = 0
    unknown_cells: int = 0
    sequence_gaps: int = 0
    lost_frames: int = 0
    duplicates: int = 0
    out_of_order: int = 0
    sequence_resets: int = 0
    unknown_cell_ids: Counter = field(default_factory=Counter)

    def as_dict(self) -> dict[str, int | dict[int, int]]:
        """Counter name -> value (``unknown_cell_ids`` as a plain dict)."""
        out: dict[str, int | dict[int, int]] = {}
        for f in fields(self):
            v = getattr(self, f.name)
            out[f.name] = dict(v) if isinstance(v, Counter) else v
        return out

    @property
    def errors(self) -> int:
        """Rejected frames of every kind (foreign traffic not included)."""
        return (self.remote_or_error_frames + self.unknown_modality + self.bad_length
                + self.bad_payload + self.unknown_cells + self.duplicates)


class SkinCanDecoder:
    """Decode skin-cell CAN frames into samples, counting every rejected frame.

    Parameters
    ----------
    known_cell_ids : iterable of int, optional
        Cells configured on this bus; frames of other cells are counted in
        ``stats.unknown_cell_ids`` and not returned.  ``None`` returns all.
    duplicate_window : int
        Recent sequence numbers remembered per (cell, modality) (< 128).
    """

    def __init__(self, known_cell_ids: Iterable[int] | None = None, duplicate_window: int = 32) -> None:
        self.known_cell_ids = None if known_cell_ids is None else frozenset(int(c) for c in known_cell_ids)
        self.tracker = SequenceTracker(256, duplicate_window)
        self.stats = SkinCanStats()

    def decode(self, msg: can.Message) -> SkinSample | None:
        """The sample in one frame, or ``None`` if the frame was rejected (and counted)."""
        st = self.stats
        st.frames += 1
        if msg.is_error_frame or msg.is_remote_frame:
            st.remote_or_error_frames += 1
            return None
        if not msg.is_extended_id:
            st.foreign_frames += 1
            return None
        tag, mod, cell = split_arbitration_id(int(msg.arbitration_id))
        if tag != PROTOCOL_TAG:
            st.foreign_frames += 1
            return None
        modality = _MODALITIES.get(mod)
        if modality is None:
            st.unknown_modality += 1
            return None
        data = bytes(msg.data)
        if len(data) != 1 + PAYLOAD_SIZE[modality]:
            st.bad_length += 1
            return None
        if self.known_cell_ids is not None and cell not in self.known_cell_ids:
            st.unknown_cells += 1
            st.unknown_cell_ids[cell] += 1
            return None
        try:
            values = unpack_values(modality, data[1:])
        except CodecError:
            st.bad_payload += 1
            return None
        event = self.tracker.update((cell, int(modality)), data[0])
        st.sequence_gaps = self.tracker.gaps
        st.lost_frames = self.tracker.lost
        st.sequence_resets = self.tracker.resets
        if event is SequenceEvent.DUPLICATE:
            st.duplicates += 1
            return None
        if event is SequenceEvent.LATE:
            st.out_of_order += 1
        st.samples += 1
        stamp = None if not msg.timestamp else int(round(msg.timestamp * 1e9))
        return SkinSample(cell, modality, data[0], values, stamp)

    def decode_many(self, messages: Iterable[can.Message]) -> list[SkinSample]:
        """Samples of many frames, in arrival order (rejected frames counted, left out)."""
        out = []
        for m in messages:
            s = self.decode(m)
            if s is not None:
                out.append(s)
        return out
