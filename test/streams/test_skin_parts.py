"""Per-body-part skin messages without ROS: packing, its inverse, and gathering a part's cell batches."""

from __future__ import annotations

import numpy as np
import pytest

from tactile_descriptors_ros.errors import SignalError
from tactile_descriptors_ros.streams.frames import SkinFrame
from tactile_descriptors_ros.streams.skin_parts import PartGatherer, SkinRun, pack_skin_part, skin_part_chunks


def _run(cid: int, t0_ns: int, n_a: int = 10, n_f: int = 3, proximity: bool = True, seq: int = 0) -> SkinRun:
    acc = np.tile(np.arange(n_a, dtype=np.int16), (3, 1)) + cid
    force = np.full((3, n_f), 100 + cid, np.uint16)
    frame = SkinFrame(t0_ns, acc, np.arange(n_a, dtype=np.int64) * 1_000_000, force,
                      np.arange(n_f, dtype=np.int64) * 4_000_000,
                      np.full(n_f if proximity else 0, 7, np.uint16), temperature_c=30.0 + cid, sequence=seq)
    return SkinRun(cid, frame, np.array([1.0, 2.0, 3.0]) * cid)


class _Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def test_pack_lays_the_runs_end_to_end_and_unpacks_to_the_same_batches():
    runs = [_run(5, 2_000_000_500, seq=3), _run(6, 2_000_000_000, n_a=4, n_f=1, proximity=False, seq=9)]
    part = pack_skin_part("chest", runs, force_n_per_count=0.01)
    assert part.stamp_ns == 2_000_000_000  # the earliest first sample
    assert part.accel_count.tolist() == [10, 4] and part.force_count.tolist() == [3, 1]
    assert part.accel.shape == (3, 14) and part.force.shape == (3, 4)
    assert part.accel_offset_ns[0] == 500 and part.accel_offset_ns[10] == 0
    assert part.proximity.tolist() == [7, 7, 7, 65535]  # the cell without proximity: invalid, not zero
    for (cid, frame, tare), run in zip(part.frames(), runs):
        assert cid == run.cell_id and frame.stamp_ns == run.frame.stamp_ns and frame.sequence == run.frame.sequence
        np.testing.assert_array_equal(frame.accel, run.frame.accel)
        np.testing.assert_array_equal(frame.accel_offset_ns, run.frame.accel_offset_ns)
        np.testing.assert_array_equal(frame.force, run.frame.force)
        np.testing.assert_array_equal(frame.proximity, run.frame.proximity)
        np.testing.assert_array_equal(tare, run.tare_counts)


def test_chunks_use_each_cells_own_tare_and_time():
    runs = [_run(1, 10**9), _run(2, 10**9 + 3)]
    chunks = skin_part_chunks(pack_skin_part("chest", runs, force_n_per_count=0.5), ("temperature", "proximity"))
    assert [cid for cid, _ in chunks] == [1, 2]
    for (cid, chunk), run in zip(chunks, runs):
        tare = run.tare_counts
        np.testing.assert_array_equal(chunk.force_n, np.full(3, (100 + cid - tare.mean()) * 0.5))
        np.testing.assert_array_equal(chunk.vibration_t_ns, run.frame.stamp_ns + run.frame.accel_offset_ns)
        np.testing.assert_array_equal(chunk.extra[0], np.full(3, 30.0 + cid))
        np.testing.assert_array_equal(chunk.deformation_tare, tare)


def test_pack_of_nothing_and_inconsistent_parts_are_errors():
    with pytest.raises(SignalError, match="no cell batches"):
        pack_skin_part("chest", [])
    part = pack_skin_part("chest", [_run(1, 10**9)])
    with pytest.raises(SignalError, match="accel must be"):
        type(part)(**{**part.__dict__, "accel_count": np.array([11])})
    with pytest.raises(SignalError, match="extra channel"):
        skin_part_chunks(part, ("pdc",))


def test_gatherer_sends_a_part_once_every_cell_has_its_batch():
    g = PartGatherer({"chest": [1, 2, 3], "head": [9]}, max_wait_s=0.1, now_s=_Clock())
    g.add("chest", _run(1, 0))
    g.add("chest", _run(2, 0))
    assert g.due() == []  # cell 3 not in yet
    g.add("head", _run(9, 0))
    g.add("chest", _run(3, 1))
    due = dict(g.due())
    assert sorted(due) == ["chest", "head"]
    assert [r.cell_id for r in due["chest"]] == [1, 2, 3] and g.pending() == 0 and g.partial == 0


def test_gatherer_does_not_wait_more_than_a_batch_for_a_silent_cell():
    g = PartGatherer({"chest": [1, 2]}, max_wait_s=10.0, now_s=_Clock())
    g.add("chest", _run(1, 0, seq=0))
    assert g.due() == []
    g.add("chest", _run(1, 10_000_000, seq=1))  # cell 1's next batch: cell 2 is late or silent
    (part, runs), = g.due()
    assert [(r.cell_id, r.frame.sequence) for r in runs] == [(1, 0), (1, 1)] and g.partial == 1
    g.add("chest", _run(1, 20_000_000, seq=2))  # cell 2 is no longer waited for
    assert [r.cell_id for _, rr in g.due() for r in rr] == [1]
    g.add("chest", _run(2, 25_000_000))  # a cell that comes back joins the next message
    assert g.due() == []
    g.add("chest", _run(1, 30_000_000, seq=3))
    assert [r.cell_id for _, rr in g.due() for r in rr] == [2, 1]
    g.add("chest", _run(1, 40_000_000, seq=4))  # and is waited for again
    assert g.due() == []


def test_gatherer_flushes_what_waited_too_long():
    clock = _Clock()
    g = PartGatherer({"chest": [1, 2]}, max_wait_s=0.1, now_s=clock)
    g.add("chest", _run(1, 0))
    clock.t = 0.05
    assert g.due() == [] and g.flush_stale() == []
    clock.t = 0.1
    (part, runs), = g.flush_stale()
    assert part == "chest" and [r.cell_id for r in runs] == [1] and g.pending() == 0


def _checkers():
    from tactile_descriptors_ros.streams.skin_parts import RunChecker

    parts = {"hand": [5, 9, 12], "arm": [20, 21]}
    return RunChecker(parts), RunChecker(parts)


def _check(checker, compiled: bool, part, ids, seq, bad):
    from unittest import mock

    from tactile_descriptors_ros.core import windowing

    with mock.patch.object(windowing, "COMPILED_INTAKE", compiled):
        return checker.check(part, np.array(ids, np.int64), np.array(seq, np.uint32), np.array(bad, np.uint32))


def test_run_checker_known_answers():
    """Batch numbers per cell: gaps are lost batches (also across the 32-bit wrap), a number at or before the
    newest a restart; unknown cells and another body part's cells are left out and counted, first id named."""
    checker, _ = _checkers()
    got = _check(checker, True, "hand", [5, 9], [10, 2**32 - 1], [1, 0])
    assert got.mine.tolist() == [True, True] and (got.lost, got.restarts, got.bad_frames) == (0, 0, 1)
    got = _check(checker, True, "hand", [5, 9, 77, 20, 12], [13, 1, 0, 0, 4], [0, 2, 9, 9, 1])
    assert got.mine.tolist() == [True, True, False, False, True]
    assert (got.unknown, got.first_unknown, got.other_part, got.first_other_part) == (1, 77, 1, 20)
    # cell 5: 11 and 12 lost; cell 9: 2**32 - 1 -> 1 wraps, 0 lost; cell 12: first seen
    assert (got.lost, got.restarts, got.bad_frames) == (3, 0, 3)
    got = _check(checker, True, "hand", [5, 5], [3, 4], [0, 0])  # one cell twice: a restart, then in order
    assert (got.lost, got.restarts) == (0, 1)
    got = _check(checker, True, "arm", [5, 99], [0, 0], [4, 4])  # nothing of the arm's: no state touched
    assert not got.mine.any() and (got.unknown, got.other_part, got.bad_frames) == (1, 1, 0)
    assert checker.high[checker.ids.tolist().index(5)] == 4


@pytest.mark.parametrize("seed", range(4))
def test_run_checker_compiled_equals_numpy(seed):
    """Random messages (unknown and misplaced cells, repeats, gaps, restarts, wraps) give the compiled and the
    numpy checks the same results and the same state, message after message."""
    from tactile_descriptors_ros.core import fast

    if fast.kernel_module() is None:
        pytest.skip("no compiled backend")
    rng = np.random.default_rng(seed)
    a, b = _checkers()
    newest = {}
    for _ in range(300):
        part = str(rng.choice(["hand", "arm", "leg"]))
        ids = rng.choice([5, 9, 12, 20, 21, 3, 40], int(rng.integers(0, 7)))
        seq = []
        for cid in ids.tolist():
            step = int(rng.choice([1, 1, 1, 2, 5, 0, -3, 2**31, 2**32 - 1]))
            newest[cid] = (newest.get(cid, int(rng.integers(0, 2**32))) + step) % 2**32
            seq.append(newest[cid])
        bad = rng.integers(0, 4, ids.size)
        x, y = _check(a, True, part, ids, seq, bad), _check(b, False, part, ids, seq, bad)
        assert x.mine.tolist() == y.mine.tolist()
        fields = ("unknown", "first_unknown", "other_part", "first_other_part", "lost", "restarts", "bad_frames")
        assert [getattr(x, f) for f in fields] == [getattr(y, f) for f in fields]
        assert (a.high == b.high).all() and (a.have == b.have).all()
