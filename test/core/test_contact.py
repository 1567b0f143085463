"""Contact location: known answers, an independent reduction, and the simulator's ground truth."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_descriptors_ros.core import contact, fast
from tactile_descriptors_ros.core.contact import (
    ContactWindow,
    contact_wrench,
    locate_contact,
    reduce_chunk,
    reduce_skin_runs,
    site_weights,
)
from tactile_descriptors_ros.core.display import PartDisplay, PredictionHistory, softmax_confidence
from tactile_descriptors_ros.core.geometry import Taxels
from tactile_descriptors_ros.core.robot import load_robot
from tactile_descriptors_ros.core.windowing import CellChunk
from tactile_descriptors_ros.errors import SignalError

#: Stated accuracy of the centre of pressure against where the simulator pressed (docs/view.md).
BIOTAC_COP_M = 0.003
SKIN_COP_M = 0.008


def _cells(positions, normals=None) -> Taxels:
    pos = np.asarray(positions, dtype=float)
    nrm = np.tile([0.0, 0.0, 1.0], (len(pos), 1)) if normals is None else np.asarray(normals, dtype=float)
    return Taxels("p", "link", "cells", tuple(f"c{i}" for i in range(len(pos))), np.arange(len(pos)),
                  tuple(() for _ in pos), pos, nrm)


def test_two_equal_cells_press_at_their_midpoint():
    tax = _cells([[0.0, 0.0, 0.0], [0.02, 0.0, 0.0], [0.0, 0.05, 0.0]])
    est = locate_contact(tax, np.arange(3), np.array([1.0, 1.0, 0.01]), threshold_n=0.2, floor_n=0.05)
    assert est.in_contact and est.force_n == pytest.approx(2.0)  # the third cell's 0.01 N is below the floor
    assert np.allclose(est.centre_of_pressure, [0.01, 0.0, 0.0])
    assert np.allclose(est.normal, [0, 0, 1]) and list(est.active_cells) == [0, 1]


def test_no_force_is_no_contact_and_no_centre():
    tax = _cells([[0.0, 0.0, 0.0], [0.02, 0.0, 0.0]])
    est = locate_contact(tax, np.arange(2), np.array([0.1, np.nan]), threshold_n=0.2, floor_n=0.05)
    assert not est.in_contact and est.force_n == pytest.approx(0.1) and len(est.active_cells) == 0
    est = locate_contact(tax, np.arange(2), np.array([0.01, np.nan]), threshold_n=0.2, floor_n=0.05)
    assert est.force_n == 0.0 and not est.centre_of_pressure.any() and not est.normal.any()


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(0.0, 5.0), min_size=4, max_size=4))
def test_centre_of_pressure_lies_in_the_cells_hull(forces):
    pos = np.array([[0, 0, 0], [0.02, 0, 0], [0, 0.02, 0], [0.02, 0.02, 0.01]], dtype=float)
    est = locate_contact(_cells(pos), np.arange(4), np.array(forces), threshold_n=0.2, floor_n=0.05)
    if est.force_n > 0:
        assert np.all(est.centre_of_pressure >= pos.min(axis=0) - 1e-12)
        assert np.all(est.centre_of_pressure <= pos.max(axis=0) + 1e-12)


def test_wrench_pushes_inward_at_the_centre_of_pressure():
    tax = _cells([[0.01, 0.02, 0.03]], normals=[[0.0, 1.0, 0.0]])
    est = locate_contact(tax, np.arange(1), np.array([2.0]), threshold_n=0.2, floor_n=0.05)
    f, tau = contact_wrench(est)
    assert np.allclose(f, [0.0, -2.0, 0.0])
    assert np.allclose(tau, np.cross([0.01, 0.02, 0.03], [0.0, -2.0, 0.0]))


@settings(max_examples=100, deadline=None)
@given(st.lists(st.floats(-0.1, 0.1), min_size=3, max_size=3), st.lists(st.floats(-1, 1), min_size=3, max_size=3),
       st.floats(0.0, 20.0))
def test_wrench_torque_is_numpys_cross_product(cop, normal, force_n):
    from tactile_descriptors_ros.core.contact import ContactEstimate

    est = ContactEstimate(True, force_n, np.array(cop), np.array(normal), np.zeros(0), np.zeros(0),
                          np.zeros(0, np.int64), 0.0)
    f, tau = contact_wrench(est)
    assert np.allclose(f, -force_n * np.array(normal))
    assert np.allclose(tau, np.cross(cop, f), rtol=1e-12, atol=1e-15)


def test_biotac_electrode_that_departs_locates_the_contact():
    robot = load_robot("shadow_hand")
    tax = robot.geometry.taxels(robot, "index")
    change = np.full(19, 5.0)  # every electrode rose by 5 counts (common mode)
    change[6] += 120.0  # e7, near the tip
    est = locate_contact(tax, np.array([1]), np.array([1.5]), change, threshold_n=0.2, floor_n=0.05)
    assert np.allclose(est.centre_of_pressure, tax.positions[6], atol=1e-9)
    assert est.taxel_force_n.sum() == pytest.approx(1.5) and est.taxel_force_n[6] == pytest.approx(1.5)
    # no electrode departs: the force is shared equally, the centre is the electrodes' centroid
    flat = locate_contact(tax, np.array([1]), np.array([1.5]), np.full(19, 5.0), threshold_n=0.2, floor_n=0.05)
    assert np.allclose(flat.centre_of_pressure, tax.positions.mean(axis=0))
    assert site_weights(np.array([1.0, 2.0, 3.0])).tolist() == [1.0, 0.0, 1.0]


def test_vectorised_skin_runs_reduce_like_one_chunk_per_run():
    rng = np.random.default_rng(3)
    ids = np.array([85, 86, 85])
    fc, ac = np.array([3, 2, 4]), np.array([10, 8, 12])
    force = rng.integers(20, 900, (fc.sum(), 3)).astype(np.uint16)
    force[4, 1] = 65535  # an invalid sensor: the whole sample is left out
    off_f = np.arange(fc.sum(), dtype=np.int64) * 4_000_000
    tare = rng.uniform(15, 25, (3, 3))
    accel = rng.integers(-300, 300, (3, ac.sum())).astype(np.int16)
    accel[1, 5] = -32768
    runs = reduce_skin_runs(ids, force, fc, off_f, tare, 0.002442, accel, ac, 0.0383, 1_000_000_000)
    f0 = a0 = 0
    for k in range(3):
        fs = slice(f0, f0 + fc[k])
        as_ = slice(a0, a0 + ac[k])
        ok = np.all(force[fs] != 65535, axis=1)
        fn = np.where(ok, ((force[fs].astype(float) - tare[k]).mean(axis=1)) * 0.002442, np.nan)
        chunk = CellChunk(accel[:, as_].astype(np.int32), np.arange(ac[k]), force[fs].T.astype(np.int32),
                          off_f[fs] + 1_000_000_000, fn, off_f[fs] + 1_000_000_000,
                          vibration_valid=np.all(accel[:, as_] != -32768, axis=0), deformation_valid=ok,
                          deformation_tare=tare[k])
        ref = reduce_chunk(chunk, 0.0383)
        assert runs.force_sum_n[k] == pytest.approx(ref.force_sum_n) and runs.force_count[k] == ref.force_count
        assert np.allclose(runs.deformation_sum[k], ref.deformation_sum)
        assert runs.vibration_sumsq[k] == pytest.approx(ref.vibration_sumsq)
        assert runs.vibration_count[k] == ref.vibration_count
        assert runs.newest_ns[k] == ref.newest_ns and runs.oldest_ns[k] == ref.oldest_ns
        f0, a0 = f0 + fc[k], a0 + ac[k]
    w = ContactWindow([85, 86], 3)
    assert w.add_runs(runs) == 0 and w.force_count.tolist() == [runs.force_count[[0, 2]].sum(), runs.force_count[1]]
    # cells of another body part are left out and counted, whatever their id's place among this part's
    for foreign in ([86, 90], [84, 86], [1, 2]):
        w = ContactWindow(foreign, 3)
        assert w.add_runs(runs) == int(np.isin(ids, foreign, invert=True).sum())
        assert w.force_count.tolist() == [int(runs.force_count[ids == c].sum()) for c in foreign]
        assert w.added == int(np.isin(ids, foreign).sum())


def _random_message(rng: np.random.Generator, runs: int) -> dict:
    """A body part's message as the contact node reads it: rclpy's field dtypes, invalid samples, tares far
    from the counts, offsets on both sides of the stamp."""
    fc = rng.integers(0, 7, runs).astype(np.uint32)
    ac = rng.integers(0, 12, runs).astype(np.uint32)
    force = rng.integers(0, 4096, (int(fc.sum()), 3)).astype(np.uint16)
    force[rng.random(force.shape) < 0.05] = 65535
    accel = rng.integers(-2048, 2048, (3, int(ac.sum()))).astype(np.int16)
    accel[rng.random(accel.shape) < 0.05] = -32768
    tare = rng.uniform(-1e5, 1e5, runs * 3) * rng.choice([1.0, 1e-3], runs * 3)
    off = np.sort(rng.integers(-5_000_000, 20_000_000, int(fc.sum()))).astype(np.int64)
    return dict(cell_ids=rng.integers(0, 1000, runs).astype(np.uint32), force=force.reshape(-1), force_count=fc,
                force_offset_ns=off, force_tare=tare, force_n_per_count=float(rng.uniform(1e-4, 1e-2)),
                accel=accel, accel_count=ac, accel_si_per_count=float(rng.choice([0.0383, 1.0, 1e-3])),
                stamp_ns=int(rng.integers(0, 2**62)) * int(rng.choice([1, -1])) // 4)


def _bits(runs) -> dict:
    return {name: (np.asarray(getattr(runs, name)).dtype, np.asarray(getattr(runs, name)).shape,
                   np.ascontiguousarray(getattr(runs, name)).tobytes()) for name in runs.__dataclass_fields__}


@pytest.mark.skipif(fast.kernel_module() is None, reason="no compiled backend: numpy sums every message")
@settings(max_examples=300, deadline=None)
@given(st.integers(0, 24), st.integers(0, 2**32 - 1))
def test_compiled_run_sums_give_numpys_bits(runs, seed):
    """The compiled sums of a message's runs equal numpy's to the bit (sums in the same order), and the
    compiled path serves such a message."""
    rng = np.random.default_rng(seed)
    msg = _random_message(rng, runs)
    args = (np.asarray(msg["force_count"], np.int64), msg["force"].reshape(-1, 3),
            msg["force_tare"].reshape(-1, 3), msg["force_offset_ns"], msg["stamp_ns"],
            np.asarray(msg["accel_count"], np.int64), msg["accel"], msg["accel_si_per_count"], 65535, -32768)
    assert contact._run_sums_compiled(*args) is not None
    compiled = reduce_skin_runs(**msg)
    contact.COMPILED_SUMS = False
    try:
        reference = reduce_skin_runs(**msg)
    finally:
        contact.COMPILED_SUMS = True
    assert _bits(compiled) == _bits(reference)


@pytest.mark.skipif(fast.kernel_module() is None, reason="no compiled backend: numpy sums every message")
def test_run_sums_of_other_layouts_and_dtypes_take_numpy():
    """A bag reader's read-only fields, strided views or other dtypes take numpy (no other compiled variant
    while a node runs), with the same result."""
    msg = _random_message(np.random.default_rng(7), 9)
    want = _bits(reduce_skin_runs(**msg))
    read_only = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in msg.items()}
    read_only["force"].flags.writeable = False
    strided = dict(msg, accel=np.asfortranarray(msg["accel"]))
    wide = dict(msg, force=msg["force"].astype(np.int64))
    for other in (read_only, strided, wide):
        f, a = np.asarray(other["force"]).reshape(-1, 3), np.asarray(other["accel"])
        assert contact._run_sums_compiled(np.asarray(other["force_count"], np.int64), f,
                                          other["force_tare"].reshape(-1, 3), other["force_offset_ns"], 0,
                                          np.asarray(other["accel_count"], np.int64), a, 1.0, 65535, -32768) is None
        assert _bits(reduce_skin_runs(**other)) == want


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 6), st.integers(0, 2**32 - 1))
def test_merging_message_windows_equals_adding_their_runs_in_one_window(messages, seed):
    """The display period's window (merged per message) holds what one window given every run would."""
    rng = np.random.default_rng(seed)
    cells = [40, 7, 19, 3]
    direct, merged = ContactWindow(cells, 3), ContactWindow(cells, 3)
    one = ContactWindow(cells, 3)
    for m in range(messages):
        ids = rng.choice(cells + [99], size=int(rng.integers(1, 6)))  # 99: not of this body part
        fc, ac = rng.integers(0, 4, ids.size), rng.integers(0, 6, ids.size)
        force = rng.integers(20, 900, (fc.sum(), 3)).astype(np.uint16)
        force[rng.random(fc.sum()) < 0.2, 0] = 65535
        accel = rng.integers(-300, 300, (3, ac.sum())).astype(np.int16)
        runs = reduce_skin_runs(ids, force, fc, np.arange(fc.sum(), dtype=np.int64) * 4_000_000,
                                rng.uniform(15, 25, (ids.size, 3)), 0.002442, accel, ac, 0.0383,
                                (m + 1) * 1_000_000_000)
        direct.add_runs(runs)
        one.reset()
        one.add_runs(runs)
        assert merged.merge(one) == bool(np.isin(ids, cells).any())
    for name in ("force_sum", "force_count", "deformation_sum", "deformation_count", "newest_ns"):
        assert np.allclose(getattr(merged, name), getattr(direct, name)), name
    assert merged.vibration_sumsq == pytest.approx(direct.vibration_sumsq)
    assert (merged.vibration_count, merged.start_ns, merged.end_ns, merged.added) == \
        (direct.vibration_count, direct.start_ns, direct.end_ns, direct.added)
    with pytest.raises(SignalError, match="same cells"):
        merged.merge(ContactWindow(cells[::-1], 3))


def test_display_keeps_a_cells_last_force_and_greys_stale_ones():
    tax = _cells([[0.0, 0.0, 0.0], [0.02, 0.0, 0.0]])
    d = PartDisplay(tax, [0, 1], 3, threshold_n=0.2, floor_n=0.05, stale_s=0.5)

    def chunk(force, t_ns):
        return reduce_chunk(CellChunk(np.zeros((3, 2)), np.zeros(2, np.int64), np.zeros((3, 1)),
                                      np.array([t_ns]), np.array([force]), np.array([t_ns])))

    d.add(0, chunk(1.0, 1_000_000_000), wall_s=10.0)
    d.add(1, chunk(0.5, 1_000_000_000), wall_s=10.0)
    f = d.tick(1_000_000_000, 10.0)
    assert f.contact.cell_force_n.tolist() == [1.0, 0.5] and not f.cell_stale.any()
    d.add(0, chunk(2.0, 1_300_000_000), wall_s=10.3)  # cell 1 sends nothing this period: it keeps 0.5 N
    f = d.tick(1_300_000_000, 10.3)
    assert f.contact.cell_force_n.tolist() == [2.0, 0.5] and not f.cell_stale.any()
    d.add(0, chunk(2.0, 1_700_000_000), wall_s=10.7)  # 0.7 s since cell 1's last sample: stale
    f = d.tick(1_700_000_000, 10.7)
    assert f.cell_stale.tolist() == [False, True] and np.isnan(f.contact.cell_force_n[1])
    f = d.tick(1_700_000_000, 11.5)  # nothing for 0.8 s of wall time: the whole part is stale
    assert f.cell_stale.all() and not f.contact.in_contact


def test_prediction_history_joins_descriptors_predictions_and_labels():
    h = PredictionHistory()
    h.descriptor(3, 5_000_000_000, ["thumb", "index"], [False, True])
    e = h.prediction(3, 5_000_000_000, "cork", ["cork", "felt"], [1.0, -1.0], True)
    assert e.body_parts == ("index",) and e.confidence == pytest.approx(1 / (1 + np.exp(-2.0)))
    assert e.correct is None
    h.label(0, "felt")  # 0: the latest exploration
    assert h.latest.label == "felt" and h.latest.correct is False
    assert softmax_confidence([0.0, 0.0]).tolist() == [0.5, 0.5]


def _sim_chunk(rec, ct, t0: int, t1: int, lead_ns: int):
    """The cell's samples in [t0, t1) as the drivers would send them tared (the first 0.5 s as the tare)."""
    if rec.kind == "biotac":
        pdc, el, pac = rec.streams["pdc"], rec.streams["electrodes"], rec.streams["pac"]
        tare_p = pdc.counts[0][pdc.t_ns < lead_ns].mean()
        tare_e = el.counts[:, el.t_ns < lead_ns].mean(axis=1)
        s, se, sp = [(x.t_ns >= t0) & (x.t_ns < t1) for x in (pdc, el, pac)]
        return CellChunk(pac.counts[:, sp], pac.t_ns[sp], el.counts[:, se], el.t_ns[se],
                         (pdc.counts[0][s] - tare_p) * ct.force.n_per_count, pdc.t_ns[s], deformation_tare=tare_e)
    f, a = rec.streams["force"], rec.streams["accel"]
    tare = f.counts[:, f.t_ns < lead_ns].mean(axis=1)
    s, sa = (f.t_ns >= t0) & (f.t_ns < t1), (a.t_ns >= t0) & (a.t_ns < t1)
    fn = (f.counts[:, s] - tare[:, None]).mean(axis=0) * ct.force.n_per_count
    return CellChunk(a.counts[:, sa], a.t_ns[sa], f.counts[:, s], f.t_ns[s], fn, f.t_ns[s], deformation_tare=tare)


@pytest.mark.parametrize("scene_name, tolerance_m", [("touch_shadow_hand", BIOTAC_COP_M), ("touch_nao", SKIN_COP_M)])
def test_centre_of_pressure_is_where_the_simulator_pressed(scene_name, tolerance_m):
    from tactile_descriptors_ros.sim.engine import simulate
    from tactile_descriptors_ros.sim.scene import load_scene

    scene = load_scene(scene_name)
    res = simulate(scene)
    robot = scene.robot
    assert len(res.contact_points) >= 9
    errors = []
    for cp in res.contact_points:
        timing = res.explorations[cp["exploration"]]
        part = robot.body_part(cp["body_part"])
        ct = robot.cell_types[part.cell_type]
        win = ContactWindow([c.id for c in part.cells], len(ct.deformation.channels))
        for cell in part.cells:
            chunk = _sim_chunk(res.cells[cell.id], ct, timing.slide_start_ns, timing.slide_end_ns,
                               scene.start_ns + 500_000_000)
            win.add(cell.id, reduce_chunk(chunk, ct.vibration.si_per_count))
        est = win.contact(robot.geometry.taxels(robot, part.name), threshold_n=robot.contact.force_threshold_n,
                          floor_n=0.05)
        assert est.in_contact and cp["frame_id"] == robot.geometry.part_links[part.name]
        errors.append(float(np.linalg.norm(est.centre_of_pressure - np.asarray(cp["xyz"]))))
        # the total force is what the simulator pressed with, to within its texture and noise
        assert est.force_n == pytest.approx(timing.exploration.part_force_n[part.name], rel=0.3)
    assert max(errors) <= tolerance_m, errors
