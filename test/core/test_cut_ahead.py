"""A fixed window's samples cut ahead (``Windower.cut_fixed_ahead``): the window that closes is the one a single
cut makes, to the bit, whatever happened between the two cuts.

The window node cuts the next fixed window's buffered samples once every live cell has sent data to within
``CUT_AHEAD_S`` of its end; the poll that closes it then copies only the samples since.  Every test runs a
windower that cuts ahead beside one that does not, on the same messages, and compares every window field by
field (``same_window``: every array's bits, dtype and shape; the stacks' arrays too) and every fault count.
"""

from __future__ import annotations

from unittest import mock

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_descriptors_ros.core import fast, windowing
from tactile_descriptors_ros.core.ahead import same_bits, same_window
from tactile_descriptors_ros.core.robot import load_robot
from tactile_descriptors_ros.core.windowing import PartChunk, Windower

MS = 1_000_000
NAO = load_robot("nao")

pytestmark = pytest.mark.skipif(fast.kernel_module() is None, reason="no compiled backend: windows are cut cell by cell")


def _messages(batches_ms: list[int], seed: int = 0, *, offsets_ns: dict[int, int] | None = None,
              gap_at: int | None = None, invalid_at: int | None = None, silent: tuple[str, int, int] | None = None,
              jump_at: int | None = None, slow_jitter: bool = False,
              late_force: tuple[int, int] | None = None, holes_ms: dict[str, set[int]] | None = None,
              early: tuple[str, int] | None = None) -> list[list[PartChunk]]:
    """Every NAO body part's cells in one message per part and batch (accelerometer 1 kHz, force 250 Hz), batch
    ``k`` ``batches_ms[k]`` long, as rounds of messages.

    ``offsets_ns``: cell id -> a shift of that cell's stamps (cells on their own clocks); ``gap_at``: that
    batch's first half of accelerometer samples missing, every cell's; ``invalid_at``: one cell's accelerometer
    sample in that batch is invalid; ``silent``: ``(body part, first, last)``: that part sends nothing in batches
    ``first..last-1`` and then all of them at once; ``jump_at``: the stamps step back 2 s from that batch on;
    ``slow_jitter``: the force samples' phase moves from batch to batch (a batch's count is not the rate's);
    ``late_force``: ``(first, last)``: batches ``first..last-1`` carry no force samples, batch ``last`` all of them;
    ``holes_ms``: per body part, the accelerometer samples (ms after the first) none of its cells sends;
    ``early``: ``(body part, k)``: that part's batch ``k + 1`` is sent with batch ``k``."""
    rng = np.random.default_rng(seed)
    offsets_ns = offsets_ns or {}
    t0 = 1_000_000_000
    rounds: list[list[PartChunk]] = []
    held: list[PartChunk] = []
    late_t: dict[str, np.ndarray] = {}
    for k, length in enumerate(batches_ms):
        shift = -2_000 * MS if jump_at is not None and k >= jump_at else 0
        # on a 4 ms grid of stamp time, or (jitter) each batch's on a grid of its own phase
        phase = int(rng.integers(0, 4)) * MS if slow_jitter else (-(t0 - 1_000_000_000)) % (4 * MS)
        out = []
        for part in NAO.body_parts:
            ids = [c.id for c in part.cells]
            n = len(ids)
            t_a = t0 + shift + np.arange(length, dtype=np.int64) * MS
            if gap_at == k:
                t_a = t_a[length // 2:]
            if holes_ms and part.name in holes_ms:
                t_a = t_a[~np.isin((t_a - 1_000_000_000 - shift) // MS, sorted(holes_ms[part.name]))]
            t_d = t0 + shift + np.arange(phase, length * MS, 4 * MS, dtype=np.int64)
            if late_force is not None and late_force[0] <= k < late_force[1]:
                late_t[part.name] = np.concatenate([late_t.get(part.name, t_d[:0]), t_d])
                t_d = t_d[:0]
            elif late_force is not None and k == late_force[1]:
                t_d = np.concatenate([late_t.pop(part.name), t_d])
            na, nd = t_a.size, t_d.size
            off = np.array([offsets_ns.get(c, 0) for c in ids], np.int64)
            valid = np.ones(n * na, bool)
            if invalid_at == k and part.name == "chest":
                valid[3] = False
            chunk = PartChunk(
                np.array(ids, np.int64), np.full(n, na, np.int64), np.full(n, nd, np.int64),
                rng.integers(-300, 300, (3, n * na)).astype(np.int16), (t_a[None, :] + off[:, None]).ravel(),
                rng.integers(0, 900, (3, n * nd)).astype(np.uint16), (t_d[None, :] + off[:, None]).ravel(),
                rng.uniform(1.0, 1.4, n * nd), vibration_valid=valid,
                extra=rng.uniform(0.0, 1.0, (2, n * nd)), deformation_tare=rng.normal(0.0, 2.0, (n, 3)))
            if silent is not None and part.name == silent[0] and silent[1] <= k < silent[2]:
                held.append(chunk)
                continue
            if early is not None and part.name == early[0] and k == early[1] + 1:
                rounds[-1].append(chunk)
                continue
            out.append(chunk)
        if silent is not None and k == silent[2] - 1:
            out += held
        rounds.append(out)
        t0 += length * MS
    return rounds


def _run(rounds: list[list[PartChunk]], *, ahead: bool, **windower) -> tuple[list, Windower, int]:
    """Every round into a fixed-window windower and one poll, as the window node does; cutting ahead after each
    poll when ``ahead``.  Returns (windows, windower, heads cut)."""
    w = Windower(NAO, mode="fixed", **{"lateness_s": 0.0, **windower})
    out, heads = [], 0
    for rnd in rounds:
        for chunk in rnd:
            w.add_part(chunk)
        out += w.poll()
        if ahead:
            heads += w.cut_fixed_ahead()
    return out, w, heads


def _same_cells(a, b) -> bool:
    """Every cell of two windows with the same arrays (dtype, shape, bits) and flags, in the same order."""
    if list(a.cells) != list(b.cells):
        return False
    for cid, x in a.cells.items():
        y = b.cells[cid]
        for name in ("vibration", "vibration_t_ns", "deformation", "deformation_t_ns", "force_n", "extra",
                     "deformation_tare"):
            u, v = getattr(x, name), getattr(y, name)
            if (u is None) != (v is None) or (u is not None and not same_bits(u, v)):
                return False
        if (x.valid, x.gap, x.invalid_samples) != (y.valid, y.gap, y.invalid_samples):
            return False
    return True


def _same_run(rounds, **windower) -> tuple[list, Windower, int]:
    """Both windowers on ``rounds``: the same windows, to every bit and layout, and the same faults; and the
    cells of the per-cell cut (the reference, without the compiled backend's cut and stacks)."""
    got, w_ahead, heads = _run(rounds, ahead=True, **windower)
    want, w_once, _ = _run(rounds, ahead=False, **windower)
    with mock.patch.object(windowing, "COMPILED_CUT", False):
        reference, w_ref, _ = _run(rounds, ahead=True, **windower)
    assert w_ref.heads == {} and w_ref.faults == w_once.faults
    assert len(reference) == len(want) and all(_same_cells(a, b) for a, b in zip(want, reference))
    assert [(x.start_ns, x.end_ns) for x in got] == [(x.start_ns, x.end_ns) for x in want]
    for a, b in zip(got, want):
        assert same_window(a, b)
        assert (a.stacks is None) == (b.stacks is None)
        if a.stacks is not None:
            for name in ("vibration", "vibration_t_ns", "deformation", "deformation_t_ns", "force_n", "extra"):
                x, y = getattr(a.stacks, name), getattr(b.stacks, name)
                assert same_bits(x, y) and x.flags.c_contiguous and y.flags.c_contiguous, name
            assert all(cell is a.cells[cid] for cid, cell in zip(a.cells, a.stacks.cells))
    assert w_ahead.faults == w_once.faults
    return got, w_ahead, heads


def test_a_window_closed_from_its_head_is_the_single_cut_and_copies_only_the_samples_since(monkeypatch):
    rounds = _messages([10] * 400)
    copied = []
    stack = windowing._stack_arrays

    def spy(order, head=None, room=(0, 0, 0)):
        arrays = stack(order, head, room)
        copied.append((head is not None, head is not None and arrays is head.arrays,
                       int(order[0][1][1, 0] - order[0][1][0, 0])))
        return arrays

    monkeypatch.setattr(windowing, "_stack_arrays", spy)
    got, w, heads = _same_run(rounds)
    assert len(got) == 4 and all(x.stacks is not None and len(x.cells) == 116 for x in got)
    assert heads == 4 and w.heads == {"used": 4}
    closes = [c for c in copied if c[0]]
    # each close copied the accelerometer samples since the head's mark (40 of the window's 2,000: the head is cut
    # within 50 ms of the end, on the grid of 4 ms from the start) into the arrays the head left room in
    assert closes == [(True, True, 40)] * 4


def test_the_head_is_cut_within_cut_ahead_s_of_the_end_and_once():
    w = Windower(NAO, mode="fixed", lateness_s=0.0)
    cut_at, closed_at = [], []
    for k, rnd in enumerate(_messages([10] * 300)):
        for chunk in rnd:
            w.add_part(chunk)
        if w.poll():
            closed_at.append(k)
        if w.cut_fixed_ahead():
            cut_at.append((k, w._head.mark))
    # data from 1 s; the windows end 1.5 ms before whole multiples of the 0.5 s hop, the first at 3.4985 s
    # (batch 249 holds it); its head is cut once, at the first batch after which a mark within 50 ms of its end
    # lies before the newest sample every cell has: the mark on the grid of the force's 4 ms period from the
    # window's start (1.4985 s), 3.4585 s, the newest sample 3.459 s (after batch 244: 3.4465 s, 52 ms before
    # the end); the next 0.5 s later
    assert closed_at == [249, 299] and cut_at == [(245, 3_458_500_000), (295, 3_958_500_000)]


def test_a_window_waiting_for_late_cells_is_cut_whole_ahead_and_closed_without_copying(monkeypatch):
    # 100 ms batches and 50 ms of lateness: the batch holding a window's last samples does not close it, the next
    # does; meanwhile the whole window is cut ahead, and closing it copies nothing more
    copied = []
    stack = windowing._stack_arrays

    def spy(order, head=None, room=(0, 0, 0)):
        arrays = stack(order, head, room)
        copied.append((head is not None, arrays is head.arrays if head is not None else None, room))
        return arrays

    monkeypatch.setattr(windowing, "_stack_arrays", spy)
    got, w, heads = _same_run(_messages([100] * 40), lateness_s=0.05)
    # 4 s of data from 1 s: three windows closed, the fourth's (ending at 4.9985 s) cut ahead and waiting
    assert len(got) == 3 and heads == 4 and w.heads == {"used": 3} and w._head.mark == w._head.window[1]
    assert [c for c in copied if c[0]] == [(True, True, (0, 0, 0))] * 3


def test_samples_arriving_late_inside_the_head_make_the_window_cut_whole():
    # every body part's force samples of 70 ms up to the head's mark come with the closing batch: the head, cut
    # without them, is one set of stacks, but no longer the window's first samples
    got, w, heads = _same_run(_messages([10] * 300, late_force=(242, 249)))
    assert heads == 2 and w.heads == {"recut": 1, "used": 1}


def test_a_body_part_silent_beyond_the_stall_leaves_a_head_that_is_no_set_of_stacks():
    # the chest sends nothing for 0.6 s: the others are not held back by it, and its rows hold fewer samples
    got, w, heads = _same_run(_messages([10] * 300, silent=("chest", 190, 250)))
    assert w.heads["recut"] >= 1 and heads == 1


def test_a_gap_across_the_mark_is_found_from_the_step_across_it():
    # the chest, a batch ahead of the others, misses the accelerometer samples 2,457-2,459 ms after the first:
    # its last sample before the head's mark (2,458.5 ms) is 2.5 ms before it, its first after 1.5 ms after it:
    # a 4 ms step (a gap: more than 3 periods) that neither part shows alone.  The other parts miss as many
    # samples on either side of the mark, 3 ms apart at most (no gap), so every part has as many samples as the
    # others and the window stays one set of stacks.
    holes = {p.name: ({2457, 2458, 2459} if p.name == "chest" else {2300, 2301, 2470}) for p in NAO.body_parts}
    got, w, heads = _same_run(_messages([10] * 260, holes_ms=holes, early=("chest", 245)))
    assert w.heads == {"used": 1} and got[0].stacks is not None
    assert w._head is None and w.faults["gap"] == 32
    assert [c.gap for c in got[0].cells.values()] == [p.name == "chest" for p in NAO.body_parts for _ in p.cells]


@pytest.mark.parametrize("case", ["gap", "invalid", "own_clocks", "fewer", "jitter"])
def test_faults_and_unstacked_windows_give_the_single_cut(case):
    kwargs = {"gap": {"gap_at": 249}, "invalid": {"invalid_at": 330},
              "own_clocks": {"offsets_ns": {c.id: c.id * 7_919_000 % 1_000_000 for p in NAO.body_parts
                                            for c in p.cells}},
              "fewer": {"holes_ms": {"chest": {2600}}}, "jitter": {"slow_jitter": True}}[case]
    got, w, heads = _same_run(_messages([10] * 400, seed=3, **kwargs))
    assert len(got) == 4
    if case == "gap":  # in the first window's last samples (the cut since the mark) and the others' heads: once a cell
        assert w.faults["gap"] == 116 * 4 and w.heads == {"used": 4}
    if case == "invalid":  # a cell with an invalid sample in the head: no stacks, cut whole
        assert w.faults["windows_with_invalid_samples"] >= 1 and w.heads["recut"] >= 1
    if case == "own_clocks":  # every cell sampling at its own instants (phases over the whole 1 ms period): the
        # windows start at one of two positions of the rows, with as many samples: one set of stacks still, each
        # row copied from its position, and the heads (marks on the grid of the periods) serve every window
        assert len({c.vibration_t_ns[0] % 1_000_000 for c in got[0].cells.values()}) > 100
        assert all(x.stacks is not None for x in got) and w.heads == {"used": 4}
    if case == "fewer":  # the chest misses a sample (3.6 s) the others have: no stacks for the windows holding it
        assert [x.stacks is None for x in got] == [False, True, True, True] and w.heads == {"used": 1, "recut": 3}
    if case == "jitter":  # force samples off the rate's count: the head's room does not fit, but it is used
        assert w.heads == {"used": 4}


def test_a_clock_jump_or_new_settings_drop_the_head():
    got, w, _ = _same_run(_messages([10] * 150 + [10] * 300, jump_at=148))
    assert w.faults["clock_jump"] >= 1
    rounds = _messages([10] * 300)
    w = Windower(NAO, mode="fixed", lateness_s=0.0)
    plain = Windower(NAO, mode="fixed", lateness_s=0.0)
    out, want = [], []
    for k, rnd in enumerate(rounds):
        for chunk in rnd:
            w.add_part(chunk)
            plain.add_part(chunk)
        out += w.poll()
        want += plain.poll()
        w.cut_fixed_ahead()
        if k == 246:  # the head of the window ending at 3.0015 s is cut; the window is made longer
            assert w._head is not None and w._head.arrays is not None
            w.retune(length_s=2.5)
            plain.retune(length_s=2.5)
    assert [(x.start_ns, x.end_ns) for x in out] == [(x.start_ns, x.end_ns) for x in want]
    assert all(same_window(a, b) for a, b in zip(out, want))


@settings(max_examples=25, deadline=None)
@given(batches=st.lists(st.integers(3, 80), min_size=40, max_size=140), seed=st.integers(0, 2**16),
       gap=st.none() | st.integers(0, 139), invalid=st.none() | st.integers(0, 139), jitter=st.booleans(),
       shift_ns=st.sampled_from([0, 200_000, 600_000]), lateness_s=st.sampled_from([0.0, 0.03]))
def test_any_batching_gives_the_single_cut(batches, seed, gap, invalid, jitter, shift_ns, lateness_s):
    _same_run(_messages(batches, seed, gap_at=gap, invalid_at=invalid, slow_jitter=jitter, offsets_ns={7: shift_ns}),
              length_s=0.6, hop_s=0.2, lateness_s=lateness_s)
