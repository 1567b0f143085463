"""Fuzzers for every codec: random faults with known injected truth.

Each fuzzer builds valid traffic from random *truth* (values it remembers),
damages it in the ways real buses do (bit flips, truncations, garbage,
duplicates, drops, reordering, foreign and malformed frames, error words),
decodes it, and checks three things:

1. **No crash**: decoders never raise on bad bytes (stream and CAN decoders
   count instead; the BioTac frame decoder marks words); any exception is a
   violation.
2. **Never a wrong value**: every value a decoder reports as valid equals the
   truth for that channel / cell / modality / sequence number.  For the BioTac
   SPI word code, whose per-byte parity cannot catch an even number of bit
   flips in one byte or random bytes that happen to look valid, the check
   for those undetectable classes is that the decoder agrees with an
   independent bit-level reference decoder and keeps every value in its
   own slot.
3. **Every error counted**: frames that arrive intact are delivered, lost
   frames equal the holes in the delivered sequence numbers, duplicates,
   unknown cells, foreign and malformed frames are counted exactly.

``fuzz_codec(name, n_inputs, seed)`` returns a :class:`FuzzReport`; the
``tactile fuzz`` command runs all of them with a progress bar.
"""

from __future__ import annotations

import random
import struct
import time
import traceback
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tactile_descriptors_ros.codecs import biotac_spi as spi
from tactile_descriptors_ros.codecs import bridge_serial as bridge
from tactile_descriptors_ros.codecs import skin_serial
from tactile_descriptors_ros.codecs.framing import crc32
from tactile_descriptors_ros.codecs.skin import PAYLOAD_SIZE, Modality, SkinSample
from tactile_descriptors_ros.errors import CodecError, ConfigError
from tactile_descriptors_ros.markers import INVALID_COUNT

__all__ = ["FuzzReport", "FUZZERS", "fuzz_codec", "fuzz_biotac_spi", "fuzz_bridge_serial",
           "fuzz_skin_can", "fuzz_skin_serial"]

Progress = Callable[[int], None] | None
_MAX_EXAMPLES = 10


@dataclass
class FuzzReport:
    """Outcome of one fuzz run.

    Attributes
    ----------
    codec : str
    inputs : int
        Random inputs tried (a BioTac frame, a short byte stream, a few CAN frames).
    seed : int
    seconds : float
    mutations : dict[str, int]
        How often each fault was injected.
    decoder_counts : dict[str, int]
        The decoders' own error counters, summed.
    checked : dict[str, int]
        How many values / frames were compared with the truth.
    violations : int
        Checks that failed (crashes, wrong values, uncounted errors).
    examples : list[str]
        The first few violations, for a bug report.
    """

    codec: str
    inputs: int
    seed: int
    seconds: float = 0.0
    mutations: Counter = field(default_factory=Counter)
    decoder_counts: Counter = field(default_factory=Counter)
    checked: Counter = field(default_factory=Counter)
    violations: int = 0
    examples: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True when no check failed."""
        return self.violations == 0

    @property
    def inputs_per_s(self) -> float:
        """Throughput."""
        return self.inputs / self.seconds if self.seconds > 0 else float("inf")

    def violate(self, message: str, count: int = 1) -> None:
        """Record ``count`` failed checks."""
        if count <= 0:
            return
        self.violations += int(count)
        if len(self.examples) < _MAX_EXAMPLES:
            self.examples.append(message)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return {"codec": self.codec, "inputs": self.inputs, "seed": self.seed,
                "seconds": round(self.seconds, 3), "inputs_per_s": round(self.inputs_per_s, 1),
                "ok": self.ok, "violations": self.violations, "examples": list(self.examples),
                "mutations": dict(self.mutations), "decoder_counts": dict(self.decoder_counts),
                "checked": dict(self.checked)}


def _tick(progress: Progress, n: int) -> None:
    if progress is not None and n:
        progress(n)


# ---------------------------------------------------------------------------
# BioTac SPI words and frames (vectorised)
# ---------------------------------------------------------------------------

_SPI_KINDS = ("clean", "odd_bit_flips", "error_words", "truncation", "padding_bits",
              "even_bit_flips", "random_bytes")
_PATTERNS = (spi.FramePattern.default(), spi.FramePattern.biotac_sp(), spi.FramePattern.paper_50hz())
_ERROR_WORD_LIST = np.array(sorted(spi.ERROR_WORDS), dtype=np.int64)
_ERROR_WORD_STATUS = np.array([int(spi.ERROR_WORDS[w]) for w in sorted(spi.ERROR_WORDS)], dtype=np.uint8)


def _spi_batch(report: FuzzReport, rng: np.random.Generator, pattern: spi.FramePattern, n: int) -> None:
    w = pattern.word_count
    nb = 2 * w
    truth = rng.integers(0, 4096, size=(n, w))
    raw = np.frombuffer(spi.encode_words(truth.ravel()), dtype=np.uint8).reshape(n, nb).copy()
    kind = rng.integers(0, len(_SPI_KINDS), size=n)
    for k, name in enumerate(_SPI_KINDS):
        report.mutations[name] += int(np.sum(kind == k))
    lengths = np.full(n, nb, dtype=np.intp)
    rows = np.arange(n)
    expect = np.zeros((n, w), dtype=np.int16) - 1  # expected status where forced, -1 = any invalid/ok
    detectable = np.isin(kind, (0, 1, 2, 3, 4))

    # odd number of bit flips in 1..4 bytes
    r = rows[kind == 1]
    base = rng.integers(0, nb, size=r.size)
    for t in range(4):  # up to 4 distinct bytes per frame
        pick = rng.random(r.size) < (1.0 if t == 0 else 0.5)
        sel = r[pick]
        b = (base[pick] + t) % nb
        nflip = rng.choice([1, 3], size=sel.size)
        for j in range(3):
            m = nflip > j
            raw[sel[m], b[m]] ^= (1 << rng.integers(0, 8, size=int(m.sum()))).astype(np.uint8)
        # a flipped byte's word cannot be good (a flip may land on a parity-valid
        # error word only in theory: 0xA5 has even parity, so it cannot)
        expect[sel, b // 2] = -2  # "must be invalid"
    # error words at 1..3 positions
    r = rows[kind == 2]
    for _ in range(3):
        sel = r[rng.random(r.size) < 0.7]
        pos = rng.integers(0, w, size=sel.size)
        e = rng.integers(0, len(_ERROR_WORD_LIST), size=sel.size)
        raw[sel, 2 * pos] = (_ERROR_WORD_LIST[e] >> 8).astype(np.uint8)
        raw[sel, 2 * pos + 1] = (_ERROR_WORD_LIST[e] & 0xFF).astype(np.uint8)
        expect[sel, pos] = _ERROR_WORD_STATUS[e]
    # truncation
    r = rows[kind == 3]
    lengths[r] = rng.integers(0, nb, size=r.size)
    # padding bit set with parity kept odd (flip a padding bit and the parity bit)
    r = rows[kind == 4]
    pos = rng.integers(0, w, size=r.size)
    bit = rng.choice([0x02, 0x04], size=r.size).astype(np.uint8)
    raw[r, 2 * pos + 1] ^= bit | 0x01
    expect[r, pos] = int(spi.WordStatus.PADDING)
    # even flips inside one byte (undetectable by parity)
    r = rows[kind == 5]
    b = rng.integers(0, nb, size=r.size)
    b1 = rng.integers(0, 8, size=r.size)
    b2 = (b1 + rng.integers(1, 8, size=r.size)) % 8
    raw[r, b] ^= ((1 << b1) | (1 << b2)).astype(np.uint8)
    # random bytes
    r = rows[kind == 6]
    raw[r] = rng.integers(0, 256, size=(r.size, nb), dtype=np.uint8)

    decoder = spi.BiotacFrameDecoder(pattern, sensors=(0,))
    try:
        frames = decoder.decode_many(0, raw, first_sequence=0, lengths=lengths)
    except Exception as exc:  # noqa: BLE001 - any exception is a finding
        report.violate(f"biotac_spi: decode_many raised {type(exc).__name__}: {exc}")
        return
    status = frames.status
    # values of every word in pattern order, rebuilt from the typed fields
    names = pattern.names()
    word_names = [nm for nm in names if nm != "-"]
    vals = np.full((n, w), INVALID_COUNT, dtype=np.int64)
    valid = np.zeros((n, w), dtype=bool)
    pac_cols = [i for i, nm in enumerate(word_names) if nm == "PAC"]
    vals[:, pac_cols] = frames.pac
    valid[:, pac_cols] = frames.pac_valid
    for nm, v, ok in (("PDC", frames.pdc, frames.pdc_valid), ("TAC", frames.tac, frames.tac_valid),
                      ("TDC", frames.tdc, frames.tdc_valid)):
        if nm in word_names:
            vals[:, word_names.index(nm)] = v
            valid[:, word_names.index(nm)] = ok
    for e in range(pattern.electrode_count):
        col = word_names.index(f"E{e + 1}")
        vals[:, col] = frames.electrodes[:, e]
        valid[:, col] = frames.electrodes_valid[:, e]

    # 1. reference decoder agreement (all kinds), missing words beyond the length
    ref_vals, ref_status = spi.reference_decode_words(raw)
    missing = (2 * np.arange(w)[None, :] + 2) > lengths[:, None]
    ref_status = np.where(missing, int(spi.WordStatus.MISSING), ref_status)
    ref_vals = np.where(missing, INVALID_COUNT, ref_vals)
    bad = status != ref_status
    report.violate(f"biotac_spi: {int(bad.sum())} word statuses differ from the reference decoder",
                   int(bad.any(axis=1).sum()))
    bad = (vals != ref_vals) | (valid != (ref_status == 0))
    report.violate(f"biotac_spi: {int(bad.sum())} values/validity flags differ from the reference "
                   f"decoder (pattern {pattern.word_count} words)", int(bad.any(axis=1).sum()))
    # 2. detectable faults: a valid value is the truth for that slot
    wrong = valid & (vals != truth) & detectable[:, None]
    report.violate(f"biotac_spi: {int(wrong.sum())} valid values differ from the injected truth",
                   int(wrong.any(axis=1).sum()))
    report.checked["values_vs_truth"] += int((valid & detectable[:, None]).sum())
    report.checked["words_vs_reference"] += int(n * w)
    # forced statuses
    forced = expect >= 0
    bad = forced & (status != expect)
    report.violate(f"biotac_spi: {int(bad.sum())} injected error words/padding not flagged as such",
                   int(bad.any(axis=1).sum()))
    bad = (expect == -2) & (status == 0)
    report.violate(f"biotac_spi: {int(bad.sum())} words with odd bit flips reported valid",
                   int(bad.any(axis=1).sum()))
    # 3. counts add up
    counted = np.zeros(n, dtype=np.int64)
    for st in range(1, len(spi.WordStatus)):
        counted += (status == st).sum(axis=1)
    bad = counted + valid.sum(axis=1) != w
    report.violate("biotac_spi: per-frame counts do not add up to the word count", int(bad.sum()))
    if frames.counts.bad != int(counted.sum()):
        report.violate("biotac_spi: summed WordCounts disagree with the statuses")
    for k, v in frames.counts.as_dict().items():
        report.decoder_counts[k] += v
    # 4. single-frame and multi-sensor paths agree with the batch path, nothing crosses sensors
    take = rng.choice(n, size=min(n, 5), replace=False)
    multi = spi.BiotacFrameDecoder(pattern, sensors=tuple(range(len(take))))
    try:
        sample_set = multi.decode_sample_set(
            {cs: raw[i, : lengths[i]].tobytes() for cs, i in enumerate(take)}, sequence=7)
    except Exception as exc:  # noqa: BLE001
        report.violate(f"biotac_spi: decode_sample_set raised {type(exc).__name__}: {exc}")
        return
    for cs, i in enumerate(take):
        f = sample_set[cs]
        if f.sensor != cs or f.sequence != 7 or not np.array_equal(f.status, status[i]) \
                or not np.array_equal(f.pac, frames.pac[i]) \
                or not np.array_equal(f.electrodes, frames.electrodes[i]) or f.pdc != frames.pdc[i]:
            report.violate(f"biotac_spi: sensor {cs} of a sample set differs from its own reply")
    report.checked["sample_set_frames"] += len(take)


def fuzz_biotac_spi(n_inputs: int, seed: int = 0, progress: Progress = None,
                    batch: int = 8192) -> FuzzReport:
    """Fuzz BioTac reply words and the frame decoder; one input is one frame."""
    report = FuzzReport("biotac_spi", int(n_inputs), int(seed))
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    done, k = 0, 0
    while done < n_inputs:
        n = min(batch, n_inputs - done)
        _spi_batch(report, rng, _PATTERNS[k % len(_PATTERNS)], n)
        k += 1
        done += n
        _tick(progress, n)
    # scalar API on a handful of words per run
    for word in rng.integers(0, 65536, size=min(2000, max(100, n_inputs // 100))):
        b = int(word).to_bytes(2, "big")
        st = int(spi.decode_words(b)[1][0])
        try:
            v = spi.decode_word(b)
            if st != 0 or v != int(spi.decode_words(b)[0][0]):
                report.violate(f"decode_word(0x{int(word):04X}) returned {v} for status {st}")
        except CodecError:
            if st == 0:
                report.violate(f"decode_word(0x{int(word):04X}) raised for a valid word")
        except Exception as exc:  # noqa: BLE001
            report.violate(f"decode_word raised {type(exc).__name__}")
    report.seconds = time.perf_counter() - t0
    return report


# ---------------------------------------------------------------------------
# Byte-stream framings (bridge, skin serial)
# ---------------------------------------------------------------------------

_STREAM_KINDS = ("clean", "bit_flips", "truncation", "garbage", "duplicate", "drop", "random_only",
                 "false_sync", "invalid_frame")


@dataclass
class _Item:
    """One frame in a fuzz stream: its key, truth, wire bytes, and its fate."""

    key: Any
    truth: Any
    wire: bytes
    intact: int = 0
    valid: bool = True  # False: a well-formed-but-invalid frame that must be rejected
    reject: str = ""


class _StreamCodec:
    name = ""
    sync = b""

    def new_decoder(self) -> Any:
        raise NotImplementedError

    def make_items(self, rng: random.Random, state: dict, n: int) -> list[_Item]:
        raise NotImplementedError

    def invalid_item(self, rng: random.Random) -> _Item:
        raise NotImplementedError

    def key_of(self, frame: Any) -> Any:
        raise NotImplementedError

    def modulus(self) -> int:
        raise NotImplementedError

    def check_rejects(self, report: FuzzReport, decoder: Any, items: list[_Item]) -> None:
        raise NotImplementedError


class _BridgeCodec(_StreamCodec):
    name = "bridge_serial"
    sync = bridge.SYNC

    def new_decoder(self) -> bridge.BridgeDecoder:
        return bridge.BridgeDecoder()

    def modulus(self) -> int:
        return 65536

    def make_items(self, rng, state, n):
        items = []
        for _ in range(n):
            cs = rng.randrange(0, 5)
            kind = bridge.BridgeFrameType.SERIAL_NUMBER if rng.random() < 0.05 else bridge.BridgeFrameType.SAMPLE
            key = (int(kind), cs)
            u = state.setdefault(key, rng.randrange(0, 65536) + 65536 * 4)
            state[key] = u + 1
            if kind is bridge.BridgeFrameType.SAMPLE:
                payload = rng.randbytes(2 * rng.choice([44, 54, 66]))
            else:
                payload = ("BT" + "".join(rng.choices("0123456789ABCDEF", k=14))).encode()
            frame = bridge.BridgeFrame(kind, cs, u % 65536, rng.getrandbits(32), payload)
            items.append(_Item((key, u), frame, bridge.encode_bridge_frame(frame)))
        return items

    def invalid_item(self, rng):
        # CRC-correct frame with an impossible header (chip select 5..255 or unknown type)
        if rng.random() < 0.5:
            body = struct.pack(">BBHIH", 1, rng.randrange(5, 256), 0, 0, 4) + b"\x01\x01\x01\x01"
            reason = "bad_cs"
        else:
            body = struct.pack(">BBHIH", rng.randrange(3, 256), 0, 0, 0, 2) + b"\x01\x01"
            reason = "bad_type"
        return _Item(None, None, bridge.SYNC + body + crc32(body).to_bytes(4, "big"), valid=False,
                     reject=reason)

    def key_of(self, frame):
        return (int(frame.kind), frame.chip_select)

    def check_rejects(self, report, decoder, items):
        n = sum(it.intact for it in items if not it.valid)
        if decoder.stats.bad_headers < n:
            report.violate(f"bridge_serial: {n} intact impossible headers but only "
                           f"{decoder.stats.bad_headers} bad_headers counted")
        report.checked["invalid_frames"] += n


_KNOWN_CELLS = (3, 17, 4242)
_UNKNOWN_CELLS = (9, 60000)


def _random_values(rng: random.Random, m: Modality) -> tuple[int, ...]:
    if m is Modality.ACCEL:
        return tuple(rng.randrange(-512, 512) for _ in range(3))
    if m is Modality.FORCE:
        return tuple(rng.randrange(0, 4096) for _ in range(3))
    if m is Modality.PROXIMITY:
        return (rng.randrange(0, 0xFFFF),)
    return (rng.randrange(-32767, 32768),)


def _next_known_sample(rng: random.Random, state: dict) -> tuple[tuple[tuple[int, int], int], SkinSample]:
    """A valid sample of a known cell and a random modality, with that stream's next sequence number.

    ``state`` holds each (cell, modality) stream's unwrapped counter (started at a random value a few
    wraps in); the key ``((cell, modality), counter)`` names the sample in the truth table.
    """
    cell = rng.choice(_KNOWN_CELLS)
    m = Modality(rng.randrange(1, 5))
    key = (cell, int(m))
    u = state.setdefault(key, rng.randrange(0, 256) + 256 * 4)
    state[key] = u + 1
    return (key, u), SkinSample(cell, m, u % 256, _random_values(rng, m))


class _SkinSerialCodec(_StreamCodec):
    name = "skin_serial"
    sync = skin_serial.SYNC

    def new_decoder(self) -> skin_serial.SkinSerialDecoder:
        return skin_serial.SkinSerialDecoder(known_cell_ids=_KNOWN_CELLS)

    def modulus(self) -> int:
        return 256

    def make_items(self, rng, state, n):
        items = []
        for _ in range(n):
            name, s = _next_known_sample(rng, state)
            items.append(_Item(name, s, skin_serial.encode_skin_frame(s)))
        return items

    def invalid_item(self, rng):
        r = rng.random()
        if r < 0.3:  # unknown cell, otherwise perfect
            m = Modality(rng.randrange(1, 5))
            s = SkinSample(rng.choice(_UNKNOWN_CELLS), m, rng.randrange(0, 256), _random_values(rng, m))
            return _Item(None, s, skin_serial.encode_skin_frame(s), valid=False, reject="unknown_cell")
        if r < 0.55:
            mod, payload, reason = rng.randrange(5, 256), b"\x00\x00", "unknown_modality"
        elif r < 0.8:
            mod = rng.randrange(1, 5)
            size = PAYLOAD_SIZE[Modality(mod)] + rng.choice([-1, 1, 2])
            payload, reason = bytes(size), "bad_length"
        else:
            mod, payload, reason = int(Modality.ACCEL), b"\xc0\x00\x00\x00", "bad_payload"
        body = struct.pack(">BBHB", len(payload), 0, _KNOWN_CELLS[0], mod) + payload
        return _Item(None, None, skin_serial.SYNC + body + crc32(body).to_bytes(4, "big"), valid=False,
                     reject=reason)

    def key_of(self, frame):
        return (frame.cell_id, int(frame.modality))

    def check_rejects(self, report, decoder, items):
        want = Counter()
        cells = Counter()
        for it in items:
            if not it.valid and it.intact:
                want[it.reject] += it.intact
                if it.reject == "unknown_cell":
                    cells[it.truth.cell_id] += it.intact
        for reason, n in want.items():
            if decoder.reject_reasons[reason] != n:
                report.violate(f"skin_serial: {n} intact {reason} frames, "
                               f"{decoder.reject_reasons[reason]} counted")
        if dict(cells) != dict(decoder.unknown_cell_ids):
            report.violate(f"skin_serial: unknown cells {dict(cells)} counted as {dict(decoder.unknown_cell_ids)}")
        report.checked["invalid_frames"] += sum(want.values())


def _stream_batch(report: FuzzReport, rng: random.Random, codec: _StreamCodec, n_inputs: int) -> None:
    state: dict = {}
    items: list[_Item] = []
    chunks: list[bytes] = []
    damaged_any = False
    starts: list[tuple[int, _Item]] = []  # stream offset of each intact copy
    cuts: list[tuple[int, int, bytes]] = []  # truncated copies: offset, kept bytes, full wire
    for _ in range(n_inputs):
        kind = _STREAM_KINDS[rng.randrange(0, len(_STREAM_KINDS))]
        report.mutations[kind] += 1
        if kind == "random_only":
            chunks.append(rng.randbytes(rng.randrange(1, 64)))
            damaged_any = True
            continue
        new = codec.make_items(rng, state, rng.randrange(1, 4))
        if kind == "invalid_frame":
            new.insert(rng.randrange(0, len(new) + 1), codec.invalid_item(rng))
        if kind == "drop":
            new.pop(rng.randrange(0, len(new)))  # never sent: truth keeps its seq as a hole
        wires = [bytearray(it.wire) for it in new]
        order = list(range(len(new)))
        victim = rng.randrange(0, len(new)) if new else 0
        if kind == "duplicate" and new:
            order.insert(victim + 1, victim)
        items.extend(new)
        for pos, idx in enumerate(order):
            it = new[idx]
            wire = wires[idx] if pos == order.index(idx) else bytearray(it.wire)
            intact = True
            if idx == victim and pos == order.index(idx):
                if kind == "bit_flips":
                    for _ in range(rng.randrange(1, 4)):
                        b = rng.randrange(0, len(wire))
                        wire[b] ^= 1 << rng.randrange(0, 8)
                    intact = bytes(wire) == it.wire
                elif kind == "truncation":
                    wire = wire[: rng.randrange(0, len(wire))]
                    intact = False
            if not intact:
                damaged_any = True
            it.intact += int(intact)
            offset = sum(len(c) for c in chunks) if (intact or kind == "truncation") else 0
            if intact:
                starts.append((offset, it))
            elif kind == "truncation":
                cuts.append((offset, len(wire), it.wire))
            chunks.append(bytes(wire))
            if kind == "garbage" and rng.random() < 0.5:
                chunks.append(rng.randbytes(rng.randrange(1, 40)))
                damaged_any = True
            if kind == "false_sync" and pos == 0:
                # a sync and a header promising a long frame, then real frames follow
                fake = codec.sync + rng.randbytes(rng.randrange(0, 12))
                chunks.append(fake)
                damaged_any = True
    stream = b"".join(chunks)
    # A frame cut inside its CRC whose missing bytes happen to equal the next
    # bytes is complete again (and correct): it swallows the start of the next
    # frame, which is then lost and counted as a sequence gap.  Allowed.
    completed = {off + kept for off, kept, wire in cuts if stream[off: off + len(wire)] == wire}
    for off, it in starts:
        if any(off <= c < off + len(it.wire) or c - 4 <= off < c for c in completed):
            it.intact -= 1
            report.checked["coincidental_completions"] += 1
    decoder = codec.new_decoder()
    delivered: list[Any] = []
    try:
        pos = 0
        while pos < len(stream):
            step = rng.randrange(1, 600)
            delivered.extend(decoder.feed(stream[pos: pos + step]))
            pos += step
        delivered.extend(decoder.finish())
    except Exception as exc:  # noqa: BLE001 - any exception is a finding
        report.violate(f"{codec.name}: decoder raised {type(exc).__name__}: {exc} "
                       f"{traceback.format_exc(limit=3)}")
        return
    by_key = {it.key: it for it in items if it.valid}
    m = codec.modulus()
    by_wire = {(k, u % m): ((k, u), it) for (k, u), it in by_key.items()}
    seen: set = set()
    # wrong values / duplicates delivered
    got_u: dict[Any, list[int]] = {}
    for frame in delivered:
        match = by_wire.get((codec.key_of(frame), frame.sequence))
        if match is None:
            report.violate(f"{codec.name}: delivered a frame nobody sent: {frame!r}"[:300])
            continue
        (kk, u), it = match
        if frame != it.truth:
            report.violate(f"{codec.name}: delivered {frame!r} but sent {it.truth!r}"[:300])
        if (kk, u) in seen:
            report.violate(f"{codec.name}: frame {(kk, u)} delivered twice")
        seen.add((kk, u))
        got_u.setdefault(kk, []).append(u)
    report.checked["frames_vs_truth"] += len(delivered)
    # every intact frame delivered
    lost_intact = [key for key, it in by_key.items() if it.intact and key not in seen]
    report.violate(f"{codec.name}: {len(lost_intact)} intact frames not delivered, e.g. {lost_intact[:3]}",
                   len(lost_intact))
    # duplicates counted exactly
    want_dups = sum(it.intact - 1 for key, it in by_key.items() if it.intact > 1)
    st = decoder.stats
    if st.duplicates != want_dups:
        report.violate(f"{codec.name}: {want_dups} duplicate arrivals, {st.duplicates} counted")
    # lost frames = holes in the delivered sequence numbers
    holes = 0
    for us in got_u.values():
        got = set(us)
        holes += sum(1 for u in range(min(us), max(us) + 1) if u not in got)
    if st.lost_frames != holes:
        report.violate(f"{codec.name}: {holes} holes in delivered sequence numbers, {st.lost_frames} lost counted")
    # damage is visible in the counters
    if damaged_any and st.garbage_bytes + st.crc_errors + st.truncated + st.bad_headers == 0:
        report.violate(f"{codec.name}: damaged bytes left no trace in the counters")
    codec.check_rejects(report, decoder, items)
    for k, v in st.as_dict().items():
        report.decoder_counts[k] += v


def _fuzz_stream(codec: _StreamCodec, n_inputs: int, seed: int, progress: Progress, batch: int) -> FuzzReport:
    report = FuzzReport(codec.name, int(n_inputs), int(seed))
    rng = random.Random(seed)
    t0 = time.perf_counter()
    done = 0
    while done < n_inputs:
        n = min(batch, n_inputs - done)
        _stream_batch(report, rng, codec, n)
        done += n
        _tick(progress, n)
    report.seconds = time.perf_counter() - t0
    return report


def fuzz_bridge_serial(n_inputs: int, seed: int = 0, progress: Progress = None, batch: int = 60) -> FuzzReport:
    """Fuzz the bridge framing; one input is 1-3 frames with one injected fault."""
    return _fuzz_stream(_BridgeCodec(), n_inputs, seed, progress, batch)


def fuzz_skin_serial(n_inputs: int, seed: int = 0, progress: Progress = None, batch: int = 60) -> FuzzReport:
    """Fuzz the skin serial framing; one input is 1-3 frames with one injected fault."""
    return _fuzz_stream(_SkinSerialCodec(), n_inputs, seed, progress, batch)


# ---------------------------------------------------------------------------
# Skin CAN
# ---------------------------------------------------------------------------

_CAN_KINDS = ("clean", "drop", "duplicate", "reorder", "foreign", "unknown_modality", "bad_length",
              "bad_payload", "unknown_cell", "remote_or_error")


def _can_batch(report: FuzzReport, rng: random.Random, n_inputs: int) -> None:
    import can

    from tactile_descriptors_ros.codecs import skin_can

    state: dict = {}
    truth: dict = {}  # (key, u) -> SkinSample
    msgs: list[tuple[Any, can.Message]] = []  # (truth key or None, message)
    want = Counter()
    want_cells = Counter()
    for _ in range(n_inputs):
        kind = _CAN_KINDS[rng.randrange(0, len(_CAN_KINDS))]
        report.mutations[kind] += 1
        new: list[tuple[Any, can.Message]] = []
        for _ in range(rng.randrange(1, 4)):
            name, s = _next_known_sample(rng, state)
            truth[name] = s
            new.append((name, skin_can.encode_can_message(s)))
        i = rng.randrange(0, len(new))
        if kind == "drop":
            new.pop(i)
        elif kind == "duplicate":
            new.insert(i + 1, new[i])
        elif kind == "reorder" and len(new) > 1:
            j = min(i + 1, len(new) - 1)
            i = j - 1
            new[i], new[j] = new[j], new[i]
        elif kind == "foreign":
            if rng.random() < 0.5:
                bad = can.Message(arbitration_id=rng.randrange(0, 0x800), is_extended_id=False,
                                  data=rng.randbytes(rng.randrange(0, 9)))
            else:
                arb = rng.randrange(0, 1 << 29)
                if (arb >> 20) == skin_can.PROTOCOL_TAG:
                    arb ^= 1 << 28
                bad = can.Message(arbitration_id=arb, is_extended_id=True,
                                  data=rng.randbytes(rng.randrange(0, 9)))
            new.insert(i, (None, bad))
            want["foreign_frames"] += 1
        elif kind == "unknown_modality":
            mod = rng.choice([0] + list(range(5, 16)))
            arb = (skin_can.PROTOCOL_TAG << 20) | (mod << 16) | _KNOWN_CELLS[0]
            new.insert(i, (None, can.Message(arbitration_id=arb, is_extended_id=True, data=b"\x00\x00\x00")))
            want["unknown_modality"] += 1
        elif kind == "bad_length":
            m = Modality(rng.randrange(1, 5))
            size = 1 + PAYLOAD_SIZE[m] + rng.choice([-1, 1, 2])
            data = rng.randbytes(max(0, min(size, 8)))
            new.insert(i, (None, can.Message(arbitration_id=skin_can.arbitration_id(_KNOWN_CELLS[1], m),
                                             is_extended_id=True, data=data)))
            want["bad_length"] += 1
        elif kind == "bad_payload":
            data = bytes([0]) + (b"\xc0\x00\x00\x00" if rng.random() < 0.5 else b"")
            m = Modality.ACCEL if len(data) == 5 else Modality.PROXIMITY
            if m is Modality.PROXIMITY:
                data = bytes([0, 0xFF, 0xFF])
            new.insert(i, (None, can.Message(arbitration_id=skin_can.arbitration_id(_KNOWN_CELLS[2], m),
                                             is_extended_id=True, data=data)))
            want["bad_payload"] += 1
        elif kind == "unknown_cell":
            m = Modality(rng.randrange(1, 5))
            cell = rng.choice(_UNKNOWN_CELLS)
            s = SkinSample(cell, m, rng.randrange(0, 256), _random_values(rng, m))
            new.insert(i, (None, skin_can.encode_can_message(s)))
            want["unknown_cells"] += 1
            want_cells[cell] += 1
        elif kind == "remote_or_error":
            if rng.random() < 0.5:
                msg = can.Message(arbitration_id=skin_can.arbitration_id(_KNOWN_CELLS[0], Modality.FORCE),
                                  is_extended_id=True, is_remote_frame=True, dlc=6)
            else:
                msg = can.Message(is_error_frame=True)
            new.insert(i, (None, msg))
            want["remote_or_error_frames"] += 1
        msgs.extend(new)
    decoder = skin_can.SkinCanDecoder(known_cell_ids=_KNOWN_CELLS)
    out: list[tuple[Any, SkinSample | None]] = []
    try:
        for key, msg in msgs:
            out.append((key, decoder.decode(msg)))
    except Exception as exc:  # noqa: BLE001
        report.violate(f"skin_can: decoder raised {type(exc).__name__}: {exc}")
        return
    st = decoder.stats
    seen: set = set()
    got_u: dict[Any, list[int]] = {}
    arrivals: dict[Any, list[int]] = {}
    arrived: set = set()
    copies = Counter(key for key, _ in msgs if key is not None)
    for key, sample in out:
        if key is not None and key not in arrived:
            arrived.add(key)
            arrivals.setdefault(key[0], []).append(key[1])
        if sample is None:
            if key is not None and key not in seen:
                report.violate(f"skin_can: a valid frame {key} was rejected")
            continue
        if key is None:
            report.violate(f"skin_can: an invalid frame was decoded as {sample!r}")
            continue
        if key in seen:
            report.violate(f"skin_can: frame {key} delivered twice")
        seen.add(key)
        t = truth[key]
        if (sample.cell_id, sample.modality, sample.sequence, sample.values) != (t.cell_id, t.modality, t.sequence, t.values):
            report.violate(f"skin_can: delivered {sample!r}, sent {t!r}")
        got_u.setdefault(key[0], []).append(key[1])
    report.checked["samples_vs_truth"] += len(seen)
    for name, n in want.items():
        if getattr(st, name) != n:
            report.violate(f"skin_can: {n} injected {name}, {getattr(st, name)} counted")
    if dict(st.unknown_cell_ids) != dict(want_cells):
        report.violate("skin_can: unknown cell ids miscounted")
    want_dups = sum(c - 1 for c in copies.values() if c > 1)
    if st.duplicates != want_dups:
        report.violate(f"skin_can: {want_dups} duplicates sent, {st.duplicates} counted")
    holes = 0
    late = 0
    for _kk, us in got_u.items():
        s = set(us)
        holes += sum(1 for u in range(min(us), max(us) + 1) if u not in s)
    for _kk, order in arrivals.items():
        hi = None
        for u in order:
            if hi is not None and u < hi:
                late += 1
            hi = u if hi is None else max(hi, u)
    if st.lost_frames != holes:
        report.violate(f"skin_can: {holes} holes in delivered sequence numbers, {st.lost_frames} counted")
    if st.out_of_order != late:
        report.violate(f"skin_can: {late} frames arrived late, {st.out_of_order} counted out of order")
    for k, v in st.as_dict().items():
        if isinstance(v, int):
            report.decoder_counts[k] += v


def fuzz_skin_can(n_inputs: int, seed: int = 0, progress: Progress = None, batch: int = 60) -> FuzzReport:
    """Fuzz the skin CAN decoder; one input is 1-3 frames with one injected bus fault."""
    report = FuzzReport("skin_can", int(n_inputs), int(seed))
    rng = random.Random(seed)
    t0 = time.perf_counter()
    done = 0
    while done < n_inputs:
        n = min(batch, n_inputs - done)
        _can_batch(report, rng, n)
        done += n
        _tick(progress, n)
    report.seconds = time.perf_counter() - t0
    return report


#: Codec name -> fuzzer ``f(n_inputs, seed, progress) -> FuzzReport``.
FUZZERS: dict[str, Callable[..., FuzzReport]] = {
    "biotac_spi": fuzz_biotac_spi,
    "bridge_serial": fuzz_bridge_serial,
    "skin_can": fuzz_skin_can,
    "skin_serial": fuzz_skin_serial,
}


def fuzz_codec(name: str, n_inputs: int, seed: int = 0, progress: Progress = None) -> FuzzReport:
    """Run the fuzzer of one codec.

    Raises
    ------
    ConfigError
        Unknown codec name or a negative input count.
    """
    if name not in FUZZERS:
        raise ConfigError(f"unknown codec {name!r}; known: {', '.join(FUZZERS)}", key="codec")
    if n_inputs < 0:
        raise ConfigError("the number of inputs must be >= 0", key="inputs")
    return FUZZERS[name](int(n_inputs), int(seed), progress)
