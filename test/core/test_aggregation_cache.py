"""``describe_window``'s cached per-robot plan and per-cell-type reduction give the same results on every call.

The batched path keeps, per robot object, the cell index, each body part's
cell ids and the concat labels, and per (cell type, channels) the columns
each output value averages; the stacking buffers are reused between calls.
Calling it again, with other cells, other window lengths, dtypes, modes or a
new robot object must give exactly what the per-body-part path gives, and
must not change a descriptor returned earlier.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest
from test_aggregation_batched import _assert_same, _robot, _window  # noqa: E402  (same directory)

from tactile_descriptors_ros.core import aggregation
from tactile_descriptors_ros.core.aggregation import describe_window
from tactile_descriptors_ros.core.robot import load_robot
from tactile_descriptors_ros.errors import SignalError
from tactile_descriptors_ros.sim.synthetic import biotac_window, skin_window

_OPTS = {"missing": 0.1, "mixed_shapes": 0.0, "floats": 0.0, "own_time": 0.0, "big": 0.0, "mixed_dtypes": 0.0}


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).view(np.uint64)


def _same_bits(a, b) -> None:
    assert a.labels == b.labels
    assert np.array_equal(_bits(a.values), _bits(b.values))
    for x, y in zip(a.body_parts, b.body_parts, strict=True):
        assert (x.name, x.contact, x.cells_in_contact, x.cells_total, x.quality, x.labels, x.mean_force_n) == \
               (y.name, y.contact, y.cells_in_contact, y.cells_total, y.quality, y.labels, y.mean_force_n)
        assert np.array_equal(_bits(x.values), _bits(y.values))


@pytest.mark.parametrize("name", ["shadow_hand", "nao"])
@pytest.mark.parametrize("channels", ["averaged", "per_channel"])
def test_second_call_is_bit_identical_and_leaves_the_first_alone(name, channels):
    robot = load_robot(name)
    cells = biotac_window(robot, 0.5, seed=1) if name == "shadow_hand" else skin_window(robot, 0.5, seed=1)
    first = describe_window(robot, cells, channels=channels)
    kept = copy.deepcopy(first)
    second = describe_window(robot, cells, channels=channels)
    _same_bits(first, second)
    # another window through the same plan and buffers must not alter the first descriptor
    other = biotac_window(robot, 0.5, seed=2) if name == "shadow_hand" else skin_window(robot, 0.5, seed=2)
    third = describe_window(robot, other, channels=channels)
    assert not np.array_equal(third.values, first.values)
    _same_bits(first, kept)


def test_cells_shapes_dtypes_and_modes_changing_between_calls():
    robot = load_robot("nao")
    ids = sorted(robot.cell_index())
    windows = [skin_window(robot, 0.5, seed=3), skin_window(robot, 0.2, seed=4),
               skin_window(robot, 0.5, seed=5, dtype=np.int16), skin_window(robot, 1.0, seed=6, dtype=np.int64)]
    fewer = dict(windows[0])
    for cid in ids[::3]:  # cells missing: GAP, other counts per body part
        del fewer[cid]
    out_of_contact = skin_window(robot, 0.5, seed=7)
    for cid in ids[:40]:  # whole body parts out of contact
        out_of_contact[cid].force_n = out_of_contact[cid].force_n * 0.0
    sequence = windows + [fewer, out_of_contact, windows[0], fewer, windows[1]]
    for _k, cells in enumerate(sequence):
        for channels in ("averaged", "per_channel"):
            for layout in ("concat", "pooled"):
                _assert_same(robot, cells, layout, channels)
        # a fresh robot object (a new plan) gives the same bits as the cached one
        _same_bits(describe_window(robot, cells), describe_window(load_robot("nao"), cells))


def test_robots_of_different_layouts_one_after_the_other():
    rng = np.random.default_rng(11)
    for _k in range(12):
        robot = _robot([int(x) for x in rng.integers(1, 13, rng.integers(1, 7))])
        cells = _window(robot, int(rng.integers(0, 2**31)), _OPTS)
        for channels in ("averaged", "per_channel"):
            _assert_same(robot, cells, "concat", channels)
            _assert_same(robot, cells, "pooled", channels)


def test_concat_labels_cached_per_channels_mode():
    robot = load_robot("shadow_hand")
    cells = biotac_window(robot, 0.5, seed=0)
    averaged = describe_window(robot, cells, layout="concat", channels="averaged")
    per_channel = describe_window(robot, cells, layout="concat", channels="per_channel")
    assert len(averaged.labels) == 5 * 8 and len(per_channel.labels) == 5 * 98
    assert averaged.labels == describe_window(robot, cells, layout="concat", channels="averaged").labels
    assert averaged.labels == tuple(f"{bp.name}/{lab}" for bp in averaged.body_parts for lab in bp.labels)
    assert per_channel.labels == tuple(f"{bp.name}/{lab}" for bp in per_channel.body_parts for lab in bp.labels)


def test_unknown_cells_still_rejected_after_the_plan_is_cached():
    robot = load_robot("shadow_hand")
    cells = biotac_window(robot, 0.5, seed=0)
    describe_window(robot, cells)
    bad = dict(cells)
    bad[999] = cells[next(iter(cells))]
    with pytest.raises(SignalError, match=r"\[999\]"):
        describe_window(robot, bad)


def test_reduction_matches_reduce_body_part_on_one_cell_type():
    # the cached column plan against reduce_body_part itself, cells of one body part all in contact
    robot = _robot([9, 4, 3])
    cells = _window(robot, 5, {**_OPTS, "missing": 0.0})
    for part in robot.body_parts:
        ct = robot.cell_types[part.cell_type]
        sigs = [cells[c.id] for c in part.cells]
        if not all(s.vibration.shape[1] >= 3 for s in sigs):
            continue
        feats = aggregation.cell_features(np.stack([s.vibration for s in sigs]), sigs[0].vibration_t_ns,
                                          np.stack([s.deformation for s in sigs]), sigs[0].deformation_t_ns,
                                          ct.vibration.rate_hz, ct.deformation.rate_hz)
        for channels in ("averaged", "per_channel"):
            want = aggregation.reduce_body_part(feats, np.ones(len(sigs), bool), ct, channels)
            got = aggregation._reduce_parts(feats, np.array([0]), np.array([len(sigs)]), ct, channels)
            assert np.array_equal(_bits(got[0]), _bits(want))


def test_a_cell_types_cached_hash_stays_in_its_process():
    """A cell type keys the per-type caches by a hash computed once: equal cell types hash equal, a changed
    one does not meet the cached hash, and a copy sent to another process (whose strings hash differently)
    hashes there as that process's own cell type, or its cache lookups would miss or collide."""
    import dataclasses
    import os
    import pickle
    import subprocess
    import sys

    ct = next(iter(load_robot("shadow_hand").cell_types.values()))
    fresh = next(iter(load_robot("shadow_hand").cell_types.values()))
    assert ct is not fresh and hash(ct) == hash(fresh) == hash(copy.deepcopy(ct))
    assert hash(dataclasses.replace(ct, name="other")) != hash(ct)
    sent = pickle.dumps(ct)
    code = ("import pickle, sys\nfrom tactile_descriptors_ros.core.robot import load_robot\n"
            "ct = pickle.loads(sys.stdin.buffer.read())\n"
            "own = next(iter(load_robot('shadow_hand').cell_types.values()))\n"
            "print(ct == own, hash(ct) == hash(own), hash(ct))")
    out = [subprocess.run([sys.executable, "-c", code], input=sent, capture_output=True, check=True,
                          env={**os.environ, "PYTHONHASHSEED": seed}).stdout.split()
           for seed in ("1", "2")]
    assert [o[:2] for o in out] == [[b"True", b"True"]] * 2
    assert out[0][2] != out[1][2]  # the seeds give other hashes: a hash carried over would be wrong in one
