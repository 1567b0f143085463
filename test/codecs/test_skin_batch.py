"""Batch (numpy) skin codecs against the per-frame reference: same bytes, same samples, same counters."""

from __future__ import annotations

import random
from unittest import mock

import can
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_descriptors_ros.codecs import sequence, skin_can
from tactile_descriptors_ros.codecs.can_frames import frames_from_messages, messages_from_frames
from tactile_descriptors_ros.codecs.framing import SequenceTracker
from tactile_descriptors_ros.codecs.skin import (
    Modality,
    SkinSample,
    SkinSampleBatch,
    pack_values,
    pack_values_batch,
    unpack_values,
    unpack_values_batch,
)
from tactile_descriptors_ros.codecs.skin_can import PROTOCOL_TAG, SkinCanDecoder, encode_can_frames, encode_can_message
from tactile_descriptors_ros.core import fast
from tactile_descriptors_ros.errors import CodecError

_RANGE = {Modality.ACCEL: (-512, 511), Modality.FORCE: (0, 4095), Modality.PROXIMITY: (0, 0xFFFE),
          Modality.TEMPERATURE: (-32767, 32767)}
_COUNT = {Modality.ACCEL: 3, Modality.FORCE: 3, Modality.PROXIMITY: 1, Modality.TEMPERATURE: 1}


def _values(m: Modality):
    lo, hi = _RANGE[m]
    return st.tuples(*[st.integers(lo, hi)] * _COUNT[m])


samples = st.sampled_from(list(Modality)).flatmap(
    lambda m: st.builds(SkinSample, st.integers(0, 0xFFFF), st.just(m), st.integers(0, 255), _values(m),
                        st.one_of(st.none(), st.integers(1, 2 ** 52))))


@settings(max_examples=60, deadline=None)
@given(st.lists(samples, max_size=40), st.data())
def test_batch_payloads_and_can_frames_equal_the_per_sample_encoder(items, data):
    batch = SkinSampleBatch.from_samples(items)
    corrupt = np.array(data.draw(st.lists(st.booleans(), min_size=len(items), max_size=len(items))), dtype=bool)
    pay = pack_values_batch(batch.modality, batch.values)
    for s, row in zip(items, pay):
        ref = pack_values(s.modality, s.values)
        assert bytes(row[:len(ref)]) == ref and not row[len(ref):].any()
    vals, ok = unpack_values_batch(batch.modality, pay)
    assert ok.all() and np.array_equal(vals, batch.values)
    frames = encode_can_frames(batch, corrupt)
    for s, bad, got in zip(items, corrupt, messages_from_frames(frames)):
        ref = encode_can_message(s)
        if bad:
            ref.data = ref.data[:-1]
            ref.dlc = len(ref.data)
        assert ref.equals(got, timestamp_delta=0.0)


def test_batch_payload_validation_matches_the_reference():
    rng = np.random.default_rng(3)
    mods = rng.integers(1, 5, 4000)
    pay = rng.integers(0, 256, (4000, 5)).astype(np.uint8)
    pay[::3] = 0xFF  # reserved proximity value, set must-be-zero bits
    vals, ok = unpack_values_batch(mods, pay)
    for m, p, v, good in zip(mods.tolist(), pay, vals, ok):
        size = {1: 4, 2: 5, 3: 2, 4: 2}[m]
        try:
            ref = unpack_values(m, bytes(p[:size]))
        except CodecError:
            assert not good
            continue
        assert good and tuple(v[:len(ref)]) == ref
    with pytest.raises(CodecError):
        pack_values_batch(np.array([1]), np.array([[512, 0, 0]]))
    with pytest.raises(CodecError):
        pack_values_batch(np.array([7]), np.array([[0, 0, 0]]))


# ----------------------------------------------------------- CAN streams
KNOWN = (3, 4, 5)


_KINDS = ["good"] * 12 + ["repeat", "jump", "back", "foreign", "std", "std_tagged", "remote", "error", "bad_mod",
                          "bad_len", "bad_payload", "unknown_cell"]


def _random_values(rng: random.Random, m: Modality) -> tuple[int, ...]:
    lo, hi = _RANGE[m]
    return tuple(rng.randint(lo, hi) for _ in range(_COUNT[m]))


def can_stream(seed: int, n: int) -> list[can.Message]:
    """Frames of a few cells with in-order, lost, repeated, late and restarted sequence numbers, plus damage."""
    rng = random.Random(seed)
    seq: dict = {}
    msgs = []
    for _ in range(n):
        kind = rng.choice(_KINDS)
        cell = rng.choice(KNOWN)
        mod = rng.choice(list(Modality))
        key = (cell, mod)
        s = seq.get(key, rng.randint(0, 255))
        if kind == "jump":
            s = (s + rng.randint(1, 200)) & 0xFF
        elif kind == "back":
            s = (s - rng.randint(1, 255)) & 0xFF
        elif kind == "repeat":
            s = (s - 1) & 0xFF
        if kind == "unknown_cell":
            cell = rng.randint(6, 9)
        stamp = None if rng.random() < 0.3 else rng.randint(1, 10 ** 12)
        msg = encode_can_message(SkinSample(cell, mod, s, _random_values(rng, mod), stamp))
        seq[key] = (s + 1) & 0xFF
        if kind == "foreign":
            msg.arbitration_id = ((PROTOCOL_TAG + 1) << 20) | (msg.arbitration_id & 0xFFFFF)
        elif kind == "std":
            msg = can.Message(arbitration_id=0x123, is_extended_id=False, data=bytes(msg.data))
        elif kind == "std_tagged":  # an adapter's standard frame whose id bits look like ours: still foreign
            msg.is_extended_id = False
        elif kind == "remote":
            msg = can.Message(arbitration_id=msg.arbitration_id, is_remote_frame=True, dlc=2)
        elif kind == "error":
            msg = can.Message(arbitration_id=0, is_error_frame=True, data=b"\x01")
        elif kind == "bad_mod":
            msg.arbitration_id = (PROTOCOL_TAG << 20) | (rng.choice([0, 5, 15]) << 16) | cell
        elif kind == "bad_len":
            k = rng.randint(0, 8)
            msg.data = bytearray(rng.randbytes(k))
            msg.dlc = k
        elif kind == "bad_payload":
            d = bytearray(msg.data)
            if mod is Modality.ACCEL:
                d[1] |= 0xC0
            elif mod is Modality.FORCE:
                d[5] |= 0x01
            elif mod is Modality.PROXIMITY:
                d[1:3] = b"\xff\xff"
            else:
                d[1:3] = b"\x80\x00"
            msg.data = d
        msgs.append(msg)
    return msgs


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 2 ** 32), st.integers(0, 300), st.lists(st.integers(0, 300), max_size=6),
       st.sampled_from([None, KNOWN]), st.integers(2, 40), st.booleans())
def test_can_batch_decoder_equals_the_per_frame_decoder(seed, n, cuts, known, window, compiled):
    """Both batch paths (the compiled pass where the backend is loaded, and numpy) against the per-frame decoder."""
    msgs = can_stream(seed, n)
    cuts = sorted(min(c, n) for c in cuts)
    ref = SkinCanDecoder(known_cell_ids=known, duplicate_window=window)
    want = [s for m in msgs if (s := ref.decode(m)) is not None]
    dec = SkinCanDecoder(known_cell_ids=known, duplicate_window=window)
    frames = frames_from_messages(msgs)
    got = []
    with mock.patch.object(skin_can, "COMPILED_DECODE", compiled):  # not monkeypatch: per example
        for a, b in zip([0] + cuts, cuts + [len(msgs)]):
            got += dec.decode_frames(frames[a:b]).to_samples()
    assert got == want
    assert dec.stats == ref.stats
    assert dec.tracker.snapshot() == ref.tracker.snapshot()  # everything that decides future events


needs_kernel = pytest.mark.skipif(fast.kernel_module() is None, reason="the compiled backend is not loaded here")


@needs_kernel
@settings(max_examples=100, deadline=None)
@given(st.integers(0, 2 ** 32), st.integers(1, 300), st.integers(1, 2 ** 62), st.booleans())
def test_compiled_can_decoder_equals_numpy_with_arrival_times(seed, n, arrival_ns, unstamped):
    """Frames without bus times are unwrapped on the read's arrival time on both paths alike; bus times that
    fall between two nanoseconds round half to even on both."""
    frames = frames_from_messages(can_stream(seed, n))
    if unstamped:
        frames["timestamp"] = 0.0
    else:
        frames["timestamp"][::3] = 0.0
        frames["timestamp"][1::3] = np.arange(len(frames[1::3])) * 1e-9 + 0.5e-9 + 1.0  # ties and near-ties
    out = []
    for compiled in (True, False):
        dec = SkinCanDecoder(known_cell_ids=KNOWN)
        with mock.patch.object(skin_can, "COMPILED_DECODE", compiled):
            batch = dec.decode_frames(frames, arrival_ns)
        out.append((batch, dec.stats, dec.tracker.snapshot()))
    (a, sa, ta), (b, sb, tb) = out
    for field in ("cell_id", "modality", "sequence", "values", "stamp_ns"):
        x, y = getattr(a, field), getattr(b, field)
        assert x.dtype == y.dtype and np.array_equal(x, y), field
    assert sa == sb and ta == tb


def test_load_compiled_says_numpy_serves_when_the_compiled_decoding_is_off():
    with mock.patch.object(skin_can, "COMPILED_DECODE", False):
        assert skin_can.load_compiled() is False


@needs_kernel
def test_the_decoder_takes_the_compiled_pass_when_the_backend_is_loaded():
    frames = frames_from_messages(can_stream(7, 200))
    dec = SkinCanDecoder(known_cell_ids=KNOWN)
    with mock.patch.object(dec, "_decode_compiled", wraps=dec._decode_compiled) as spy:
        dec.decode_frames(frames)
        dec.decode_frames(frames[:0])  # nothing to decode: nothing called
    assert spy.call_count == 1
    with mock.patch.object(skin_can, "COMPILED_DECODE", False), \
            mock.patch.object(dec, "_decode_compiled", wraps=dec._decode_compiled) as off:
        dec.decode_frames(frames)
    assert off.call_count == 0


@needs_kernel
def test_the_compiled_can_decoder_runs_one_variant_warmed_up_at_set_up():
    """Frame arrays of any length, slices and strides take the variant ``make setup`` compiles; a single frame and
    a read-only buffer take numpy (each would be another variant, compiled while the driver runs)."""
    kernel = fast.kernel_module()
    fast.warm_up()
    skin_can.load_compiled()
    before = list(kernel.decode_can_rows.signatures)
    frames = frames_from_messages(can_stream(11, 120))
    readonly = np.frombuffer(frames.tobytes(), dtype=frames.dtype)
    want = SkinCanDecoder(known_cell_ids=KNOWN)
    with mock.patch.object(skin_can, "COMPILED_DECODE", False):
        ref = [want.decode_frames(f).to_samples() for f in (frames, frames[:1], frames[::3], frames[5:7], readonly)]
    dec = SkinCanDecoder(known_cell_ids=KNOWN)
    got = [dec.decode_frames(f).to_samples() for f in (frames, frames[:1], frames[::3], frames[5:7], readonly)]
    assert got == ref and dec.stats == want.stats
    assert kernel.decode_can_rows.signatures == before and len(before) == 1


@needs_kernel
def test_the_compiled_tracker_runs_one_variant_the_drivers_warm_up_loads():
    """Scalar or per-number periods, read-only times or none take the variant that ``load_compiled`` (the
    driver, before it opens its bus) and ``make setup`` load."""
    kernel = fast.kernel_module()
    assert skin_can.load_compiled() is True
    before = list(kernel.track_forward.signatures)
    codes, seqs = np.repeat(np.arange(4), 5), np.tile(np.arange(5), 4)
    times = np.arange(20, dtype=np.int64) * 1000
    times.flags.writeable = False
    for t, period in ((None, None), (times, 1000.0), (times, np.full(20, 1000.0)), (times.astype(np.int32), 1000)):
        SequenceTracker(256, 8).track_many(codes, seqs, int, t, period)
    assert kernel.track_forward.signatures == before and len(before) == 1


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 5), st.integers(0, 255)), max_size=200), st.integers(0, 60),
       st.booleans(), st.one_of(st.none(), st.integers(0, 2 ** 16)))
def test_sequence_tracker_update_many_equals_update(pairs, window, compiled, time_seed):
    """Both batch paths (compiled where the backend is loaded, numpy) against ``update`` one by one, with and
    without duplicate memory, with frame times (some unknown) that carry keys over silences, or without."""
    ref, got = SequenceTracker(256, window), SequenceTracker(256, window)
    codes = np.array([k for k, _ in pairs], dtype=np.int64)
    seqs = np.array([s for _, s in pairs], dtype=np.int64)
    period = 1000.0
    if time_seed is None:
        t = None
        want = [int(ref.update(("k", k), s)) for k, s in pairs]
    else:  # increasing times, a silence of up to 600 periods now and then, a few unknown (-1)
        rng = np.random.default_rng(time_seed)
        t = np.cumsum(rng.choice([1000, 1000, 1000, 2000, 600_000], size=len(pairs))).astype(np.int64)
        t[rng.random(len(pairs)) < 0.1] = -1
        want = [int(ref.update(("k", k), s, None if ti < 0 else ti, period)) for (k, s), ti in zip(pairs, t.tolist())]
    half = len(pairs) // 2
    with mock.patch.object(sequence, "COMPILED_TRACKING", compiled):
        ev = np.concatenate([
            got.update_many(codes[:half], seqs[:half], lambda c: ("k", c), None if t is None else t[:half],
                            None if t is None else period),
            got.update_many(codes[half:], seqs[half:], lambda c: ("k", c), None if t is None else t[half:],
                            None if t is None else period)])
    assert ev.tolist() == want
    assert (got.gaps, got.lost, got.duplicates, got.late, got.resets) == \
        (ref.gaps, ref.lost, ref.duplicates, ref.late, ref.resets)
    assert got.snapshot() == ref.snapshot()


def test_in_order_stream_decodes_with_array_operations_only():
    """The common case (every key in order or with gaps) never takes the per-number path."""
    cells = np.repeat(np.arange(100, dtype=np.int64), 20)
    seq = np.tile(np.arange(20, dtype=np.int64), 100)
    seq[seq >= 10] += 3  # a gap of three frames in every cell
    batch = SkinSampleBatch(cells, np.ones(2000, np.int64), seq & 0xFF, np.zeros((2000, 3), np.int64),
                            np.arange(2000, dtype=np.int64) + 1)
    dec = SkinCanDecoder()
    calls = []
    dec.tracker._track_slot = lambda *a: calls.append(a)  # the per-number path would record here
    out = dec.decode_frames(encode_can_frames(batch))
    assert not calls and len(out) == 2000
    assert dec.stats.sequence_gaps == 100 and dec.stats.lost_frames == 300
