"""Cutting a skin stream into body part messages: every part at once gives what one part at a time gives.

``SkinStream._cut`` selects the due samples of all body parts with one mask
per modality and splits them by part.  The reference below is the plain
loop: for each part, its due samples taken out of the pending arrays on
their own.  Random reads of several body parts (cells that go silent or
send proximity alone, dropped samples, temperature, backlogs, the final
flush) must give the same messages, field by field, the same counters, and
leave the same samples waiting.
"""

from __future__ import annotations

import dataclasses
from collections import Counter

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_descriptors_ros.codecs.skin import Modality, SkinSampleBatch
from tactile_descriptors_ros.streams.skin import SkinStream

MS = 1_000_000
T0 = 1_700_000_000 * 10**9
CELLS = {1: ("left_hand", "c1"), 2: ("left_hand", "c2"), 5: ("chest", "c5"), 9: ("right_hand", "c9"),
         11: ("right_hand", "c11")}


def _take(pending, sel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    out = pending.t[sel], pending.c[sel], pending.v[sel]
    keep = ~sel
    pending.t, pending.c, pending.v = pending.t[keep], pending.c[keep], pending.v[keep]
    return out


class _OnePartAtATime(SkinStream):
    """The reference cut: each body part's due samples taken on their own, parts in order."""

    def _cut(self, final: bool):
        out = []
        if not (self._acc.t.size or self._force.t.size):
            return out
        n_parts = len(self._parts)
        edges = self._batch_ends(final)  # the same batch edges: only the taking differs
        for k in range(n_parts):
            mask_a = self._part_of[self._acc.c] == k
            mask_f = self._part_of[self._force.c] == k
            mask_p = self._part_of[self._prox.c] == k
            if not (mask_a.any() or mask_f.any()):
                continue
            end = int(edges[k])
            sel_a = mask_a & (self._acc.t < end)
            sel_f = mask_f & (self._force.t < end)
            if not (sel_a.any() or sel_f.any()):
                continue
            sel_p = mask_p & (self._prox.t < end)
            out += self._messages(self._parts[k], _take(self._acc, sel_a), _take(self._force, sel_f),
                                  _take(self._prox, sel_p))
        if len(out) > n_parts:
            out.sort(key=lambda m: m.stamp_ns)
        return out


def _samples(rng: np.random.Generator, span_ms: int) -> tuple[SkinSampleBatch, np.ndarray]:
    """Every cell's samples over ``span_ms`` (accelerometer 1 kHz, force and proximity 250 Hz, temperature
    10 Hz), some cells silent for a while or sending proximity alone, some samples dropped; arrival order by
    sample time."""
    rows = []
    for cid in CELLS:
        quiet = sorted(rng.integers(0, span_ms, 2).tolist()) if rng.random() < 0.4 else (0, 0)
        late = int(rng.integers(0, 30)) if rng.random() < 0.3 else 0  # a cell that starts late
        # a stretch where only proximity (and temperature) comes: nothing of its part may go out for it
        prox_only = sorted(rng.integers(0, span_ms, 2).tolist()) if rng.random() < 0.5 else (0, 0)
        for ms in range(late, span_ms):
            if quiet[0] <= ms < quiet[1]:
                continue
            alone = prox_only[0] <= ms < prox_only[1]
            mods = [] if alone else [Modality.ACCEL]
            if ms % 4 == 0:
                mods += [Modality.PROXIMITY] if alone else [Modality.FORCE, Modality.PROXIMITY]
            if ms % 100 == 0:
                mods.append(Modality.TEMPERATURE)
            for m in mods:
                if rng.random() < 0.02:
                    continue  # dropped on the bus
                period = {Modality.ACCEL: 1, Modality.TEMPERATURE: 100}.get(m, 4)
                rows.append((ms, cid, int(m), (ms // period) % 256, rng.integers(0, 1000, 3).tolist()))
    rows.sort(key=lambda r: r[0])
    ms = np.array([r[0] for r in rows], np.int64)
    batch = SkinSampleBatch(np.array([r[1] for r in rows], np.int64), np.array([r[2] for r in rows], np.int64),
                            np.array([r[3] for r in rows], np.int64), np.array([r[4] for r in rows], np.int64),
                            T0 + ms * MS)
    return batch, ms


def _take_rows(batch: SkinSampleBatch, sel: np.ndarray) -> SkinSampleBatch:
    return SkinSampleBatch(batch.cell_id[sel], batch.modality[sel], batch.sequence[sel], batch.values[sel],
                           batch.stamp_ns[sel])


def _run(cls, batch: SkinSampleBatch, ms: np.ndarray, reads_ms: list[int], batch_s: float
         ) -> tuple[list, Counter, int]:
    now = {"ns": T0}
    faults: Counter[str] = Counter()
    stream = cls(CELLS, 1000.0, 250.0, batch_s, "clock", 0.0, 0.0, lambda: now["ns"], faults)
    out = []
    lo = 0
    for hi in reads_ms:
        sel = (ms >= lo) & (ms < hi)
        now["ns"] = T0 + hi * MS + 2 * MS
        if sel.any():
            out.append(stream.add_parts(_take_rows(batch, sel), now["ns"]))
        lo = hi
    out.append(stream.flush())
    return out, faults, stream.pending()


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), batch_s=st.sampled_from([0.005, 0.01, 0.05]),
       span_ms=st.integers(20, 400), read_ms=st.lists(st.integers(1, 120), min_size=1, max_size=40))
def test_cutting_every_body_part_at_once_gives_the_messages_of_one_part_at_a_time(seed, batch_s, span_ms, read_ms):
    batch, ms = _samples(np.random.default_rng(seed), span_ms)
    reads = np.cumsum(read_ms).tolist()
    reads = [r for r in reads if r < span_ms] + [span_ms]
    got, got_faults, got_left = _run(SkinStream, batch, ms, reads, batch_s)
    ref, ref_faults, ref_left = _run(_OnePartAtATime, batch, ms, reads, batch_s)
    assert got_faults == ref_faults
    assert got_left == ref_left  # what could not go out (proximity without its force) still waits
    assert [len(r) for r in got] == [len(r) for r in ref]
    sent = 0
    for x, y in zip((m for r in got for m in r), (m for r in ref for m in r)):
        for f in dataclasses.fields(x):
            a, b = getattr(x, f.name), getattr(y, f.name)
            if isinstance(a, np.ndarray):
                assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), f.name
            else:
                assert a == b, f.name
        sent += int(x.accel_count.sum() + x.force_count.sum())
    # every accelerometer and force sample went out, once (nothing was waiting for a start tare)
    assert sent == int(np.isin(batch.modality, [Modality.ACCEL, Modality.FORCE]).sum())
