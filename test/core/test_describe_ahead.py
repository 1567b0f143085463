"""An exploration's window described during its release time: the same descriptor, or described again."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tactile_descriptors_ros.core.aggregation import CellSignals, describe_window
from tactile_descriptors_ros.core.ahead import DescribeAhead, same_window
from tactile_descriptors_ros.core.robot import load_robot
from tactile_descriptors_ros.core.windowing import CellChunk, PartChunk, Windower, rehearsal_window

MS = 1_000_000


def _chunk(t0_ns: int, force_n: float, rng, tare=None) -> CellChunk:
    """100 ms of one BioTac: 10 frames of 19 electrodes, 22 PAC samples each."""
    frame_t = t0_ns + np.arange(10, dtype=np.int64) * 10 * MS
    pac_t = (frame_t[:, None] + (np.arange(22) * 10 * MS) // 22).ravel()
    return CellChunk(rng.integers(0, 4096, (1, pac_t.size)), pac_t, rng.integers(0, 4096, (19, 10)),
                     frame_t, np.full(10, force_n), frame_t, deformation_tare=tare)


def _describe(robot):
    def describe(window):
        return describe_window(robot, window.cells, stacks=window.stacks).values
    return describe


def _run(schedule, *, ahead: bool, seed: int = 0, tare_after_s: float | None = None):
    """Feed one finger 100 ms chunks of ``schedule`` [(seconds, force_n)], polling after each as the window node
    does; returns (descriptors published, the DescribeAhead, the windower, polls at which a description was made
    ahead)."""
    robot = load_robot("shadow_hand")
    w = Windower(robot, mode="exploration", min_duration_s=0.5)
    describe = _describe(robot)
    keeper = DescribeAhead(describe)
    rng = np.random.default_rng(seed)
    out, made_at, t = [], [], 0
    for seconds, force in schedule:
        for _ in range(int(round(seconds * 10))):
            tare = np.full(19, 7.0) if tare_after_s is not None and t >= tare_after_s * 1e9 else None
            w.add(1, _chunk(t, force, rng, tare))
            for win in w.poll():
                got = keeper.take(win) if ahead else None
                out.append((win.start_ns, win.end_ns, got if got is not None else describe(win)))
            if ahead and keeper.offer(w):
                made_at.append(t)
            t += 100 * MS
    return out, keeper, w, made_at


def _bits(values: np.ndarray) -> bytes:
    return np.ascontiguousarray(values, np.float64).tobytes()


def test_a_window_described_ahead_is_published_with_the_same_bits_and_earlier():
    schedule = [(1.0, 0.0), (2.0, 1.0), (1.0, 0.0), (1.5, 2.0), (1.0, 0.0)]
    with_ahead, keeper, w, made_at = _run(schedule, ahead=True)
    without, *_ = _run(schedule, ahead=False)
    assert [(a, b) for a, b, _ in with_ahead] == [(a, b) for a, b, _ in without] == \
        [(1000 * MS, 3000 * MS), (4000 * MS, 5500 * MS)]
    assert [_bits(v) for *_, v in with_ahead] == [_bits(v) for *_, v in without]
    assert keeper.counts() == {"used": 2, "changed": 0, "discarded": 0}
    # described at the poll that first found the finger released, a release time (0.1 s) before the decision
    assert made_at == [3000 * MS, 5500 * MS]
    assert keeper.pending is None


def test_a_touch_again_within_the_release_time_discards_the_description():
    # released for 0.1 s only (one chunk): below release_s + smoothing, so the exploration goes on
    schedule = [(1.0, 0.0), (1.0, 1.0), (0.1, 0.0), (1.0, 1.0), (1.0, 0.0)]
    with_ahead, keeper, _, made_at = _run(schedule, ahead=True)
    without, *_ = _run(schedule, ahead=False)
    assert [(a, b) for a, b, _ in with_ahead] == [(1000 * MS, 3100 * MS)]
    assert [_bits(v) for *_, v in with_ahead] == [_bits(v) for *_, v in without]
    assert keeper.counts() == {"used": 1, "changed": 0, "discarded": 1}
    assert len(made_at) == 2


def test_a_window_whose_samples_changed_after_is_described_again():
    # the driver tares again during the release time: the final window's cell carries the new tare
    schedule = [(1.0, 0.0), (2.0, 1.0), (1.0, 0.0)]
    with_ahead, keeper, _, _ = _run(schedule, ahead=True, tare_after_s=3.1)
    without, *_ = _run(schedule, ahead=False, tare_after_s=3.1)
    assert [_bits(v) for *_, v in with_ahead] == [_bits(v) for *_, v in without]
    assert keeper.counts() == {"used": 0, "changed": 1, "discarded": 0}


def test_cutting_ahead_counts_no_fault_twice():
    """A window with a gap: the cut ahead and the cut at the decision find it; it is counted once."""
    robot = load_robot("shadow_hand")
    rng = np.random.default_rng(3)
    counts = []
    for ahead in (False, True):
        w = Windower(robot, mode="exploration", min_duration_s=0.5)
        keeper = DescribeAhead(_describe(robot))
        t = 0
        for k, force in enumerate([0.0] * 5 + [1.0] * 15 + [0.0] * 10):
            chunk = _chunk(t, force, rng)
            if k == 10:  # 30 ms of PAC missing inside the touch
                keep = (chunk.vibration_t_ns < t + 20 * MS) | (chunk.vibration_t_ns >= t + 50 * MS)
                chunk = dataclasses.replace(chunk, vibration=chunk.vibration[:, keep],
                                            vibration_t_ns=chunk.vibration_t_ns[keep])
            w.add(1, chunk)
            for win in w.poll():
                keeper.take(win)
            if ahead:
                keeper.offer(w)
            t += 100 * MS
        counts.append((dict(w.faults), keeper.used))
    assert counts[0][0]["gap"] == 1 and counts[0][0] == counts[1][0]
    assert counts[1][1] == 1


def test_nothing_is_described_ahead_in_fixed_mode_or_for_an_exploration_too_short_to_keep():
    robot = load_robot("shadow_hand")
    rng = np.random.default_rng(1)
    fixed = Windower(robot, mode="fixed", length_s=0.5, hop_s=0.5)
    short = Windower(robot, mode="exploration", min_duration_s=1.0)
    for w in (fixed, short):
        keeper = DescribeAhead(_describe(robot))
        t = 0
        for force in [0.0] * 5 + [1.0] * 5 + [0.0] * 5:  # a 0.5 s touch
            w.add(1, _chunk(t, force, rng))
            w.poll()
            assert w.closing_exploration() is None and w.cut_ahead() is None and not keeper.offer(w)
            t += 100 * MS


def test_same_window_compares_every_bit_of_every_field():
    assert {f.name for f in dataclasses.fields(CellSignals)} == \
        {"vibration", "vibration_t_ns", "deformation", "deformation_t_ns", "force_n", "valid", "gap",
         "invalid_samples", "extra", "deformation_tare"}, "same_window must compare every field of CellSignals"
    nao = load_robot("nao")
    a = rehearsal_window(nao, 0.5, np.dtype(np.int16), np.dtype(np.uint16), seed=5)
    b = rehearsal_window(nao, 0.5, np.dtype(np.int16), np.dtype(np.uint16), seed=5)
    assert a.stacks is not None and len(a.cells) == nao.n_cells
    assert same_window(a, b)
    cid = list(a.cells)[7]

    def with_cell(**fields):
        c = rehearsal_window(nao, 0.5, np.dtype(np.int16), np.dtype(np.uint16), seed=5)
        c.cells[cid] = dataclasses.replace(c.cells[cid], **fields)  # no longer a row of the stacks
        return c

    cell = a.cells[cid]
    bumped = cell.vibration.copy()
    bumped[1, 3] += 1
    for fields in ({"vibration": bumped}, {"gap": True}, {"invalid_samples": 2}, {"deformation_tare": np.ones(3)},
                   {"vibration": cell.vibration.astype(np.int32)}):  # the last: the same values in another dtype
        assert not same_window(a, with_cell(**fields)), fields
    assert same_window(a, with_cell(vibration=cell.vibration.copy()))  # the same bits out of the stacks
    zero, negative_zero, nan = cell.force_n.copy(), cell.force_n.copy(), cell.force_n.copy()
    zero[0], negative_zero[0], nan[0] = 0.0, -0.0, np.nan
    assert not same_window(with_cell(force_n=zero), with_cell(force_n=negative_zero))  # equal values, other bits
    assert same_window(with_cell(force_n=nan), with_cell(force_n=nan.copy()))  # NaN equals its own bits
    # a stacked window changed in one stack row
    f = rehearsal_window(nao, 0.5, np.dtype(np.int16), np.dtype(np.uint16), seed=5)
    f.stacks.deformation[3, 0, 0] += 1
    assert not same_window(a, f)
    other = rehearsal_window(nao, 0.5, np.dtype(np.int16), np.dtype(np.uint16), seed=6)
    assert not same_window(a, other)
    shifted = dataclasses.replace(a, end_ns=a.end_ns + 1)
    assert not same_window(a, shifted)


@pytest.mark.parametrize("seed", range(3))
def test_described_ahead_equals_described_after_on_random_touches(seed):
    """Random touch and release lengths, some releases shorter than the release time: the same bits."""
    rng = np.random.default_rng(100 + seed)
    schedule = [(1.0, 0.0)]
    for _ in range(6):
        schedule += [(float(rng.integers(6, 20)) / 10, float(rng.uniform(0.5, 3.0))),
                     (float(rng.integers(1, 6)) / 10, 0.0)]
    schedule.append((1.0, 0.0))
    with_ahead, keeper, *_ = _run(schedule, ahead=True, seed=seed)
    without, *_ = _run(schedule, ahead=False, seed=seed)
    assert [(a, b, _bits(v)) for a, b, v in with_ahead] == [(a, b, _bits(v)) for a, b, v in without]
    assert keeper.used == len(without) >= 1


def _nao_run(touching: list[bool], *, ahead: bool, seed: int = 0, tare_at: int | None = None,
             gap_at: int | None = None):
    """Every NAO body part's cells in 20 ms messages (accelerometer 1 kHz, force 250 Hz, the cells sampled
    together, as the latency bench's frames), touching (about 1.2 N) or released per message round; polled after
    each round as the window node does.

    ``tare_at``: from that round on one cell reports another tare; ``gap_at``: that round's first 8 ms of
    accelerometer samples are missing, every cell's.  Returns (windows, descriptors, windows cut ahead with the
    rounds they were cut at, windower, DescribeAhead)."""
    robot = load_robot("nao")
    w = Windower(robot, mode="exploration", min_duration_s=0.5)
    describe = _describe(robot)
    keeper = DescribeAhead(describe)
    rng = np.random.default_rng(seed)
    wins, descs, cut_ahead = [], [], []
    for k, touch in enumerate(touching):
        t0 = 1_000_000_000 + k * 20 * MS
        first = 0
        for part in robot.body_parts:
            ct = robot.cell_types[part.cell_type]
            n = len(part.cells)
            n_a = 12 if gap_at == k else 20
            t_a = np.tile(t0 + np.arange(20 - n_a, 20, dtype=np.int64) * MS, n)
            t_d = np.tile(t0 + np.arange(5, dtype=np.int64) * 4 * MS, n)
            counts_a = np.full(n, n_a, np.int64)
            vib = rng.integers(-300, 300, (len(ct.vibration.channels), n * n_a)).astype(np.int16)
            force = rng.uniform(1.0, 1.4, n * 5) if touch else rng.uniform(0.0, 0.02, n * 5)
            tare = np.zeros((n, len(ct.deformation.channels)))
            if tare_at is not None and k >= tare_at and first == 0:
                tare[0] = 3.0
            w.add_part(PartChunk(
                np.array([c.id for c in part.cells], np.int64), counts_a, np.full(n, 5, np.int64), vib, t_a,
                rng.integers(0, 900, (len(ct.deformation.channels), n * 5)).astype(np.uint16), t_d, force,
                extra=rng.uniform(0.0, 1.0, (len(ct.extra_channels), n * 5)) if ct.extra_channels else None,
                deformation_tare=tare))
            first += n
        for win in w.poll():
            got = keeper.take(win) if ahead else None
            wins.append(win)
            descs.append(got if got is not None else describe(win))
        if ahead and keeper.offer(w):
            cut_ahead.append((k, keeper._window))
    return wins, descs, cut_ahead, w, keeper


def test_a_stacked_window_still_held_is_handed_back_without_cutting_again():
    """The NAO, every body part in the window as one set of stacks: the window at the decision is the very one
    cut ahead (nothing inside its span reached the buffers since), its descriptor the bits of one described
    after."""
    touching = [False] * 20 + [True] * 60 + [False] * 15
    wins, descs, cut_ahead, w, keeper = _nao_run(touching, ahead=True)
    ref_wins, ref_descs, _, ref_w, _ = _nao_run(touching, ahead=False)
    assert len(wins) == len(ref_wins) == 1 and wins[0].stacks is not None
    assert (wins[0].start_ns, wins[0].end_ns) == (ref_wins[0].start_ns, ref_wins[0].end_ns)
    assert (wins[0].end_ns - wins[0].start_ns) / 1e9 == pytest.approx(1.2, abs=0.01)
    assert len(cut_ahead) == 1 and wins[0] is cut_ahead[0][1]
    assert same_window(wins[0], ref_wins[0]) and _bits(descs[0]) == _bits(ref_descs[0])
    assert keeper.counts() == {"used": 1, "changed": 0, "discarded": 0}
    assert w.faults == ref_w.faults


def test_a_stacked_window_with_a_gap_counts_it_once():
    touching = [False] * 20 + [True] * 60 + [False] * 15
    wins, descs, cut_ahead, w, keeper = _nao_run(touching, ahead=True, gap_at=40)
    ref_wins, ref_descs, _, ref_w, _ = _nao_run(touching, ahead=False, gap_at=40)
    assert wins[0].stacks is not None and wins[0] is cut_ahead[0][1] and same_window(wins[0], ref_wins[0])
    n_cells = load_robot("nao").n_cells
    assert sum(c.gap for c in wins[0].cells.values()) == n_cells
    assert w.faults["gap"] == ref_w.faults["gap"] == n_cells and w.faults == ref_w.faults
    assert _bits(descs[0]) == _bits(ref_descs[0])


def test_a_stacked_window_whose_tare_changed_is_cut_and_described_again():
    touching = [False] * 20 + [True] * 60 + [False] * 15
    _, _, [(cut_at, _)], _, _ = _nao_run(touching, ahead=True)
    # a new tare one round after the window was cut ahead, inside the release time
    wins, descs, cut_ahead, w, keeper = _nao_run(touching, ahead=True, tare_at=cut_at + 1)
    ref_wins, ref_descs, _, ref_w, _ = _nao_run(touching, ahead=False, tare_at=cut_at + 1)
    assert [k for k, _ in cut_ahead] == [cut_at] and wins[0] is not cut_ahead[0][1]
    assert same_window(wins[0], ref_wins[0]) and not same_window(wins[0], cut_ahead[0][1])
    assert keeper.counts() == {"used": 0, "changed": 1, "discarded": 0}
    assert _bits(descs[0]) == _bits(ref_descs[0]) and w.faults == ref_w.faults


def test_samples_arriving_late_inside_the_window_make_it_cut_and_described_again():
    """A finger silent for longer than the windower waits (0.5 s) sends its backlog after the window was cut
    ahead, stamps inside the window: the window is cut again with them, and described again."""
    robot = load_robot("shadow_hand")
    results = []
    for ahead in (True, False):
        w = Windower(robot, mode="exploration", min_duration_s=0.5, release_s=0.5)
        describe = _describe(robot)
        keeper = DescribeAhead(describe)
        rng = np.random.default_rng(7)
        backlog, out, cut_at = [], [], []
        for k in range(60):  # 6 s of 100 ms chunks; the first finger touches from 1 to 3 s
            t = k * 100 * MS
            w.add(1, _chunk(t, 1.0 if 10 <= k < 30 else 0.0, rng))
            chunk = _chunk(t, 1.0 if 10 <= k < 20 else 0.0, rng)
            if 15 <= k < 33:  # the second finger falls silent from 1.5 s ...
                backlog.append(chunk)
            else:
                w.add(2, chunk)
            if k == 32:  # ... and its backlog arrives at once, after the release was first seen
                w.add_many([(2, c) for c in backlog])
            for win in w.poll():
                got = keeper.take(win) if ahead else None
                out.append((win.start_ns, win.end_ns, sorted(win.cells), got if got is not None else describe(win)))
            if ahead and keeper.offer(w):
                cut_at.append(k)
        results.append((out, keeper.counts(), cut_at, dict(w.faults)))
    (with_ahead, counts, cut_at, faults), (without, _, _, ref_faults) = results
    assert [(a, b, c) for a, b, c, _ in with_ahead] == [(a, b, c) for a, b, c, _ in without] == \
        [(1000 * MS, 3000 * MS, [1, 2])]
    assert [_bits(v) for *_, v in with_ahead] == [_bits(v) for *_, v in without]
    assert cut_at and cut_at[0] < 32 and faults == ref_faults
    assert counts["used"] == 0 and counts["changed"] == 1


def test_samples_added_since_a_mark_are_found_through_moves_and_growth():
    """``_RowBuffer.added_inside``: the samples appended since a mark, wherever rows were moved or grown to."""
    from tactile_descriptors_ros.core.windowing import _RowBuffer

    buf = _RowBuffer(3, 1, np.dtype(np.int32), capacity=8)
    for t in range(6):  # rows 0 and 1 in step, row 2 silent
        buf.append_runs(np.array([0, 1]), np.array([1, 1]), np.array([10 * t, 10 * t + 1]), np.zeros((1, 2), np.int32))
    buf.trim_before(30)
    mark = buf.added.copy()
    assert not buf.added_inside(mark, 0, 1000)
    buf.append(2, np.array([25, 26]), np.zeros((1, 2), np.int32))  # a late cell, inside [20, 30)
    assert buf.added_inside(mark, 20, 30) and not buf.added_inside(mark, 30, 1000)
    mark = buf.added.copy()
    for t in range(6, 40):  # rows moved down and the arrays grown, several times
        buf.append_runs(np.array([0, 1]), np.array([1, 1]), np.array([10 * t, 10 * t + 1]), np.zeros((1, 2), np.int32))
    assert buf.capacity > 8
    assert not buf.added_inside(mark, 0, 60) and buf.added_inside(mark, 391, 392) and buf.added_inside(mark, 0, 61)
    assert not buf.added_inside(buf.added.copy(), 0, 10**6)
