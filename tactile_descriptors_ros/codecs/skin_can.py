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
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, fields
from types import ModuleType

import can
import numpy as np

from ..core import fast
from ..errors import CodecError
from .can_frames import CAN_FRAME_DTYPE, FLAG_ERROR, FLAG_EXTENDED, FLAG_REMOTE, empty_frames
from .framing import SequenceEvent, SequenceTracker
from .skin import (
    NO_STAMP,
    NOMINAL_RATE_HZ,
    PAYLOAD_SIZE,
    PAYLOAD_SIZE_BY_NUMBER,
    Modality,
    SkinSample,
    SkinSampleBatch,
    check_batch_ids,
    pack_values,
    pack_values_batch,
    unpack_values,
    unpack_values_batch,
)

__all__ = [
    "PROTOCOL_TAG",
    "arbitration_id",
    "split_arbitration_id",
    "encode_can_message",
    "encode_can_frames",
    "SkinCanEncoder",
    "SkinCanStats",
    "SkinCanDecoder",
    "load_compiled",
    "COMPILED_DECODE",
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


def encode_can_frames(samples: SkinSampleBatch, corrupt: np.ndarray | None = None) -> np.ndarray:
    """CAN frames of many samples at once (:data:`~.can_frames.CAN_FRAME_DTYPE`), row ``i`` equal to
    :func:`encode_can_message` of sample ``i``.

    Parameters
    ----------
    samples : SkinSampleBatch
        ``stamp_ns`` :data:`~.skin.NO_STAMP` gives timestamp 0.0, as ``stamp_ns=None`` does.
    corrupt : array of bool, optional
        Frames that lose their last data byte on the way (the simulator's
        ``corrupt_frames`` on CAN: a DLC that does not fit the modality).

    Raises
    ------
    CodecError
        A cell id, sequence number or value out of range, or an unknown modality.
    """
    n = len(samples)
    out = empty_frames(n)
    if not n:
        return out
    cell, mod, seq = samples.cell_id, samples.modality, samples.sequence
    check_batch_ids(samples)
    payload = pack_values_batch(mod, samples.values)
    out["arbitration_id"] = (PROTOCOL_TAG << 20) | (mod << 16) | cell
    out["flags"] = FLAG_EXTENDED
    out["data"][:, 0] = seq
    out["data"][:, 1:6] = payload
    dlc = 1 + PAYLOAD_SIZE_BY_NUMBER[mod]
    if corrupt is not None:
        bad = np.asarray(corrupt, dtype=bool)
        dlc = dlc - bad
        out["data"][np.flatnonzero(bad), dlc[bad]] = 0
    out["dlc"] = dlc
    stamp = samples.stamp_ns
    out["timestamp"] = np.where(stamp == NO_STAMP, 0.0, stamp * 1e-9)
    return out


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
    rates_hz : mapping of Modality to float, optional
        Sample rate per modality (default :data:`~.skin.NOMINAL_RATE_HZ`).
        Sequence numbers are unwrapped with the frames' bus times (or the
        arrival time given to :meth:`decode_frames`), so a cell silent for
        longer than half a wrap (128 frames) is a gap of the right length.
    """

    def __init__(self, known_cell_ids: Iterable[int] | None = None, duplicate_window: int = 32,
                 rates_hz: Mapping[Modality, float] | None = None) -> None:
        self.known_cell_ids = None if known_cell_ids is None else frozenset(int(c) for c in known_cell_ids)
        self.tracker = SequenceTracker(256, duplicate_window)
        rates = {**NOMINAL_RATE_HZ, **(rates_hz or {})}
        self._period_ns = np.zeros(16)
        for m, r in rates.items():
            self._period_ns[int(m)] = 1e9 / float(r)
        self.stats = SkinCanStats()
        self._known_table: tuple[frozenset[int] | None, np.ndarray] | None = None  # (its source, the table)

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
        t = int(round(msg.timestamp * 1e9)) if msg.timestamp else None
        event = self.tracker.update((cell, int(modality)), data[0], t, self._period_ns[int(modality)])
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

    def decode_frames(self, frames: np.ndarray, arrival_ns: int | None = None) -> SkinSampleBatch:
        """Decode a batch of frames (:data:`~.can_frames.CAN_FRAME_DTYPE`) at once.

        The result and every counter are exactly those of :meth:`decode` on
        the frames one by one, in order (a property test checks this on
        random valid and damaged streams); the two can be mixed on one decoder.
        ``arrival_ns`` (the host time of the read, in the clock of the bus
        time stamps) times the frames for unwrapping when none of them has a
        bus time (an adapter that does not stamp).
        """
        if frames.dtype != CAN_FRAME_DTYPE:
            raise CodecError(f"decode_frames needs a CAN_FRAME_DTYPE array, got dtype {frames.dtype}")
        st = self.stats
        n = int(frames.size)
        st.frames += n
        if not n:
            return SkinSampleBatch.empty()
        kernel = _codec_kernel()
        # one compiled variant (strided, writeable field arrays): a single frame's fields are contiguous and a
        # read-only buffer's are read-only, each another variant compiled while the driver runs; numpy serves them
        if kernel is not None and frames.ndim == 1 and n >= 2 and frames.flags.writeable:
            return self._decode_compiled(kernel, frames, arrival_ns)
        flags = frames["flags"]
        arb = frames["arbitration_id"].astype(np.int64)
        dlc = frames["dlc"].astype(np.int64)
        data = frames["data"]
        rem_err = (flags & (FLAG_REMOTE | FLAG_ERROR)) != 0
        tag = (arb >> 20) & 0x1FF
        mod = (arb >> 16) & 0xF
        cell = arb & 0xFFFF
        foreign = ~rem_err & (((flags & FLAG_EXTENDED) == 0) | (tag != PROTOCOL_TAG))
        ours = ~rem_err & ~foreign
        known_mod = (mod >= 1) & (mod <= 4)
        unknown_mod = ours & ~known_mod
        ours &= known_mod
        want = 1 + PAYLOAD_SIZE_BY_NUMBER[mod]
        bad_len = ours & (dlc != want)
        ours &= ~bad_len
        st.remote_or_error_frames += int(rem_err.sum())
        st.foreign_frames += int(foreign.sum())
        st.unknown_modality += int(unknown_mod.sum())
        st.bad_length += int(bad_len.sum())
        if self.known_cell_ids is not None:
            known = np.isin(cell, np.fromiter(self.known_cell_ids, dtype=np.int64, count=len(self.known_cell_ids)))
            unknown = ours & ~known
            if unknown.any():
                st.unknown_cells += int(unknown.sum())
                ids, counts = np.unique(cell[unknown], return_counts=True)
                for c, k in zip(ids.tolist(), counts.tolist()):
                    st.unknown_cell_ids[c] += k
            ours &= known
        idx = np.flatnonzero(ours)
        values, ok = unpack_values_batch(mod[idx], data[idx, 1:6])
        st.bad_payload += int((~ok).sum())
        idx, values = idx[ok], values[ok]
        seq = data[idx, 0].astype(np.int64)
        code = (cell[idx] << 4) | mod[idx]
        ts = frames["timestamp"][idx]
        # the arrival time stands in only on a bus that gives no times at all (one clock per key)
        stand_in = -1 if arrival_ns is None or (ts != 0.0).any() else int(arrival_ns)
        t = np.rint(ts * 1e9).astype(np.int64)
        t[ts == 0.0] = stand_in  # exact: through a float64 array, a host time in ns (~1.8e18) lost its last 8 bits
        events = self.tracker.update_many(code, seq, _key_of_code, t, self._period_ns[mod[idx]])
        st.sequence_gaps = self.tracker.gaps
        st.lost_frames = self.tracker.lost
        st.sequence_resets = self.tracker.resets
        dup = events == SequenceEvent.DUPLICATE
        st.duplicates += int(dup.sum())
        st.out_of_order += int((events == SequenceEvent.LATE).sum())
        keep = ~dup
        idx, values, seq = idx[keep], values[keep], seq[keep]
        st.samples += int(idx.size)
        ts = frames["timestamp"][idx]
        stamp = np.rint(ts * 1e9).astype(np.int64)
        stamp[ts == 0.0] = NO_STAMP
        return SkinSampleBatch(cell[idx], mod[idx], seq, values, stamp)

    def _decode_compiled(self, kernel: ModuleType, frames: np.ndarray, arrival_ns: int | None) -> SkinSampleBatch:
        """:meth:`decode_frames` with the checks and unpacking in one compiled pass
        (:func:`~..core.numba_kernel.decode_can_rows`); the sequence numbers go through the same tracker."""
        st = self.stats
        n = int(frames.size)
        if self._known_table is None or self._known_table[0] is not self.known_cell_ids:
            table = np.ones(_CELL_IDS, dtype=bool)
            if self.known_cell_ids is not None:
                table[:] = False
                ids = np.fromiter(self.known_cell_ids, dtype=np.int64, count=len(self.known_cell_ids))
                table[ids[(ids >= 0) & (ids < _CELL_IDS)]] = True
            self._known_table = (self.known_cell_ids, table)
        status = np.empty(n, dtype=np.int8)
        values = np.empty((n, 3), dtype=np.int64)
        seq, code, t, stamp = (np.empty(n, dtype=np.int64) for _ in range(4))
        period = np.empty(n)
        k, any_stamped = kernel.decode_can_rows(
            frames["flags"], frames["arbitration_id"], frames["dlc"], frames["data"], frames["timestamp"],
            self._known_table[1], FLAG_REMOTE | FLAG_ERROR, FLAG_EXTENDED, PROTOCOL_TAG, PAYLOAD_SIZE_BY_NUMBER,
            self._period_ns, status, values, seq, code, t, period, stamp)
        verdicts = np.bincount(status, minlength=kernel.CAN_BAD_PAYLOAD + 1).tolist()
        st.remote_or_error_frames += verdicts[kernel.CAN_REMOTE_OR_ERROR]
        st.foreign_frames += verdicts[kernel.CAN_FOREIGN]
        st.unknown_modality += verdicts[kernel.CAN_UNKNOWN_MODALITY]
        st.bad_length += verdicts[kernel.CAN_BAD_LENGTH]
        if verdicts[kernel.CAN_UNKNOWN_CELL]:
            st.unknown_cells += verdicts[kernel.CAN_UNKNOWN_CELL]
            cells = frames["arbitration_id"][status == kernel.CAN_UNKNOWN_CELL].astype(np.int64) & 0xFFFF
            ids, counts = np.unique(cells, return_counts=True)
            for c, m in zip(ids.tolist(), counts.tolist()):
                st.unknown_cell_ids[c] += m
        st.bad_payload += verdicts[kernel.CAN_BAD_PAYLOAD]
        values, seq, code, t, stamp, period = values[:k], seq[:k], code[:k], t[:k], stamp[:k], period[:k]
        if arrival_ns is not None and not any_stamped:  # one clock per key: the arrival time for all, or none
            t[:] = int(arrival_ns)
        events = self.tracker.update_many(code, seq, _key_of_code, t, period)
        st.sequence_gaps = self.tracker.gaps
        st.lost_frames = self.tracker.lost
        st.sequence_resets = self.tracker.resets
        dup = events == SequenceEvent.DUPLICATE
        n_dup = int(dup.sum())
        st.duplicates += n_dup
        st.out_of_order += int((events == SequenceEvent.LATE).sum())
        if n_dup:
            keep = ~dup
            values, seq, code, stamp = values[keep], seq[keep], code[keep], stamp[keep]
        st.samples += int(code.size)
        return SkinSampleBatch(code >> 4, code & 0xF, seq, values, stamp)

    def decode_many(self, messages: Iterable[can.Message]) -> list[SkinSample]:
        """Samples of many frames, in arrival order (rejected frames counted, left out)."""
        out = []
        for m in messages:
            s = self.decode(m)
            if s is not None:
                out.append(s)
        return out


#: Whether :meth:`SkinCanDecoder.decode_frames` may use the compiled backend when it is loaded (the tests switch
#: it off to compare both paths).
COMPILED_DECODE = True
#: Cell ids an arbitration id can carry (its low 16 bits).
_CELL_IDS = 0x10000


def load_compiled() -> bool:
    """Load the compiled decoding and sequence tracking now (about 0.3 s from the on-disk cache ``make setup``
    fills) rather than on a decoder's first read, whose frames would queue meanwhile: a driver calls this before
    it opens its bus.  Returns whether they serve (False where numpy does)."""
    kernel = _codec_kernel()
    if kernel is None:
        return False
    fast.warm_up_codecs(kernel)
    return True


def _codec_kernel() -> ModuleType | None:
    """The compiled backend's module when the decoder may use it (:data:`COMPILED_DECODE`), else None."""
    return fast.kernel_module() if COMPILED_DECODE else None


def _key_of_code(code: int) -> tuple[int, int]:
    """The sequence-tracker key ``(cell, modality)`` of ``cell << 4 | modality``."""
    return code >> 4, code & 0xF
