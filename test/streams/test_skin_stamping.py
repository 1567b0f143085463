"""A skin stream's ``clock`` stamping in one compiled pass gives what its numpy code gives.

``SkinStream._add_batch`` hands a read's samples, once the sequence tracker
has unwrapped them, to ``numba_kernel.skin_clock_add`` (lost frames, the
device clocks' offsets, stamps, samples stepping back, per-cell counters,
remembered force, the pending samples).  Two streams read the same damaged
reads, one each way: after every read their messages, fault counters and
every array of their state must be equal, bit for bit.  The reads have
dropped, repeated and reordered frames, wrapping sequence numbers, cells that
go silent, a host clock whose delay jumps up and down (offsets that rise, fall
and re-anchor, samples that step back) and a start tare that ends mid-run.
"""

from __future__ import annotations

import dataclasses
from collections import Counter
from unittest import mock

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_descriptors_ros.codecs.skin import NO_STAMP, Modality, SkinSampleBatch
from tactile_descriptors_ros.core import fast
from tactile_descriptors_ros.streams import skin as skin_stream
from tactile_descriptors_ros.streams.skin import SkinStream

pytestmark = pytest.mark.skipif(fast.kernel_module() is None, reason="the compiled backend is not loaded")

MS = 1_000_000
T0 = 1_700_000_000 * 10**9
CELLS = {1: ("left_hand", "c1"), 2: ("left_hand", "c2"), 5: ("chest", "c5"), 9: ("right_hand", "c9")}
PERIOD_MS = {Modality.ACCEL: 1, Modality.FORCE: 4, Modality.PROXIMITY: 4, Modality.TEMPERATURE: 100}
#: every array of a stream's state the stamping writes (``_last_mono`` holds the monotonic clock: compared as seen
#: or not)
STATE = ("_lost", "_lost_since", "_samples", "_temperature", "_first_t", "_has_first", "_last_a", "_has_a",
         "_last_f", "_has_f", "_recent_t", "_recent_v", "_recent_pos", "_recent_n", "_tared", "_tare", "_runs")
CLOCK = ("offset_ns", "anchored", "_last_dev", "_high_since", "_high_min", "last_excess_ns", "resyncs",
         "observations")


def _rows(rng: np.random.Generator, span_ms: int) -> list[tuple[int, int, int, int, list[int], int]]:
    """(arrival ms, cell, modality, 8-bit sequence number, values, sample ms) of every cell over ``span_ms``,
    damaged:
    frames dropped, repeated or arriving late, cells silent for a while, modalities starting late."""
    rows = []
    for cid in CELLS:
        quiet = sorted(rng.integers(0, span_ms, 2).tolist()) if rng.random() < 0.4 else (0, 0)
        # a modality that starts late (a cell whose first frames are its temperature's)
        late = int(rng.integers(1, span_ms)) if rng.random() < 0.3 else 0
        start = {m: late if m != Modality.TEMPERATURE else 0 for m in PERIOD_MS}
        start.update({m: int(rng.integers(0, span_ms)) for m in PERIOD_MS if rng.random() < 0.1})
        for ms in range(span_ms):
            if quiet[0] <= ms < quiet[1]:
                continue
            for m, period in PERIOD_MS.items():
                if ms % period or ms < start[m] or rng.random() < 0.03:
                    continue
                seq = (ms // period) % 256
                vals = rng.integers(0, 4000, 3).tolist()
                late = int(rng.integers(1, 12)) if rng.random() < 0.02 else 0
                rows.append((ms + late, cid, int(m), seq, vals, ms))
                if rng.random() < 0.01:  # a repeated frame
                    rows.append((ms + late, cid, int(m), seq, vals, ms))
    rows.sort(key=lambda r: r[0])
    return rows


def _batch(rows, bus_times: np.ndarray | None = None) -> SkinSampleBatch:
    """The rows as a decoded read; a row's bus time is its sample time where ``bus_times`` says so, else none."""
    stamps = np.full(len(rows), NO_STAMP, np.int64)
    if bus_times is not None:
        stamps[bus_times] = T0 + np.array([r[5] for r in rows], np.int64)[bus_times] * MS
    return SkinSampleBatch(np.array([r[1] for r in rows], np.int64), np.array([r[2] for r in rows], np.int64),
                           np.array([r[3] for r in rows], np.int64), np.array([r[4] for r in rows], np.int64),
                           stamps)


def _same_message(x, y) -> None:
    for f in dataclasses.fields(x):
        a, b = getattr(x, f.name), getattr(y, f.name)
        if isinstance(a, np.ndarray):
            assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes(), f.name
        else:
            assert a == b, f.name


def _same_state(a: SkinStream, b: SkinStream) -> None:
    for name in STATE:
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), name
    assert np.array_equal(np.isnan(a._last_mono), np.isnan(b._last_mono))
    for name in CLOCK:
        assert np.array_equal(getattr(a.clock, name), getattr(b.clock, name)), name
    for name, x in a._clk.items():
        assert np.array_equal(x, b._clk[name]), name
    for name in ("_acc", "_force", "_prox"):
        p, q = getattr(a, name), getattr(b, name)
        for part in ("t", "c", "v"):
            x, y = getattr(p, part), getattr(q, part)
            assert x.dtype == y.dtype and x.shape == y.shape and np.array_equal(x, y), (name, part)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), span_ms=st.integers(30, 600),
       read_ms=st.lists(st.integers(1, 40), min_size=1, max_size=60),
       delay_ms=st.lists(st.integers(0, 1500), min_size=1, max_size=8),
       resync_s=st.sampled_from([0.0, 0.05, 1.0]), confirm_ms=st.sampled_from([0, 20, 5000]),
       tare_s=st.sampled_from([0.0, 0.03]), batch_s=st.sampled_from([0.005, 0.01]),
       source=st.sampled_from(["clock", "device"]))
def test_compiled_stamping_equals_numpy(seed, span_ms, read_ms, delay_ms, resync_s, confirm_ms, tare_s, batch_s,
                                        source):
    """``device`` reads carry bus times on most rows, none on some, or none at all in a read (an adapter
    without times): the stream extrapolates those in numpy before the pass."""
    rng = np.random.default_rng(seed)
    rows = _rows(rng, span_ms)
    arrival = np.array([r[0] for r in rows], np.int64)
    reads = [r for r in np.cumsum(read_ms).tolist() if r < span_ms + 12] + [span_ms + 12]
    now = {"ns": T0}
    streams = {}
    for compiled in (True, False):
        faults: Counter[str] = Counter()
        s = SkinStream(CELLS, 1000.0, 250.0, batch_s, source, resync_s, tare_s, lambda: now["ns"], faults)
        s.clock.confirm_ns = confirm_ms * MS
        streams[compiled] = (s, faults)
    used = with_samples = 0
    lo = 0
    for k, hi in enumerate(reads):
        sel = (arrival >= lo) & (arrival < hi)
        lo = hi
        if not sel.any():
            continue
        with_samples += 1
        # the host clock's delay over the device's steps between a few levels: offsets fall, rise, re-anchor
        now["ns"] = T0 + (hi + delay_ms[k % len(delay_ms)]) * MS
        taken = [r for r, s in zip(rows, sel) if s]
        batch = _batch(taken, None if rng.random() < 0.2 else rng.random(len(taken)) < 0.9)
        out = {}
        for compiled, (s, _) in streams.items():
            with mock.patch.object(skin_stream, "COMPILED_STAMPING", compiled), \
                    mock.patch.object(s, "_add_compiled", wraps=s._add_compiled) as spy:
                out[compiled] = s.add_parts(batch, now["ns"])
            used += spy.call_count
            if not compiled:
                assert spy.call_count == 0
        assert len(out[True]) == len(out[False])
        for x, y in zip(out[True], out[False]):
            _same_message(x, y)
        assert streams[True][1] == streams[False][1]
        _same_state(streams[True][0], streams[False][0])
    if tare_s == 0:  # nothing waits for a start tare: every read took the compiled pass
        assert used == with_samples
    final = [s.flush() for s, _ in streams.values()]
    assert len(final[0]) == len(final[1])
    for x, y in zip(*final):
        _same_message(x, y)


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "numpy"])
def test_steps_back_and_resyncs_known_answers(compiled):
    """One cell's accelerometer read three times.  The second read's host time is 3 ms earlier relative to
    its samples (the delay fell): the offset drops by 3 ms, and the new samples that would be stamped at or
    before the last one are dropped and counted.  The third read is 2.48 s late, above the 1 s jump, and
    ``confirm_ns`` 0 re-anchors the key at once."""
    now = {"ns": T0}
    faults: Counter[str] = Counter()
    s = SkinStream({1: ("p", "c1")}, 1000.0, 250.0, 1.0, "clock", 1.0, 0.0, lambda: now["ns"], faults)
    s.clock.confirm_ns = 0

    def read(first_seq: int, n: int, host_ms: int) -> list:
        rows = [(0, 1, int(Modality.ACCEL), (first_seq + i) % 256, [1, 2, 3], 0) for i in range(n)]
        now["ns"] = T0 + host_ms * MS
        return s.add_parts(_batch(rows))  # no arrival time: the tracker unwraps by the numbers alone

    with mock.patch.object(skin_stream, "COMPILED_STAMPING", compiled):
        assert read(0, 10, 20) == []  # device 0..9 ms, read at 20 ms: offset 11 ms, stamps 11..20 (1 s batches)
        assert read(10, 5, 22) == []  # device 10..14 ms, read at 22: offset 8 ms, stamps 18..22; 18, 19, 20 step back
        assert faults["clock_step_back_samples"] == 3
        assert s._acc.t.tolist() == [T0 + (11 + i) * MS for i in range(10)] + [T0 + 21 * MS, T0 + 22 * MS]
        read(15, 5, 2_500)  # the first batch goes out
        assert faults["clock_resync"] == 1
        assert s.clock.offset_ns[0] == T0 + 2_500 * MS - 19 * MS


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "numpy"])
def test_a_lasting_excess_re_anchors_at_its_least_observation(compiled):
    """Observations (host - device time) above the estimate by more than the 1 s jump for ``confirm_ns``
    (20 ms) re-anchor the key at the least of them, not the first or the last."""
    now = {"ns": T0}
    faults: Counter[str] = Counter()
    s = SkinStream({1: ("p", "c1")}, 1000.0, 250.0, 1.0, "clock", 1.0, 0.0, lambda: now["ns"], faults)
    s.clock.confirm_ns = 20 * MS

    def read(first_seq: int, host_ms: int) -> None:
        rows = [(0, 1, int(Modality.ACCEL), (first_seq + i) % 256, [1, 2, 3], 0) for i in range(10)]
        now["ns"] = T0 + host_ms * MS
        s.add_parts(_batch(rows))

    with mock.patch.object(skin_stream, "COMPILED_STAMPING", compiled):
        read(0, 10)  # device 0..9 ms: observation 1 ms, the estimate
        read(10, 1_520)  # device 19 ms: 1,501 ms, the excess starts
        read(40, 1_530)  # 20 frames lost, device 49 ms: 1,481 ms, the least; 10 ms of excess
        assert faults["clock_resync"] == 0
        assert s.clock.offset_ns[0] < T0 + 2 * MS
        read(50, 1_550)  # device 59 ms: 1,491 ms; 30 ms of excess: re-anchored at 1,481 ms
    assert faults["clock_resync"] == 1
    assert s.clock.offset_ns[0] == T0 + 1_481 * MS


def test_the_stamping_runs_one_variant_the_drivers_warm_up_loads():
    """Clock and device stamps, a first read and later ones take the variant that ``load_compiled`` (the
    driver, before it opens its bus) and ``make setup`` load: no compiling while a driver runs."""
    kernel = fast.kernel_module()
    assert skin_stream.load_compiled() is True
    before = list(kernel.skin_stamp_add.signatures)
    rows = _rows(np.random.default_rng(3), 60)
    for source in ("clock", "device"):
        s = SkinStream(CELLS, 1000.0, 250.0, 0.01, source, 1.0, 0.0, lambda: T0 + 70 * MS, Counter())
        with mock.patch.object(s, "_add_compiled", wraps=s._add_compiled) as spy:
            s.add_parts(_batch(rows[: len(rows) // 2], np.ones(len(rows) // 2, bool)))
            s.add_parts(_batch(rows[len(rows) // 2:]))
        assert spy.call_count == 2
    assert kernel.skin_stamp_add.signatures == before and len(before) == 1
