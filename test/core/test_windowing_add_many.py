"""``Windower.add_many`` buffers exactly what repeated ``Windower.add`` does.

Hypothesis drives both with the same stream of chunks -- several cells,
batches of any size, and every fault the windower counts (unknown cell, bad
shape, empty, duplicate, out of order, unsorted stamps, clock jumps, NaN
force, invalid samples) -- and compares the return values, the counted
faults, every cell's buffers and the windows cut from them, in fixed and
exploration mode.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_descriptors_ros.core.robot import load_robot
from tactile_descriptors_ros.core.windowing import CellChunk, Windower
from tactile_descriptors_ros.errors import SignalError

MS = 1_000_000
NAO = load_robot("nao")
CELLS = sorted(NAO.cell_index())[:3]
UNKNOWN = max(NAO.cell_index()) + 1000

KINDS = ("ok", "ok", "ok", "ok", "duplicate", "late", "overlap", "unsorted", "clock_jump", "empty",
         "bad_shape", "nan_force", "invalid", "no_force", "unknown")

events = st.lists(
    st.tuples(st.sampled_from(range(len(CELLS))), st.sampled_from(KINDS), st.integers(1, 24),
              st.floats(0.0, 3.0), st.booleans()),
    min_size=1, max_size=60,
)


def _chunks(spec, seed: int) -> list[tuple[int, CellChunk, bool]]:
    """(cell_id, chunk, end of batch) for each event; each cell keeps its own time cursor."""
    rng = np.random.default_rng(seed)
    cursor = {c: 5_000 * MS for c in CELLS}
    prev = {c: None for c in CELLS}
    out = []
    for k, kind, n, force, batch_end in spec:
        cid = CELLS[k]
        t0 = cursor[cid]
        if kind == "duplicate" and prev[cid] is not None:
            t0 = prev[cid]
        elif kind in ("late", "overlap") and prev[cid] is not None:
            t0 = prev[cid] - (n * MS if kind == "late" else MS)
        elif kind == "clock_jump":
            t0 = max(0, t0 - 3_000 * MS)
        t_a = t0 + np.arange(n, dtype=np.int64) * MS  # 1 kHz accelerometer
        if kind == "unsorted" and n > 2:
            t_a[[0, 1]] = t_a[[1, 0]]
        if kind == "empty":
            t_a = t_a[:0]
        t_f = t_a[::4].copy()  # 250 Hz force
        acc = rng.integers(-512, 512, (2 if kind == "bad_shape" else 3, t_a.size)).astype(np.int32)
        frc = rng.integers(0, 4096, (3, t_f.size)).astype(np.int32)
        force_n = np.full(t_f.size, force)
        if kind == "nan_force":
            force_n[::2] = np.nan
        if kind == "no_force":
            t_f, force_n = t_f[:0], force_n[:0]
        valid_a = valid_f = None
        if kind == "invalid":
            valid_a = rng.random(t_a.size) > 0.2
            valid_f = rng.random(t_f.size) > 0.2
        chunk = CellChunk(acc, t_a, frc, t_a[::4].copy(), force_n, t_f, valid_a, valid_f)
        out.append((UNKNOWN if kind == "unknown" else cid, chunk, batch_end))
        if kind in ("ok", "nan_force", "invalid", "no_force", "clock_jump") and t_a.size:
            prev[cid] = int(t_a[0])
            cursor[cid] = max(cursor[cid], int(t_a[-1]) + MS) if kind != "clock_jump" else int(t_a[-1]) + MS
    return out


def _plain(a: np.ndarray) -> list:
    """A list that compares NaN equal to NaN."""
    return np.where(np.isnan(a), -1.0, a).tolist() if a.dtype.kind == "f" else a.tolist()


def _state(w: Windower) -> dict:
    cells = {}
    for cid, s in w._cells.items():
        streams = [x.between(-(2**62), 2**62) for x in (s.vib, s.dfm, s.force)]
        cells[cid] = ([_plain(a) for trip in streams for a in trip], s.last_force_n)
    return {"faults": dict(w.faults), "latest": w._latest_ns, "cells": cells}


def _windows(ws) -> list:
    return [(w.start_ns, w.end_ns, w.exploration_id, w.mode,
             {cid: (c.vibration.tolist(), c.vibration_t_ns.tolist(), c.deformation.tolist(),
                    c.deformation_t_ns.tolist(), _plain(c.force_n), c.valid, c.gap,
                    c.invalid_samples) for cid, c in w.cells.items()}) for w in ws]


def _run(chunks, mode: str, many: bool):
    w = Windower(NAO, mode=mode, length_s=0.02, hop_s=0.01, min_duration_s=0.0, release_s=0.005,
                 lateness_s=0.0, force_threshold_n=1.0, release_threshold_n=0.5, clock_jump_s=1.0,
                 smooth_s=0.004)
    accepted, windows, batch = [], [], []
    for cid, chunk, end in chunks:
        batch.append((cid, chunk))
        if end:
            accepted += w.add_many(batch) if many else [w.add(c, ch) for c, ch in batch]
            windows += w.poll()
            batch = []
    accepted += w.add_many(batch) if many else [w.add(c, ch) for c, ch in batch]
    windows += w.poll() + w.flush()
    return accepted, _windows(windows), _state(w)


@settings(max_examples=150, deadline=None)
@given(events, st.integers(0, 2**16), st.sampled_from(["fixed", "exploration"]))
def test_add_many_equals_repeated_add(spec, seed, mode):
    chunks = _chunks(spec, seed)
    one = _run(chunks, mode, many=False)
    many = _run(chunks, mode, many=True)
    assert many[0] == one[0]
    assert many[2] == one[2]
    assert many[1] == one[1]


def test_add_many_counts_each_fault_like_add():
    w = Windower(NAO, mode="fixed", length_s=1.0, hop_s=0.5)
    t = np.arange(10, dtype=np.int64) * MS
    acc = np.zeros((3, 10), np.int32)
    frc = np.zeros((3, 3), np.int32)
    good = CellChunk(acc, t, frc, t[::4], np.ones(3), t[::4])
    unsorted = CellChunk(acc, t[::-1].copy(), frc, t[::4], np.ones(3), t[::4])
    later = CellChunk(acc, t + 10 * MS, frc, t[::4] + 10 * MS, np.ones(3), t[::4] + 10 * MS)
    got = w.add_many([(CELLS[0], good), (CELLS[1], unsorted), (CELLS[0], good), (UNKNOWN, good),
                      (CELLS[0], later), (CELLS[1], good)])
    assert got == [True, False, False, False, True, True]
    assert w.faults == {"unsorted_stamps": 1, "duplicate": 1, "unknown_cell": 1}
    assert w.add_many([]) == []
    assert w.add_many({CELLS[2]: good}.items()) == [True]


def test_add_many_raises_like_add_and_keeps_the_items_before():
    w = Windower(NAO, mode="fixed", length_s=1.0, hop_s=0.5)
    t = np.arange(10, dtype=np.int64) * MS
    good = CellChunk(np.zeros((3, 10), np.int32), t, np.zeros((3, 3), np.int32), t[::4], np.ones(3), t[::4])
    bad = CellChunk(np.zeros((3, 9), np.int32), t, np.zeros((3, 3), np.int32), t[::4], np.ones(3), t[::4])
    with pytest.raises(SignalError):
        w.add_many([(CELLS[0], good), (CELLS[1], bad)])
    assert len(w._cells[CELLS[0]].vib) == 10
