"""``describe_window`` batches cells by cell type; results equal the per-body-part path exactly.

The window node's path gates, checks saturation and computes the per-cell
quantities once per *cell type* (all its body parts' cells stacked) and then
averages per body part.  The reference here is the previous path: one
``_body_part_descriptor`` per body part (gate, kernel and
``reduce_body_part`` on that body part's cells only).  Hypothesis draws
robots' windows with cells out of contact, invalid and gap cells, missing
cells, NaN force, saturated ADCs, per-cell time bases, mixed window shapes
and dtypes, float data and integers too large for exact moments, and body
parts of 1 to 12 cells; every value, flag, count and mean force must be the
same (``array_equal``), in ``averaged`` and ``per_channel`` mode, ``concat``
and ``pooled`` layout.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_descriptors_ros.core import aggregation
from tactile_descriptors_ros.core.aggregation import CellSignals, describe_window, pool_body_parts
from tactile_descriptors_ros.core.robot import load_robot, parse_robot

MS = 1_000_000


def _modality(symbol: str, rate_hz: float, axes: list, bits: int = 12, signed: bool = False) -> dict:
    return {"symbol": symbol, "rate_hz": rate_hz, "adc_bits": bits, "signed": signed, "unit": "count",
            "si_per_count": 1.0, "axes": [{"name": n, "channels": ch} for n, ch in axes]}


def _robot(part_sizes: list[int]):
    """Three cell types (1 S / 4 V channels in 2 axes; 3 S axes / 3 V; pairwise 3 x 3), parts interleaved."""
    types = {
        "mono": {"vibration": _modality("p", 1000.0, [("", ["p"])]),
                 "deformation": _modality("e", 250.0, [("a", ["e1", "e2"]), ("b", ["e3", "e4"])]),
                 "force": {"channels": ["e1"], "n_per_count": 0.01, "rate_hz": 250.0}},
        "skin": {"vibration": _modality("a", 1000.0, [("x", ["ax"]), ("y", ["ay"]), ("z", ["az"])], 10, True),
                 "deformation": _modality("F", 250.0, [("", ["f1", "f2", "f3"])]),
                 "force": {"channels": ["f1", "f2", "f3"], "n_per_count": 0.01, "rate_hz": 250.0},
                 "correlate": "each_with_all"},
        "pair": {"vibration": _modality("s", 1000.0, [("x", ["sx"]), ("y", ["sy"]), ("z", ["sz"])]),
                 "deformation": _modality("v", 250.0, [("x", ["vx"]), ("y", ["vy"]), ("z", ["vz"])]),
                 "force": {"channels": ["vx"], "n_per_count": 0.01, "rate_hz": 250.0},
                 "correlate": "pairwise"},
    }
    names = list(types)
    parts, cid = [], 1
    for k, size in enumerate(part_sizes):
        parts.append({"name": f"part{k}", "cell_type": names[k % 3],
                      "cells": [{"id": cid + j} for j in range(size)]})
        cid += size
    data = {"robot": {"name": "batched"}, "cell_types": types, "body_parts": parts,
            "contact": {"force_threshold_n": 0.2}}
    return parse_robot(data, source="<test robot>")


def _cell(rng, ct, n_fast: int, *, dtype, shift_ns: int, force: float, nan_force: bool,
          big: bool, saturate: bool) -> CellSignals:
    n_s, n_v = len(ct.vibration.channels), len(ct.deformation.channels)
    n_slow = (n_fast + 3) // 4 + 1
    t_s = shift_ns + np.arange(n_fast, dtype=np.int64) * MS
    t_v = shift_ns + (np.arange(n_slow, dtype=np.int64) - 1) * 4 * MS
    lo_s, hi_s = ct.vibration.adc_range
    if np.dtype(dtype).kind == "u":
        lo_s = 0
    s = rng.integers(lo_s, hi_s + 1, (n_s, n_fast))
    if rng.random() < 0.3:  # ties and flat channels
        s = s // 64 * 64
        s[rng.integers(0, n_s)] = s[0, 0] if n_fast else 0
    v = rng.integers(0, 4096, (n_v, n_slow))
    if saturate and n_fast:
        s[0, : max(1, n_fast // 10)] = hi_s
    if big:
        s = s.astype(np.int64) * (1 << 40)
    f = np.full(n_slow, force)
    if nan_force:
        f[:: 2] = np.nan
    return CellSignals(s.astype(dtype) if not big else s, t_s, v.astype(dtype), t_v, f)


def _window(robot, seed: int, opts: dict) -> dict[int, CellSignals]:
    rng = np.random.default_rng(seed)
    cells = {}
    n_common = int(rng.integers(0, 50))
    dtype_common = rng.choice([np.int32, np.int16, np.int64, np.uint16])
    for part in robot.body_parts:
        ct = robot.cell_types[part.cell_type]
        for c in part.cells:
            if rng.random() < opts["missing"]:
                continue
            n = int(rng.integers(0, 50)) if rng.random() < opts["mixed_shapes"] else n_common
            dtype = np.float64 if rng.random() < opts["floats"] else dtype_common
            if rng.random() < opts["mixed_dtypes"]:
                dtype = rng.choice([np.int32, np.int16, np.int64])
            sig = _cell(rng, ct, n, dtype=dtype,
                        shift_ns=int(rng.integers(0, 3)) * MS if rng.random() < opts["own_time"] else 0,
                        force=float(rng.choice([0.0, 0.1, 0.2, 0.5, 2.0])), nan_force=rng.random() < 0.15,
                        big=rng.random() < opts["big"], saturate=rng.random() < 0.15)
            sig.valid = bool(rng.random() > 0.1)
            sig.gap = bool(rng.random() < 0.1)
            sig.invalid_samples = int(rng.random() < 0.1)
            cells[c.id] = sig
    return cells


def _per_body_part(robot, cells, layout: str, channels: str, threshold: float | None = None):
    """The previous describe_window: one body part at a time."""
    thr = robot.contact.force_threshold_n if threshold is None else threshold
    parts = tuple(aggregation._body_part_descriptor(p, robot.cell_types[p.cell_type], cells, thr, channels)
                  for p in robot.body_parts)
    if layout == "concat":
        return parts, np.concatenate([bp.values for bp in parts])
    return parts, pool_body_parts(robot, parts)[0]


def _assert_same(robot, cells, layout: str, channels: str) -> None:
    got = describe_window(robot, cells, layout=layout, channels=channels)
    parts, values = _per_body_part(robot, cells, layout, channels)
    assert np.array_equal(got.values, values, equal_nan=True)
    for a, b in zip(got.body_parts, parts):
        group = {"averaged": "paper", "per_channel": "per_channel"}[channels]  # labels carry the group
        assert (a.name, a.contact, a.cells_in_contact, a.cells_total, a.quality, a.labels) == \
               (b.name, b.contact, b.cells_in_contact, b.cells_total, b.quality,
                tuple(f"{group}/{lab}" for lab in b.labels))
        assert a.mean_force_n == b.mean_force_n
        assert np.array_equal(a.values, b.values, equal_nan=True)


options = st.fixed_dictionaries({
    "missing": st.sampled_from([0.0, 0.1]),
    "mixed_shapes": st.sampled_from([0.0, 0.0, 0.2]),
    "floats": st.sampled_from([0.0, 0.0, 0.2, 1.0]),
    "own_time": st.sampled_from([0.0, 0.3]),
    "big": st.sampled_from([0.0, 0.0, 0.1]),
    "mixed_dtypes": st.sampled_from([0.0, 0.0, 0.2]),
})


@settings(max_examples=80, deadline=None)
@given(st.lists(st.integers(1, 12), min_size=1, max_size=6), st.integers(0, 2**31), options,
       st.sampled_from(["concat", "pooled"]), st.sampled_from(["averaged", "per_channel"]))
def test_batched_equals_per_body_part(part_sizes, seed, opts, layout, channels):
    robot = _robot(part_sizes)
    _assert_same(robot, _window(robot, seed, opts), layout, channels)


@pytest.mark.parametrize("name", ["shadow_hand", "nao"])
@pytest.mark.parametrize("channels", ["averaged", "per_channel"])
def test_shipped_robots_identical_on_bench_windows(name, channels):
    from tactile_descriptors_ros.sim.synthetic import biotac_window, skin_window

    robot = load_robot(name)
    cells = biotac_window(robot, 0.5, seed=3) if name == "shadow_hand" else skin_window(robot, 0.5, seed=3)
    for k, cid in enumerate(sorted(cells)):  # some cells out of contact, one invalid
        if k % 5 == 1:
            cells[cid].force_n = cells[cid].force_n * 0.0
    cells[sorted(cells)[-1]].valid = False
    for layout in ("concat", "pooled"):
        _assert_same(robot, cells, layout, channels)


@pytest.mark.parametrize("channels", ["averaged", "per_channel"])
def test_single_channel_modality_in_a_large_body_part(channels):
    # numpy sums one column pairwise, several columns row after row: both must come out the same
    robot = _robot([12, 9, 10, 1])
    rng = np.random.default_rng(7)
    cells = {}
    for part in robot.body_parts:
        ct = robot.cell_types[part.cell_type]
        for c in part.cells:
            cells[c.id] = _cell(rng, ct, 40, dtype=np.int32, shift_ns=0, force=1.0, nan_force=False,
                                big=False, saturate=False)
    got = describe_window(robot, cells, layout="concat", channels=channels)
    assert got.body_parts[0].cells_in_contact == 12
    _assert_same(robot, cells, "concat", channels)


@pytest.mark.parametrize("chunk_samples", [1, 7 * 3 * 200])
def test_chunks_of_cells_change_nothing(monkeypatch, chunk_samples):
    from tactile_descriptors_ros.sim.synthetic import skin_window

    robot = load_robot("nao")
    cells = skin_window(robot, 0.2, seed=5)
    whole = describe_window(robot, cells, layout="concat")
    monkeypatch.setattr(aggregation, "STACK_CHUNK_SAMPLES", chunk_samples)
    chunked = describe_window(robot, cells, layout="concat")
    assert np.array_equal(whole.values, chunked.values)
    assert [bp.quality for bp in whole.body_parts] == [bp.quality for bp in chunked.body_parts]
    _assert_same(robot, cells, "concat", "averaged")


@pytest.mark.parametrize("chunk_samples", [None, 7 * 3 * 200])
def test_feature_groups_on_the_kernels_stacks_equal_their_own_stacking(monkeypatch, chunk_samples):
    """The non-kernel groups read the cells the kernel stacked (one chunk) or stack them themselves: same bits."""
    from tactile_descriptors_ros.sim.synthetic import skin_window

    robot = load_robot("nao")
    groups = robot.descriptor.groups
    cells = skin_window(robot, 0.5, seed=11)
    for k, cid in enumerate(sorted(cells)):  # some cells out of contact, one invalid
        if k % 4 == 1:
            cells[cid].force_n = cells[cid].force_n * 0.0
    cells[sorted(cells)[0]].valid = False
    if chunk_samples is not None:
        monkeypatch.setattr(aggregation, "STACK_CHUNK_SAMPLES", chunk_samples)
    own_stacks = []
    real_stack = aggregation._stack
    monkeypatch.setattr(aggregation, "_stack", lambda arrays, slot=None: (
        own_stacks.append(slot), real_stack(arrays, slot))[1])
    shared = describe_window(robot, cells, groups=groups)
    assert ("groups.vib" in own_stacks) == (chunk_samples is not None), own_stacks
    real_features = aggregation._type_features
    monkeypatch.setattr(aggregation, "_type_features", lambda sigs, cell_type, stacked=None, stacks=None:
                        real_features(sigs, cell_type))
    alone = describe_window(robot, cells, groups=groups)
    assert np.array_equal(shared.values, alone.values)
    assert [bp.quality for bp in shared.body_parts] == [bp.quality for bp in alone.body_parts]
