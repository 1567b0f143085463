"""A window cut as one set of stacks (``Window.stacks``) holds what the cell-by-cell cut holds, and
``describe_window`` given those stacks describes it to the same bits as without them.

When every cell of the robot is in the window, clean, with as many samples as the others, the windower
copies each stream of all cells into one array and every cell's arrays are views of its row
(:class:`~tactile_descriptors_ros.core.aggregation.CellStacks`); the descriptor then reads those arrays
instead of stacking the cells again.  It must do so only while the cells are the ones stacked: a cell
whose array was replaced after the cut is described from its own array.
"""

from __future__ import annotations

import dataclasses
from unittest import mock

import numpy as np
import pytest

from tactile_descriptors_ros.core import fast, windowing
from tactile_descriptors_ros.core.aggregation import describe_window, stack_cells
from tactile_descriptors_ros.core.blocks import describe_blocks
from tactile_descriptors_ros.core.robot import load_robot
from tactile_descriptors_ros.core.windowing import PartChunk, Windower

MS = 1_000_000
NAO = load_robot("nao")
# two body parts of two cells each: every cell of the robot can send
ROBOT = dataclasses.replace(NAO, body_parts=tuple(dataclasses.replace(NAO.body_part(name), cells=NAO.body_part(name).cells[:2])
                                                  for name in ("left_hand", "right_hand")))
PARTS = {p.name: [c.id for c in p.cells] for p in ROBOT.body_parts}
SELECTIONS = [("paper",), ("per_channel", "bands", "levels", "statistics"), ("per_channel",), ("plain",),
              ("levels", "paper")]

pytestmark = pytest.mark.skipif(fast.kernel_module() is None, reason="no compiled backend: windows are cut cell by cell")


def _chunks(n_batches: int, seed: int, *, invalid: int | None = None, quiet: int | None = None,
            light: int | None = None, first: str = "left_hand", later_ns: dict[int, int] | None = None
            ) -> list[PartChunk]:
    """10 ms messages, one per body part and batch, every cell on the same stamps (``first``'s message first).

    ``invalid``: a cell with an invalid accelerometer sample in batch 12; ``quiet``: a cell that never sends;
    ``light``: a cell pressed below the contact threshold; ``later_ns``: cells sampling that much after the
    others (on a clock of their own)."""
    rng = np.random.default_rng(seed)
    order = [first] + [p for p in PARTS if p != first]
    out = []
    for b in range(n_batches):
        ta = 5_000 * MS + (b * 10 + np.arange(10, dtype=np.int64)) * MS
        tf = ta[::4 - (b % 2)][:3 - (b % 2)].copy()  # 3 or 2 force samples in turn, as 250 Hz in 10 ms batches
        for name in order:
            ids = [c for c in PARTS[name] if c != quiet]
            n = len(ids)
            va = np.ones(10 * n, bool)
            if invalid in ids and b == 12:
                va[10 * ids.index(invalid) + 4] = False
            force = rng.uniform(1.0, 2.0, tf.size * n)
            if light in ids:
                k = ids.index(light)
                force[k * tf.size:(k + 1) * tf.size] = 0.01
            out.append(PartChunk(
                cell_ids=np.array(ids, np.int64), vibration_count=np.full(n, 10, np.int64),
                deformation_count=np.full(n, tf.size, np.int64),
                vibration=rng.integers(-512, 512, (3, 10 * n)).astype(np.int32),
                vibration_t_ns=np.concatenate([ta + (later_ns or {}).get(c, 0) for c in ids]),
                deformation=rng.integers(0, 4096, (3, tf.size * n)).astype(np.int32),
                deformation_t_ns=np.concatenate([tf + (later_ns or {}).get(c, 0) for c in ids]), force_n=force,
                vibration_valid=va,
                deformation_valid=np.ones(tf.size * n, bool), extra=rng.normal(0, 1, (2, tf.size * n)),
                deformation_tare=rng.normal(0, 5, (n, 3))))
    return out


def _windows(chunks: list[PartChunk]) -> list:
    w = Windower(ROBOT, mode="fixed", length_s=0.2, hop_s=0.1, lateness_s=0.0)
    out = []
    for chunk in chunks:
        w.add_part(chunk)
        out += w.poll()
    return out


def _arrays(window) -> list:
    fields = ("vibration", "vibration_t_ns", "deformation", "deformation_t_ns", "force_n", "extra",
              "deformation_tare")
    return [(cid, [(getattr(c, f).tolist(), getattr(c, f).dtype.str, getattr(c, f).flags.c_contiguous)
                   for f in fields], c.valid, c.gap, c.invalid_samples) for cid, c in window.cells.items()]


def _same_descriptors(a, b) -> bool:
    return (np.array_equal(a.values, b.values, equal_nan=True) and a.labels == b.labels
            and [(bp.quality, bp.contact, bp.cells_in_contact, bp.mean_force_n) for bp in a.body_parts]
            == [(bp.quality, bp.contact, bp.cells_in_contact, bp.mean_force_n) for bp in b.body_parts])


@pytest.mark.parametrize("first", ["left_hand", "right_hand"])
def test_a_clean_window_is_one_set_of_stacks_whose_rows_are_the_cells(first):
    chunks = _chunks(40, 1, first=first)
    windows = _windows(chunks)
    with mock.patch.object(windowing, "COMPILED_CUT", False):
        reference = _windows(chunks)
    assert len(windows) == len(reference) >= 2
    for got, ref in zip(windows, reference):
        assert _arrays(got) == _arrays(ref)
        stacks = got.stacks
        assert stacks is not None and ref.stacks is None
        # the rows are in the robot's order of body parts and cells, whichever message came first
        assert [id(c) for c in stacks.cells] == [id(got.cells[cid]) for ids in PARTS.values() for cid in ids]
        assert stacks.vibration.shape == (4, 3, 200) and stacks.deformation.shape[:2] == (4, 3)
        for k, cell in enumerate(stacks.cells):
            for name in ("vibration", "vibration_t_ns", "deformation", "deformation_t_ns", "force_n", "extra"):
                assert np.shares_memory(getattr(cell, name), getattr(stacks, name)[k]), name
                assert np.array_equal(getattr(cell, name), getattr(stacks, name)[k]), name
        assert stacks.holds(list(stacks.cells), "vibration", "deformation", "force_n", "extra")


def test_cells_on_clocks_of_their_own_are_stacked_each_from_its_own_position():
    # two cells sampling 0.6 and 0.3 ms after the others: the windows (edges half a ms before a whole ms) hold the
    # same number of their samples; the one 0.6 ms late has a sample 0.1 ms after the window's start, a position
    # earlier in its row than the others' first (0.5 ms after it; 0.8 ms for the one 0.3 ms late)
    chunks = _chunks(40, 6, later_ns={PARTS["left_hand"][1]: 600_000, PARTS["right_hand"][0]: 300_000})
    windows = _windows(chunks)
    with mock.patch.object(windowing, "COMPILED_CUT", False):
        reference = _windows(chunks)
    assert len(windows) == len(reference) >= 2
    for got, ref in zip(windows, reference):
        assert _arrays(got) == _arrays(ref) and got.stacks is not None
        firsts = {cid: int(c.vibration_t_ns[0] - got.start_ns) for cid, c in got.cells.items()}
        assert sorted(set(firsts.values())) == [100_000, 500_000, 800_000]
        assert _same_descriptors(describe_window(ROBOT, got.cells, stacks=got.stacks),
                                 describe_window(ROBOT, ref.cells))


@pytest.mark.parametrize("groups", SELECTIONS, ids="+".join)
def test_describing_with_the_stacks_gives_the_same_bits(groups):
    for window in _windows(_chunks(40, 2)):
        assert window.stacks is not None
        plain = describe_window(ROBOT, window.cells, groups=groups)
        assert _same_descriptors(describe_window(ROBOT, window.cells, groups=groups, stacks=window.stacks), plain)
        assert _same_descriptors(describe_blocks(ROBOT, window.cells, block_s=0.0, block_hop_s=0.0, groups=groups,
                                                 stacks=window.stacks), plain)


def test_the_stacks_are_read_instead_of_stacking_the_cells(monkeypatch):
    """With the stacks the kernel gets the stacks' own arrays; without, a concatenation of the cells'."""
    from tactile_descriptors_ros.core import aggregation

    window = _windows(_chunks(30, 3))[0]
    seen = []
    real = aggregation.cell_quantities_bounded
    monkeypatch.setattr(aggregation, "cell_quantities_bounded", lambda vib, ts, dfm, tv, *a: seen.append(
        (vib, ts, dfm, tv)) or real(vib, ts, dfm, tv, *a))
    describe_window(ROBOT, window.cells, groups=("paper",), stacks=window.stacks)
    describe_window(ROBOT, window.cells, groups=("paper",))
    (vib, ts, dfm, tv), (vib2, *_) = seen
    s = window.stacks
    assert vib is s.vibration and ts is s.vibration_t_ns and dfm is s.deformation and tv is s.deformation_t_ns
    assert not np.shares_memory(vib2, s.vibration)


@pytest.mark.parametrize("case", ["invalid", "quiet"])
def test_a_window_with_an_invalid_sample_or_a_missing_cell_is_cut_cell_by_cell(case):
    cell = PARTS["right_hand"][1]
    chunks = _chunks(40, 4, **{case: cell})
    windows = _windows(chunks)
    with mock.patch.object(windowing, "COMPILED_CUT", False):
        reference = _windows(chunks)
    assert [_arrays(w) for w in windows] == [_arrays(w) for w in reference]
    if case == "invalid":  # batch 12 is in the first window only: [5.0985, 5.2985) s (on the grid of the hop)
        assert windows[0].cells[cell].invalid_samples == 1 and windows[0].stacks is None
        assert windows[-1].stacks is not None
    else:
        assert cell not in windows[0].cells and all(w.stacks is None for w in windows)


def test_cells_out_of_contact_or_replaced_after_the_cut_are_described_from_their_own_arrays():
    """A cell below the contact threshold leaves the gated cells a subset of the stacks' rows; a cell whose
    array the caller replaced is no longer its row: both are described as without the stacks."""
    groups = ("per_channel", "bands", "levels", "statistics")
    window = _windows(_chunks(40, 5, light=PARTS["left_hand"][0]))[0]
    assert window.stacks is not None
    plain = describe_window(ROBOT, window.cells, groups=groups)
    assert plain.body_parts[0].cells_in_contact == 1
    assert _same_descriptors(describe_window(ROBOT, window.cells, groups=groups, stacks=window.stacks), plain)

    window = _windows(_chunks(40, 6))[0]
    cid = PARTS["right_hand"][0]
    cell = window.cells[cid]
    for name in ("vibration", "force_n", "extra", "deformation_t_ns"):
        changed = getattr(cell, name).copy()
        changed[..., 5] = changed[..., 5] + (3 if name != "deformation_t_ns" else 0)
        if name == "force_n":
            changed[:] = 0.01  # out of contact now
        setattr(cell, name, changed)
        expected = describe_window(ROBOT, window.cells, groups=groups)
        got = describe_window(ROBOT, window.cells, groups=groups, stacks=window.stacks)
        assert _same_descriptors(got, expected), name
    assert not window.stacks.holds(list(window.stacks.cells), "vibration")


def test_stack_cells_lays_out_an_offline_window_as_the_windower_does():
    """``stack_cells``: copies of a window's cells as rows of one set of stacks, described to the same bits;
    None where the windower would not stack them either."""
    window = _windows(_chunks(30, 7, first="right_hand"))[0]
    cells = {cid: dataclasses.replace(c) for cid, c in window.cells.items()}  # not the windower's stacks
    copies, stacks = stack_cells(ROBOT, cells)
    assert [c for c in copies] == [cid for ids in PARTS.values() for cid in ids]
    assert stacks.holds([copies[cid] for cid in copies], "vibration", "vibration_t_ns", "deformation",
                        "deformation_t_ns", "force_n", "extra")
    assert not any(np.shares_memory(copies[cid].vibration, cells[cid].vibration) for cid in cells)
    for groups in SELECTIONS:
        assert _same_descriptors(describe_window(ROBOT, copies, groups=groups, stacks=stacks),
                                 describe_window(ROBOT, cells, groups=groups))
    one = next(iter(cells))
    assert stack_cells(ROBOT, {cid: c for cid, c in cells.items() if cid != one}) is None  # a cell missing
    short = dict(cells)
    short[one] = dataclasses.replace(cells[one], vibration=cells[one].vibration[:, 1:],
                                     vibration_t_ns=cells[one].vibration_t_ns[1:])
    assert stack_cells(ROBOT, short) is None  # one cell shorter than the others
    assert stack_cells(NAO, cells) is None  # not every cell of that robot


@pytest.mark.parametrize("robot_name,dtypes", [("nao", (np.int32, np.int32)), ("shadow_hand", (np.int64, np.float64))])
def test_rehearsal_window_is_a_live_window_of_every_cell_in_contact(robot_name, dtypes):
    """The window node's rehearsal: every cell of the robot in one set of stacks, the window's length, the data's
    sample types, each cell on its own clock, and a description with every cell in contact and every value finite."""
    robot = load_robot(robot_name)
    w = windowing.rehearsal_window(robot, 2.0, *dtypes)
    assert w.end_ns - w.start_ns == 2_000_000_000 and w.mode == "fixed"
    assert sorted(w.cells) == sorted(c.id for p in robot.body_parts for c in p.cells)
    assert w.stacks is not None and w.stacks.vibration.dtype == dtypes[0] and w.stacks.deformation.dtype == dtypes[1]
    ct = robot.cell_types[robot.body_parts[0].cell_type]
    assert w.stacks.vibration.shape[-1] == round(2.0 * ct.vibration.rate_hz)
    assert np.unique(w.stacks.vibration_t_ns[:, 0]).size == len(w.cells)  # a clock per cell, as a driver stamps
    d = robot.descriptor
    desc = describe_blocks(robot, w.cells, stacks=w.stacks, block_s=d.block_s, block_hop_s=d.block_hop_s,
                           groups=d.groups)
    assert [bp.cells_in_contact for bp in desc.body_parts] == [len(p.cells) for p in robot.body_parts]
    assert np.isfinite(desc.values).all()
    again = windowing.rehearsal_window(robot, 2.0, *dtypes)
    assert np.array_equal(again.stacks.vibration, w.stacks.vibration)  # seeded: the same noise every time
