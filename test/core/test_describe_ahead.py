"""An exploration's window described during its release time: the same descriptor, or described again."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tactile_descriptors_ros.core.aggregation import CellSignals, describe_window
from tactile_descriptors_ros.core.ahead import DescribeAhead, same_window
from tactile_descriptors_ros.core.robot import load_robot
from tactile_descriptors_ros.core.windowing import CellChunk, Windower, rehearsal_window

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
