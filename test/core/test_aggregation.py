"""Contact gate, per-body-part aggregation (eq. 11, 17, 28) and whole-robot layouts (eq. 12, 18, 29)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from tactile_descriptors_ros.core.aggregation import (
    CellSignals,
    cell_features,
    contact_gate,
    describe_window,
)
from tactile_descriptors_ros.core.alignment import hold_indices, zero_order_hold
from tactile_descriptors_ros.core.descriptors import Quality, hjorth
from tactile_descriptors_ros.core.groups import body_part_layout
from tactile_descriptors_ros.core.robot import load_robot, parse_robot
from tactile_descriptors_ros.errors import SignalError

RNG = np.random.default_rng(42)


def _biotac_cell(rng, n_frames=200, force=1.0, pac_per_frame=22):
    frame_t = np.arange(n_frames, dtype=np.int64) * 10_000_000
    pac_t = (frame_t[:, None] + (np.arange(pac_per_frame) * 10_000_000) // pac_per_frame).ravel()
    pac = rng.integers(0, 4096, size=(1, pac_t.size))
    ele = rng.integers(0, 4096, size=(19, n_frames))
    return CellSignals(pac, pac_t, ele, frame_t, np.full(n_frames, force))


def _skin_cell(rng, force=1.0, n_acc=400, n_f=100):
    ta = np.arange(n_acc, dtype=np.int64) * 1_000_000
    tf = np.arange(n_f, dtype=np.int64) * 4_000_000
    return CellSignals(rng.integers(-512, 512, (3, n_acc)), ta, rng.integers(0, 4096, (3, n_f)), tf,
                       np.full(n_f, force))


# ------------------------------------------------------------------ alignment
def test_zero_order_hold_holds_each_slow_sample_until_the_next():
    t_slow = np.array([10, 20, 30])
    v = np.array([[1, 2, 3]])
    t_fast = np.array([5, 10, 15, 20, 29, 30, 99])
    held, valid = zero_order_hold(t_slow, v, t_fast)
    np.testing.assert_array_equal(valid, [False, True, True, True, True, True, True])
    np.testing.assert_array_equal(held[0, valid], [1, 1, 2, 2, 3, 3])
    assert held.dtype == v.dtype  # integers stay integers
    np.testing.assert_array_equal(hold_indices(t_slow, t_fast), [-1, 0, 0, 1, 1, 2, 2])
    with pytest.raises(SignalError):
        hold_indices(np.array([3, 1]), t_fast)


# --------------------------------------------------------------- contact gate
def test_contact_gate_is_mean_force_at_least_threshold():
    gate = contact_gate([np.array([0.1, 0.3]), np.array([0.19, 0.2]), np.array([np.nan, 0.5]),
                         np.array([])], 0.2)
    np.testing.assert_array_equal(gate, [True, False, True, False])


# ----------------------------------------------------------- cell quantities
def test_cell_features_correlate_on_the_fast_time_base_with_held_slow_signal():
    rng = np.random.default_rng(0)
    cell = _biotac_cell(rng, n_frames=50)
    f = cell_features(cell.vibration[None], cell.vibration_t_ns, cell.deformation[None], cell.deformation_t_ns,
                      2200.0, 100.0)
    held, _ = zero_order_hold(cell.deformation_t_ns, cell.deformation, cell.vibration_t_ns)
    for e in (0, 7, 18):
        assert f.lin[0, 0, e] == pytest.approx(stats.pearsonr(cell.vibration[0], held[e]).statistic, abs=1e-12)
        assert f.nonlin[0, 0, e] == pytest.approx(stats.spearmanr(cell.vibration[0], held[e]).statistic, abs=1e-12)
    h = hjorth(cell.deformation, 100.0)
    np.testing.assert_allclose(f.mob_v[0], h.mobility)


# ------------------------------------------------- hand-computed aggregation
def test_biotac_finger_eq17_eight_values_by_hand():
    robot = load_robot("shadow_hand")
    rng = np.random.default_rng(1)
    cell = _biotac_cell(rng)
    d = describe_window(robot, {1: cell}, channels="averaged")
    index = d.body_parts[1]
    assert index.name == "index" and index.contact and index.cells_in_contact == 1
    assert index.labels == tuple(f"paper/{q}" for q in ("A_pac", "A_E", "M_pac", "M_E", "C_pac", "C_E", "L_pac_E",
                                                          "N_pac_E"))
    hp = hjorth(cell.vibration[0], 2200.0)
    he = hjorth(cell.deformation, 100.0)
    held, _ = zero_order_hold(cell.deformation_t_ns, cell.deformation, cell.vibration_t_ns)
    lin = [stats.pearsonr(cell.vibration[0], held[e]).statistic for e in range(19)]
    non = [stats.spearmanr(cell.vibration[0], held[e]).statistic for e in range(19)]
    expected = [hp.activity, he.activity.mean(), hp.mobility, he.mobility.mean(),
                hp.complexity, he.complexity.mean(), np.mean(lin), np.mean(non)]
    np.testing.assert_allclose(index.values, np.array(expected, dtype=float), rtol=1e-10, atol=1e-12)
    # eq. 18: five fingers x 8, fingers without data are zeros and flagged
    assert d.values.shape == (40,)
    np.testing.assert_array_equal(d.values[8:16], index.values)
    assert not d.body_parts[0].contact and np.all(d.values[:8] == 0)
    assert d.body_parts[0].quality & Quality.NO_CONTACT
    assert d.labels[8] == "index/paper/A_pac"


def test_skin_body_part_eq28_eighteen_values_by_hand_with_gate():
    robot = load_robot("nao")
    rng = np.random.default_rng(2)
    hand = robot.body_part("left_hand")
    cells = {c.id: _skin_cell(rng) for c in hand.cells[:3]}
    cells[hand.cells[3].id] = _skin_cell(rng, force=0.1)  # below F_t = 0.2 N: gated out
    d = describe_window(robot, cells, channels="averaged")
    bp = d.body_parts[0]
    assert bp.labels == tuple("paper/" + q for q in (
        "A_a_x", "A_a_y", "A_a_z", "A_F", "M_a_x", "M_a_y", "M_a_z", "M_F", "C_a_x", "C_a_y", "C_a_z", "C_F",
        "L_a_F_x", "L_a_F_y", "L_a_F_z", "N_a_F_x", "N_a_F_y", "N_a_F_z"))
    assert bp.cells_in_contact == 3 and bp.cells_total == 14
    touching = [cells[c.id] for c in hand.cells[:3]]
    acc = np.array([hjorth(c.vibration, 1000.0) for c in touching])  # (cell, quantity, axis)
    frc = np.array([hjorth(c.deformation, 250.0) for c in touching])
    lin = np.zeros((3, 3))
    for k, c in enumerate(touching):
        held, _ = zero_order_hold(c.deformation_t_ns, c.deformation, c.vibration_t_ns)
        for ax in range(3):
            lin[k, ax] = np.mean([stats.pearsonr(c.vibration[ax], held[j]).statistic for j in range(3)])
    expected_a = acc[:, 0, :].mean(axis=0)  # A per axis over cells
    np.testing.assert_allclose(bp.values[0:3], expected_a, rtol=1e-10)
    assert bp.values[3] == pytest.approx(frc[:, 0, :].mean(), rel=1e-10)  # A_F over cells and sensors
    np.testing.assert_allclose(bp.values[4:7], acc[:, 1, :].mean(axis=0), rtol=1e-10)
    np.testing.assert_allclose(bp.values[12:15], lin.mean(axis=0), rtol=1e-9, atol=1e-12)
    assert d.values.shape == (126,)  # eq. 29: 7 body parts x 18


def test_general_eq11_form_has_24_values_for_two_three_axis_modalities():
    axes = lambda p: [{"name": a, "channels": [f"{p}{a}"]} for a in "xyz"]  # noqa: E731
    robot = parse_robot({
        "robot": {"name": "ur10"},
        "cell_types": {"tri": {
            "vibration": {"symbol": "S", "rate_hz": 1000.0, "axes": axes("s")},
            "deformation": {"symbol": "V", "rate_hz": 250.0, "axes": axes("v")},
            "force": {"channels": ["vx"], "n_per_count": 1.0, "rate_hz": 250.0},
            "correlate": "pairwise"}},
        "body_parts": [{"name": "tool", "cell_type": "tri", "cells": [{"id": 0}]}],
    })
    labels = body_part_layout(robot.cell_types["tri"])
    assert len(labels) == 24
    assert labels[-3:] == ("N_S_V_x", "N_S_V_y", "N_S_V_z")
    rng = np.random.default_rng(3)
    d = describe_window(robot, {0: _skin_cell(rng)})
    assert d.values.shape == (24,) and d.body_parts[0].contact


def test_per_channel_mode_keeps_98_values_per_biotac():
    robot = load_robot("shadow_hand")
    d = describe_window(robot, {1: _biotac_cell(np.random.default_rng(4))}, channels="per_channel")
    assert d.values.shape == (5 * 98,)
    bp = d.body_parts[1]
    averaged = describe_window(robot, {1: _biotac_cell(np.random.default_rng(4))}, channels="averaged").body_parts[1]
    # the averaged descriptor is the mean of the per-channel one (electrode blocks)
    assert averaged.values[1] == pytest.approx(bp.values[1:20].mean())
    assert averaged.values[6] == pytest.approx(bp.values[60:79].mean())


def test_pooled_mode_is_the_mean_over_parts_in_contact():
    robot = load_robot("shadow_hand")
    rng = np.random.default_rng(5)
    cells = {0: _biotac_cell(rng), 2: _biotac_cell(rng), 4: _biotac_cell(rng, force=0.0)}
    concat = describe_window(robot, cells, channels="averaged")
    pooled = describe_window(robot, cells, layout="pooled", channels="averaged")
    assert pooled.values.shape == (8,)
    np.testing.assert_allclose(pooled.values, (concat.values[0:8] + concat.values[16:24]) / 2)
    assert pooled.labels[0] == "biotac/paper/A_pac"


def test_no_contact_anywhere_gives_zeros_and_flags():
    robot = load_robot("shadow_hand")
    d = describe_window(robot, {1: _biotac_cell(np.random.default_rng(6), force=0.05)}, channels="averaged")
    assert not d.contact and np.all(d.values == 0)
    assert all(bp.quality & Quality.NO_CONTACT for bp in d.body_parts)


def test_invalid_cell_is_left_out_and_flagged():
    robot = load_robot("nao")
    rng = np.random.default_rng(7)
    part = robot.body_part("chest")
    good = _skin_cell(rng)
    bad = _skin_cell(rng)
    bad.valid = False
    d1 = describe_window(robot, {part.cells[0].id: good}, channels="averaged")
    d2 = describe_window(robot, {part.cells[0].id: good, part.cells[1].id: bad}, channels="averaged")
    chest1, chest2 = d1.body_parts[-1], d2.body_parts[-1]
    np.testing.assert_allclose(chest2.values, chest1.values)
    assert chest2.quality & Quality.INVALID and chest2.cells_in_contact == 1


def test_unknown_cell_and_wrong_channel_count_raise():
    robot = load_robot("shadow_hand")
    rng = np.random.default_rng(8)
    with pytest.raises(SignalError, match="not in robot description"):
        describe_window(robot, {99: _biotac_cell(rng)})
    cell = _biotac_cell(rng)
    cell.deformation = cell.deformation[:18]
    with pytest.raises(SignalError, match="19 deformation channels"):
        describe_window(robot, {1: cell})


def test_descriptor_is_finite_for_flat_and_nan_signals():
    robot = load_robot("shadow_hand")
    rng = np.random.default_rng(9)
    flat = _biotac_cell(rng)
    flat.deformation = np.zeros_like(flat.deformation)
    nan = _biotac_cell(rng)
    nan.vibration = nan.vibration.astype(float)
    nan.vibration[0, 10] = np.nan
    d = describe_window(robot, {1: flat, 2: nan}, channels="averaged")
    assert np.all(np.isfinite(d.values))
    assert d.body_parts[1].quality & Quality.FLAT
    assert d.body_parts[2].quality & Quality.NONFINITE


def test_stacked_extras_and_tares_equal_the_per_cell_path_whatever_the_cells_hold():
    """The levels group's inputs stacked at once (float64 extras and tares, or none) or cell by cell (else)."""
    from tactile_descriptors_ros.core.aggregation import _extra_of, _extras_of, _tare_of, _tares_of

    nao = load_robot("nao")
    ct = nao.cell_types[nao.body_parts[0].cell_type]
    rng = np.random.default_rng(3)
    n_x, n_v, n = len(ct.extra_channels), len(ct.deformation.channels), 50

    def cell(extra, tare=None):
        return CellSignals(np.zeros((3, 4 * n), np.int32), np.arange(4 * n, dtype=np.int64),
                           rng.integers(0, 900, (n_v, n)).astype(np.int32), 4 * np.arange(n, dtype=np.int64),
                           np.ones(n), extra=extra, deformation_tare=tare)

    floats = [cell(rng.normal(size=(n_x, n))) for _ in range(4)]
    mixed = [*floats[:2], cell(None), cell(rng.normal(size=(n_x, n)).astype(np.float32), np.full(n_v, 7.0))]
    tared = [cell(rng.normal(size=(n_x, n)), rng.normal(size=n_v)) for _ in range(3)]
    for sigs in (floats, mixed, tared):
        ids = list(range(len(sigs)))
        want_x = np.stack([_extra_of(s, ct, c) for s, c in zip(sigs, ids)])
        want_t = np.stack([_tare_of(s, n_v, c) for s, c in zip(sigs, ids)])
        np.testing.assert_array_equal(_extras_of(sigs, ct, ids), want_x)
        np.testing.assert_array_equal(_tares_of(sigs, n_v, ids), want_t)
    assert np.isnan(_extras_of(mixed, ct, [0, 1, 2, 3])[2]).all()
    with pytest.raises(SignalError, match="cell 11: expected extra channels"):
        _extras_of([floats[0], cell(np.zeros((n_x, n - 1)))], ct, [10, 11])
