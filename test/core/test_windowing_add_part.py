"""``Windower.add_part`` (a body part's message in one piece) buffers exactly what ``add_many`` does.

Hypothesis builds messages of runs -- several cells of one body part, runs
of any length, a cell twice in a message, and every fault the windower
counts (duplicate, late, overlapping and unsorted stamps, clock jumps, empty
runs, unknown cells, NaN force, invalid samples) -- and feeds them as one
``PartChunk`` to one windower and as its per-run ``CellChunk`` s to another:
the return values, the faults, every cell's buffers, smoothed force and
contact state, and the windows cut from them are the same, in fixed and
exploration mode (``touching``: a run that starts on its cell's newest stamp;
``repeated``: a stamp twice in a run).  In-order messages take the array path, the others the
per-run reference; both are exercised (the test counts them).  The array
path runs twice: with the compiled intake (``numba_kernel.runs_in_order``,
``append_runs`` and ``explore_runs``) where the compiled backend is loaded,
and with numpy alone; both must give the per-run reference's buffers to the bit.
The windows are cut twice as well: by the compiled cut (``numba_kernel.cut_rows``,
a body part's rows at once) and cell by cell, to the same arrays, layouts and faults.
"""

from __future__ import annotations

from unittest import mock

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_descriptors_ros.core import fast, windowing
from tactile_descriptors_ros.core.robot import load_robot
from tactile_descriptors_ros.core.windowing import PartChunk, Windower

MS = 1_000_000
NAO = load_robot("nao")
PART = NAO.body_part("left_hand")
CELLS = [c.id for c in PART.cells][:4]
UNKNOWN = max(NAO.cell_index()) + 1000

KINDS = ("ok", "ok", "ok", "ok", "ok", "ok", "duplicate", "late", "overlap", "unsorted", "clock_jump", "empty",
         "nan_force", "invalid", "unknown", "repeated", "touching")

messages = st.lists(
    st.lists(st.tuples(st.sampled_from(range(len(CELLS))), st.sampled_from(KINDS), st.integers(1, 24),
                       st.floats(0.0, 3.0)), min_size=1, max_size=6),
    min_size=1, max_size=30,
)


def _messages(spec, seed: int) -> list[PartChunk]:
    """One ``PartChunk`` per message; each cell keeps its own time cursor (accelerometer 1 kHz, force 250 Hz)."""
    rng = np.random.default_rng(seed)
    cursor = {c: 5_000 * MS for c in CELLS}
    prev = {c: None for c in CELLS}
    out = []
    for runs in spec:
        ids, acc, t_a, frc, t_f, force, va, vf, tare, n_a, n_f = [], [], [], [], [], [], [], [], [], [], []
        for k, kind, n, f in runs:
            cid = CELLS[k]
            t0 = cursor[cid]
            if kind == "duplicate" and prev[cid] is not None:
                t0 = prev[cid]
            elif kind in ("late", "overlap") and prev[cid] is not None:
                t0 = prev[cid] - (n * MS if kind == "late" else MS)
            elif kind == "clock_jump":
                t0 = max(0, t0 - 3_000 * MS)
            elif kind == "touching":  # starts on the cell's newest stamp
                t0 -= MS
            ta = t0 + np.arange(0 if kind == "empty" else n, dtype=np.int64) * MS
            if kind == "unsorted" and n > 2:
                ta[[0, 1]] = ta[[1, 0]]
            if kind == "repeated" and n > 2:  # one stamp twice in a row
                ta[2] = ta[1]
            tf = ta[::4].copy()
            fn = f + rng.uniform(-0.2, 0.2, tf.size)  # forces vary within a run: smoothing spans matter
            if kind == "nan_force":
                fn[::2] = np.nan
            ids.append(UNKNOWN if kind == "unknown" else cid)
            acc.append(rng.integers(-512, 512, (3, ta.size)).astype(np.int32))
            frc.append(rng.integers(0, 4096, (3, tf.size)).astype(np.int32))
            t_a.append(ta)
            t_f.append(tf)
            force.append(fn)
            va.append(rng.random(ta.size) > 0.2 if kind == "invalid" else np.ones(ta.size, bool))
            vf.append(rng.random(tf.size) > 0.2 if kind == "invalid" else np.ones(tf.size, bool))
            tare.append(rng.normal(0, 5, 3))
            n_a.append(ta.size)
            n_f.append(tf.size)
            if kind in ("ok", "nan_force", "invalid", "clock_jump") and ta.size:
                prev[cid] = int(ta[0])
                cursor[cid] = max(cursor[cid], int(ta[-1]) + MS) if kind != "clock_jump" else int(ta[-1]) + MS
        out.append(PartChunk(
            cell_ids=np.array(ids, np.int64), vibration_count=np.array(n_a, np.int64),
            deformation_count=np.array(n_f, np.int64), vibration=np.concatenate(acc, axis=1),
            vibration_t_ns=np.concatenate(t_a), deformation=np.concatenate(frc, axis=1),
            deformation_t_ns=np.concatenate(t_f), force_n=np.concatenate(force),
            vibration_valid=np.concatenate(va), deformation_valid=np.concatenate(vf),
            extra=rng.normal(0, 1, (2, sum(n_f))), deformation_tare=np.array(tare)))
    return out


def _plain(a: np.ndarray) -> list:
    """A list that compares NaN equal to NaN."""
    return np.where(np.isnan(a), -1.0, a).tolist() if a.dtype.kind == "f" else a.tolist()


def _state(w: Windower) -> dict:
    cells = {}
    for cid, s in w._cells.items():
        streams = [x.between(-(2**62), 2**62) for x in (s.vib, s.dfm, s.force, s.extra)]
        cells[cid] = ([_plain(a) for trip in streams for a in trip], s.last_force_n, s.hot_until_ns,
                      None if s.tare is None else s.tare.tolist())
    # the samples each buffer row took (what cutting ahead compares against its marks)
    added = {name: [b.added.tolist() for b in part.buffers] for name, part in w._parts.items()}
    return {"faults": dict(w.faults), "latest": w._latest_ns, "cells": list(cells.items()), "added": added}


def _windows(ws) -> list:
    return [(w.start_ns, w.end_ns, w.exploration_id, w.mode,
             {cid: (c.vibration.tolist(), c.vibration_t_ns.tolist(), c.deformation.tolist(),
                    c.deformation_t_ns.tolist(), _plain(c.force_n), c.valid, c.gap,
                    c.invalid_samples) for cid, c in w.cells.items()}) for w in ws]


def _run(chunks: list[PartChunk], mode: str, part: bool):
    w = Windower(NAO, mode=mode, length_s=0.02, hop_s=0.01, min_duration_s=0.0, release_s=0.005,
                 lateness_s=0.0, force_threshold_n=1.0, release_threshold_n=0.5, clock_jump_s=1.0,
                 smooth_s=0.004)
    accepted, windows = [], []
    for chunk in chunks:
        accepted += (w.add_part(chunk).tolist() if part else w.add_many(chunk.chunks()))
        windows += w.poll()
    windows += w.flush()
    return accepted, _windows(windows), _state(w)



@settings(max_examples=150, deadline=None)
@given(messages, st.integers(0, 2**16), st.sampled_from(["fixed", "exploration"]))
def test_add_part_equals_add_many(spec, seed, mode):
    chunks = _messages(spec, seed)
    ref = _run(chunks, mode, part=False)
    for compiled in (True, False):
        with mock.patch.object(windowing, "COMPILED_INTAKE", compiled):  # not monkeypatch: per example
            got = _run(chunks, mode, part=True)
        assert got[0] == ref[0], compiled
        assert got[2] == ref[2], compiled
        assert got[1] == ref[1], compiled


def test_an_in_order_message_takes_the_array_path_and_a_faulty_one_the_reference(monkeypatch):
    """The array path must actually run (not only the per-run reference that add_part falls back to)."""
    w = Windower(NAO, mode="exploration")
    calls = []
    monkeypatch.setattr(w, "add_many", lambda items: calls.append(1) or Windower.add_many(w, items))
    ok = _messages([[(0, "ok", 10, 2.0), (1, "ok", 10, 2.0), (2, "ok", 10, 0.0)]], 1)[0]
    assert w.add_part(ok).tolist() == [True, True, True] and not calls
    assert len(w._cells[CELLS[0]].vib) == 10 and w._cells[CELLS[0]].hot_until_ns is not None
    assert w.add_part(ok).tolist() == [False, False, False] and calls  # the same again: duplicates
    assert w.faults["duplicate"] == 3


class _Counting:
    """The compiled backend's module, recording each call of the intake's functions and what it returned."""

    def __init__(self, module) -> None:
        self.module = module
        self.results: dict[str, list] = {"runs_in_order": [], "append_runs": [], "explore_runs": [],
                                         "trim_rows": [], "add_part_runs": []}

    def __getattr__(self, name: str):
        func = getattr(self.module, name)

        def call(*args):
            out = func(*args)
            self.results[name].append(out)
            return out
        return call


def _counting_kernel(monkeypatch) -> _Counting:
    kernel = fast.kernel_module()
    if kernel is None:
        pytest.skip(f"no compiled backend here ({fast.backend()}): the numpy intake serves, tested above")
    counting = _Counting(kernel)
    monkeypatch.setattr(windowing, "_intake_kernel", lambda: counting)
    return counting


def test_in_order_messages_take_the_compiled_intake(monkeypatch):
    """Once a body part has buffers, an in-order message is checked and written by the compiled intake alone, in
    one call (``add_part_runs``: the checks, the four buffers and, in exploration mode, the hot cells and
    smoothed forces)."""
    counting = _counting_kernel(monkeypatch)
    chunks = _messages([[(0, "ok", 10, 2.0), (1, "ok", 12, 0.5), (2, "ok", 9, 0.0)]] * 3, 7)
    for mode in ("fixed", "exploration"):
        for calls in counting.results.values():
            calls.clear()
        got = _run(chunks, mode, part=True)
        # the first message finds no buffers (numpy checks it, the pass-by-pass intake writes its four buffers
        # compiled); the two after it are written in one call each
        assert counting.results["runs_in_order"] == []
        assert counting.results["append_runs"] == [True] * 4
        assert counting.results["add_part_runs"] == [windowing._WRITTEN] * 2
        # the first message's hot cells and smoothed forces: compiled in exploration mode, none in fixed mode
        assert len(counting.results["explore_runs"]) == (1 if mode == "exploration" else 0)
        assert got == _run(chunks, mode, part=False)


def test_a_run_past_its_rows_capacity_is_written_by_numpy_after_making_room(monkeypatch):
    counting = _counting_kernel(monkeypatch)
    w = Windower(NAO, mode="fixed", length_s=0.02, hop_s=0.01, lateness_s=0.0)
    cap = w.buffer_capacity(CELLS[0])[0]
    chunks = _messages([[(0, "ok", 24, 2.0)], [(0, "ok", 24, 2.0), (1, "ok", cap + 50, 2.0)]], 3)
    got = _run(chunks, "fixed", part=True)
    # the long run did not fit: nothing written in one call, nor pass by pass, and numpy grew the rows
    assert counting.results["add_part_runs"] == [windowing._NO_ROOM]
    assert False in counting.results["append_runs"]
    assert got == _run(chunks, "fixed", part=False)


def test_the_compiled_intake_takes_only_the_arrays_it_was_compiled_for(monkeypatch):
    """Other dtypes, non-contiguous and read-only arrays take the numpy path (a compiled variant of their own
    would be compiled while a node runs); transposed samples are made contiguous first."""
    counting = _counting_kernel(monkeypatch)
    first, second = _messages([[(0, "ok", 10, 2.0)], [(0, "ok", 10, 2.0)]], 5)
    base = Windower(NAO, mode="fixed")
    base.add_part(first)
    part = base._parts[PART.name]
    rows = np.zeros(1, np.int64)
    counts = np.array([10], np.int64)
    t = second.vibration_t_ns
    for kind in ("int16", "readonly", "strided_t", "transposed"):
        buf = part.vib
        values = second.vibration.copy()
        stamps = t.copy()
        if kind == "int16":
            values = values.astype(np.int16)
        elif kind == "readonly":
            values.flags.writeable = False
        elif kind == "strided_t":
            stamps = np.repeat(t, 2)[::2]
        else:
            values = np.asfortranarray(values)
        before = len(counting.results["append_runs"])
        hi = buf.hi.copy()
        assert buf._append_compiled(rows, counts, stamps, values, None) is (kind == "transposed"), kind
        assert len(counting.results["append_runs"]) == before + (kind == "transposed"), kind
        if kind == "transposed":
            assert buf.t[0, hi[0]:hi[0] + 10].tolist() == t.tolist()
            assert buf.v[:, 0, hi[0]:hi[0] + 10].tolist() == second.vibration.tolist()


def _same(a: list[float], b: list[float]) -> bool:
    """Equal to the bit, NaN equal to NaN."""
    return np.array_equal(np.asarray(a, float), np.asarray(b, float), equal_nan=True)


@settings(max_examples=100, deadline=None)
@given(messages, st.integers(0, 2**16), st.sampled_from([0.0, 0.004, 0.02, 0.2]),
       st.lists(st.floats(-0.1, 1.1), min_size=1, max_size=8))
def test_forces_of_a_body_part_at_once_equal_each_cells_own(spec, seed, smooth_s, where):
    """``_forces_at`` (a body part's cells as one array) gives each cell's ``_force_at`` to the bit.

    At times before, inside and after the cells' force stamps, with NaN force,
    cells far ahead of the time (the look falls back to the cell alone) and
    smoothing spans from none to 50 force samples.
    """
    w = Windower(NAO, mode="exploration", smooth_s=smooth_s, min_duration_s=0.0, release_s=0.005,
                 force_threshold_n=1.0, release_threshold_n=0.5, clock_jump_s=1.0)
    for chunk in _messages(spec, seed):
        w.add_part(chunk)
    part = w._parts.get(PART.name)
    if part is None:
        return
    rows = np.flatnonzero(part.force.hi > part.force.lo)
    if not rows.size:
        return
    buf = part.force
    stamps = np.concatenate([buf.t[r, buf.lo[r]:buf.hi[r]] for r in rows.tolist()])
    lo, hi = int(stamps.min()), int(stamps.max())
    pick = [stamps[int(abs(x) * 1e6) % stamps.size] for x in where]
    times = [lo + int(x * (hi - lo)) for x in where] + pick + [int(p) + w.smooth_ns for p in pick]
    for t_ns in times:  # anywhere, on a stamp, and a smoothing span after one (a span starting on it)
        own = [w._force_at(w._cells[part.cell_ids[r]], t_ns) for r in rows.tolist()]
        assert _same(w._forces_at(part, rows, t_ns), own)


def test_forces_of_a_body_part_at_the_watermark_take_the_array_path(monkeypatch):
    """At the watermark (every cell's newest sample at it or a message after) no cell is looked at alone but
    one whose force is all NaN; a cell far ahead of the time is (the hypothesis test above covers that)."""
    w = Windower(NAO, mode="exploration")
    spec = [[(0, "ok", 12, 2.0 + k), (1, "ok", 12, 0.3 * k), (2, "ok", 12, float("nan")), (3, "ok", 12, 1.0)]
            for k in range(20)]
    spec.append([(0, "ok", 12, 3.0), (1, "ok", 12, 3.0), (2, "ok", 12, float("nan"))])  # ahead of cell 3
    for chunk in _messages(spec, 3):
        w.add_part(chunk)
    part = w._parts[PART.name]
    rows = np.flatnonzero(part.force.hi > part.force.lo)
    t_ns = w._watermark()
    assert (part.force.last[rows] > t_ns).sum() == 3
    own = [w._force_at(w._cells[part.cell_ids[r]], t_ns) for r in rows.tolist()]
    alone = []
    monkeypatch.setattr(w, "_force_at", lambda st, t: alone.append(st) or Windower._force_at(w, st, t))
    assert _same(w._forces_at(part, rows, t_ns), own)
    assert len(alone) == 1  # only the cell whose force is all NaN: nothing finite to average


def _cut_windows(chunks: list[PartChunk], mode: str) -> tuple[list, dict]:
    """Every window's cells, each array with its dtype and layout, and the faults after the last poll."""
    w = Windower(NAO, mode=mode, length_s=0.02, hop_s=0.01, min_duration_s=0.0, release_s=0.005,
                 lateness_s=0.0, force_threshold_n=1.0, release_threshold_n=0.5, clock_jump_s=1.0,
                 smooth_s=0.004)
    windows = []
    for chunk in chunks:
        w.add_part(chunk)
        windows += w.poll()
    windows += w.flush()

    def arr(a):
        return None if a is None else (_plain(a), a.dtype.str, a.shape, a.flags.c_contiguous)
    out = [(x.start_ns, x.end_ns, x.exploration_id, x.mode,
            [(cid, [arr(getattr(c, f)) for f in ("vibration", "vibration_t_ns", "deformation", "deformation_t_ns",
                                                 "force_n", "extra", "deformation_tare")],
              c.valid, c.gap, c.invalid_samples) for cid, c in x.cells.items()]) for x in windows]
    return out, dict(w.faults)


@settings(max_examples=150, deadline=None)
@given(messages, st.integers(0, 2**16), st.sampled_from(["fixed", "exploration"]))
def test_compiled_cut_equals_the_per_cell_cut(spec, seed, mode):
    if fast.kernel_module() is None:
        pytest.skip(f"no compiled backend here ({fast.backend()}): the per-cell cut serves")
    chunks = _messages(spec, seed)
    with mock.patch.object(windowing, "COMPILED_CUT", False):
        ref = _cut_windows(chunks, mode)
    with mock.patch.object(windowing, "COMPILED_CUT", True):
        got = _cut_windows(chunks, mode)
    assert got == ref


def test_windows_are_cut_by_the_compiled_cut(monkeypatch):
    """A window of clean samples is cut by ``cut_rows`` (once per buffer of each body part), not cell by cell."""
    kernel = fast.kernel_module()
    if kernel is None:
        pytest.skip(f"no compiled backend here ({fast.backend()}): the per-cell cut serves")
    calls = []

    class Spy:
        def __getattr__(self, name):
            if name == "cut_rows":
                return lambda *a: calls.append(a) or kernel.cut_rows(*a)
            return getattr(kernel, name)
    monkeypatch.setattr(windowing.fast, "kernel_module", Spy)
    per_cell = []
    monkeypatch.setattr(Windower, "_cell_window", lambda self, *a: per_cell.append(a))
    chunks = _messages([[(0, "ok", 12, 2.0), (1, "ok", 12, 2.0), (2, "ok", 12, 2.0)]] * 4, 3)
    windows, _ = _cut_windows(chunks, "fixed")
    assert windows and all(len(x[4]) == 3 for x in windows)
    assert len(calls) == 4 * len(windows)  # vibration, deformation, extra and force of the one body part
    assert not per_cell
    assert len(kernel.cut_rows.signatures) == 1  # the one variant make setup compiles (fast.warm_up)


OTHER = [c.id for c in NAO.body_part("right_hand").cells][:4]


def _watermark_as_fresh(w: Windower) -> None:
    """The watermark and live rows from each body part's remembered held rows equal those worked out afresh."""
    got = w._watermark()
    live = [(p, rows.tolist()) for p, rows in w._live_rows]
    for p in w._parts.values():
        p._held = None
    assert w._watermark() == got
    assert [(p, rows.tolist()) for p, rows in w._live_rows] == live


@settings(max_examples=100, deadline=None)
@given(messages, st.integers(0, 2**16), st.booleans())
def test_the_watermark_from_remembered_rows_equals_one_worked_out_afresh(spec, seed, part):
    """Each body part remembers its rows holding force and their newest stamps while its force buffer keeps its
    version; through two body parts' messages in turn, every fault, polls that trim rows empty and stalls,
    the watermark and live rows are those of a windower that forgets them."""
    chunks = []
    for c in _messages(spec, seed):
        other = np.array([OTHER[CELLS.index(i)] if i in CELLS else i for i in c.cell_ids.tolist()], np.int64)
        chunks += [c, PartChunk(**{**c.__dict__, "cell_ids": other})]
    w = Windower(NAO, mode="exploration", length_s=0.02, hop_s=0.01, min_duration_s=0.0, release_s=0.005,
                 lateness_s=0.0, force_threshold_n=1.0, release_threshold_n=0.5, clock_jump_s=1.0,
                 smooth_s=0.004)
    for chunk in chunks:
        if part:
            w.add_part(chunk)
        else:
            w.add_many(chunk.chunks())
        _watermark_as_fresh(w)
        w.poll()
        _watermark_as_fresh(w)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.lists(st.integers(0, 5), max_size=12), min_size=1, max_size=6),
       st.lists(st.integers(-5, 70), min_size=1, max_size=4))
def test_a_compiled_trim_equals_numpys(steps, cuts):
    """``_RowBuffer.trim_before`` by the compiled pass (``numba_kernel.trim_rows``) and by numpy: the same rows'
    starts, ends and ``has`` flags after each of several trims, rows with repeated stamps, empty rows and rows
    trimmed empty among them, and the buffer's version moved exactly when a row lost samples."""
    if fast.kernel_module() is None:
        pytest.skip("no compiled backend (TACTILE_NO_NUMBA or numba missing)")
    bufs = []
    for _ in range(2):
        buf = windowing._RowBuffer(len(steps), 1, np.float64, 4)
        for r, row in enumerate(steps):
            if row:
                t = np.cumsum(np.array(row, np.int64))  # non-decreasing: a stamp may repeat
                buf.append(r, t, np.zeros((1, t.size)))
        bufs.append(buf)
    for t_ns in sorted(cuts):
        got = []
        for buf, compiled in zip(bufs, (True, False)):
            before = buf.version
            with mock.patch.object(windowing, "COMPILED_INTAKE", compiled):
                buf.trim_before(t_ns)
            got.append((buf.lo.tolist(), buf.hi.tolist(), buf.has.tolist(), buf.version != before))
        assert got[0] == got[1], t_ns
    # every sample left is not older than the last trim; every one dropped was
    for r in range(len(steps)):
        kept = bufs[0].t[r, bufs[0].lo[r]:bufs[0].hi[r]]
        assert (kept >= max(cuts)).all()
        dropped = bufs[0].t[r, :bufs[0].lo[r]]
        assert (dropped < max(cuts)).all()
