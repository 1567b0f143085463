"""Shared pieces of our serial framings: CRC, sequence tracking, a resynchronising stream decoder.

Both serial framings (:mod:`.bridge_serial` for BioTac frames and
:mod:`.skin_serial` for skin-cell samples) have the same shape::

    sync (2 bytes) | header | payload | CRC-32 (4 bytes, big-endian)

The CRC is **CRC-32/ISO-HDLC** (the CRC of Ethernet, zlib and PNG:
polynomial 0x04C11DB7 reflected, init and final XOR 0xFFFFFFFF; check value
``crc32(b"123456789") == 0xCBF43926``), computed over everything after the
sync bytes up to the end of the payload.  It is computed by
:func:`zlib.crc32` (C code in the standard library).  We chose it over a
16-bit CRC because after resynchronisation a decoder tries a candidate frame
at every sync-looking position: with 16 bits about one corrupt candidate in
65536 would pass, which a million-input fuzz run shows as wrong values;
with 32 bits it is one in 4.3e9.

:class:`StreamDecoder` finds frames in a byte stream fed in arbitrary pieces:
it scans for the sync, validates the header, waits for the whole frame,
checks the CRC, and on any failure drops *one* byte and scans again, so a
good frame right after damaged bytes is always recovered.

:class:`~.sequence.SequenceTracker` (re-exported here) detects lost,
duplicated and out-of-order frames from wrapping sequence numbers.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable, Hashable
from dataclasses import dataclass, fields
from typing import Generic, TypeVar

from ..errors import CodecError
from .sequence import SequenceEvent, SequenceTracker

__all__ = [
    "CRC_NAME",
    "crc32",
    "SequenceEvent",
    "SequenceTracker",
    "StreamStats",
    "StreamDecoder",
]

#: Name of the CRC used by our serial framings (reveng catalogue name).
CRC_NAME = "CRC-32/ISO-HDLC"


def crc32(data: bytes | bytearray | memoryview) -> int:
    """CRC-32/ISO-HDLC of ``data`` (``crc32(b"123456789") == 0xCBF43926``)."""
    return zlib.crc32(data) & 0xFFFFFFFF


@dataclass
class StreamStats:
    """Counters of a stream decoder; all start at zero and only grow.

    Attributes
    ----------
    bytes_in : int
        Bytes fed.
    frames : int
        Frames delivered.
    garbage_bytes : int
        Bytes skipped while looking for a sync.
    resyncs : int
        Times the decoder lost and searched for the sync.
    bad_headers : int
        Sync found but the header was impossible (unknown type, length too big, ...).
    crc_errors : int
        Whole frames whose CRC did not match.
    truncated : int
        Frames cut short: the next frame's sync came inside them, or the stream ended.
    sequence_gaps : int
        Places where sequence numbers jumped forward.
    lost_frames : int
        Net frames missing by sequence number.
    duplicates : int
        Frames dropped because their sequence number was already delivered.
    out_of_order : int
        Frames delivered late (earlier sequence number than the newest).
    sequence_resets : int
        Times a sender's sequence jumped far back (restart); tracking restarted.
    bad_payloads : int
        Frames with a good CRC whose contents were impossible (e.g. unknown
        modality, wrong payload length for it): counted and dropped.
    """

    bytes_in: int = 0
    frames: int = 0
    garbage_bytes: int = 0
    resyncs: int = 0
    bad_headers: int = 0
    crc_errors: int = 0
    truncated: int = 0
    sequence_gaps: int = 0
    lost_frames: int = 0
    duplicates: int = 0
    out_of_order: int = 0
    sequence_resets: int = 0
    bad_payloads: int = 0

    def as_dict(self) -> dict[str, int]:
        """Counter name -> value."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @property
    def errors(self) -> int:
        """Every detected fault (not counting sequence gaps, which ``lost_frames`` measures)."""
        return self.bad_headers + self.crc_errors + self.truncated + self.duplicates + self.bad_payloads


F = TypeVar("F")


class StreamDecoder(Generic[F]):
    """Resynchronising decoder for ``sync | header | payload | CRC-32`` frames.

    Subclasses give the sync bytes, the header length, a header check
    returning the payload length (or ``None`` for an impossible header), a
    frame builder, and the sequence key/number of a frame.

    Parameters
    ----------
    sync : bytes
        Two or more sync bytes.
    header_size : int
        Bytes after the sync and before the payload.
    parse_header : callable(bytes) -> int or None
        Payload length from the header bytes, ``None`` if impossible.
    build : callable(header: bytes, payload: bytes) -> F
        Frame object from CRC-checked bytes; raises :class:`~..errors.CodecError`
        for impossible contents (counted in ``bad_payloads``, frame dropped).
    sequence_of : callable(F) -> (key, seq)
        Sequence key and number of a frame.
    tracker : SequenceTracker
    period_of : callable(F) -> float, optional
        Nominal period of a frame's key [ns]: with it, the arrival times
        given to :meth:`feed` take part in unwrapping (a silence longer than
        half a wrap is a gap of the right length).
    """

    CRC_SIZE = 4

    def __init__(self, sync: bytes, header_size: int, parse_header: Callable[[bytes], int | None],
                 build: Callable[[bytes, bytes], F], sequence_of: Callable[[F], tuple[Hashable, int]],
                 tracker: SequenceTracker, period_of: Callable[[F], float] | None = None) -> None:
        self.sync = bytes(sync)
        self.header_size = int(header_size)
        self._parse_header = parse_header
        self._build = build
        self._sequence_of = sequence_of
        self.tracker = tracker
        self._period_of = period_of
        self.stats = StreamStats()
        self._buf = bytearray()
        self._in_sync = True

    @property
    def pending_bytes(self) -> int:
        """Bytes held back waiting for the rest of a frame."""
        return len(self._buf)

    def _lose_sync(self) -> None:
        if self._in_sync:
            self.stats.resyncs += 1
            self._in_sync = False

    def _skip(self, n: int) -> None:
        del self._buf[:n]
        self.stats.garbage_bytes += n

    def feed(self, data: bytes | bytearray | memoryview, t_ns: int | None = None) -> list[F]:
        """Add bytes (received at host time ``t_ns``, optional); return the frames completed by them."""
        self._buf += data
        self.stats.bytes_in += len(data)
        out: list[F] = []
        buf = self._buf
        sync = self.sync
        ns, nh, nc = len(sync), self.header_size, self.CRC_SIZE
        while True:
            pos = buf.find(sync)
            if pos < 0:
                # keep a possible partial sync at the end
                keep = 0
                for k in range(ns - 1, 0, -1):
                    if buf.endswith(sync[:k]):
                        keep = k
                        break
                drop = len(buf) - keep
                if drop:
                    self._lose_sync()
                    self._skip(drop)
                break
            if pos:
                self._lose_sync()
                self._skip(pos)
            if len(buf) < ns + nh:
                break
            header = bytes(buf[ns: ns + nh])
            length = self._parse_header(header)
            if length is None:
                self.stats.bad_headers += 1
                self._lose_sync()
                self._skip(1)
                continue
            total = ns + nh + length + nc
            if len(buf) < total:
                break
            body_end = ns + nh + length
            crc = int.from_bytes(buf[body_end:total], "big")
            if zlib.crc32(memoryview(buf)[ns:body_end]) & 0xFFFFFFFF != crc:
                if buf.find(sync, 1, total) > 0:
                    self.stats.truncated += 1
                else:
                    self.stats.crc_errors += 1
                self._lose_sync()
                self._skip(1)
                continue
            payload = bytes(buf[ns + nh: body_end])
            del buf[:total]
            self._in_sync = True
            try:
                frame = self._build(header, payload)
            except CodecError as exc:
                self.stats.bad_payloads += 1
                self._on_bad_payload(exc)
                continue
            key, seq = self._sequence_of(frame)
            if t_ns is None or self._period_of is None:
                event = self.tracker.update(key, seq)
            else:
                event = self.tracker.update(key, seq, t_ns, self._period_of(frame))
            if event is SequenceEvent.DUPLICATE:
                self.stats.duplicates += 1
                continue
            if event is SequenceEvent.LATE:
                self.stats.out_of_order += 1
            self.stats.frames += 1
            out.append(frame)
        self._sync_tracker_stats()
        return out

    def _sync_tracker_stats(self) -> None:
        self.stats.sequence_gaps = self.tracker.gaps
        self.stats.lost_frames = self.tracker.lost
        self.stats.sequence_resets = self.tracker.resets

    def _on_bad_payload(self, exc: CodecError) -> None:
        """Hook for subclasses that break ``bad_payloads`` down by reason."""

    def finish(self) -> list[F]:
        """End of stream: deliver what can still be decoded, count partial frames as truncated.

        A held-back frame that can never complete (the stream ended, or a
        false sync promised more bytes than came) is counted as truncated and
        the bytes after its first byte are scanned again, so complete frames
        behind it are not lost.
        """
        out: list[F] = []
        while self._buf:
            if self._buf.startswith(self.sync):
                self.stats.truncated += 1
                self._lose_sync()
                self._skip(1)
                out.extend(self.feed(b""))
            else:
                self._skip(len(self._buf))
        self._sync_tracker_stats()
        return out
