"""The simulator: determinism, integer streams, effects computed only when declared, each effect on and off."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from tactile_descriptors_ros.errors import SceneError
from tactile_descriptors_ros.sim import engine, iter_simulate, parse_scene, simulate
from tactile_descriptors_ros.sim.engine import FAULT_CORRUPT, FAULT_PARITY

HAND = {
    "scene": {"name": "t", "robot": "shadow_hand", "seed": 11, "lead_in_s": 0.5},
    "effects": {"normal_force": {"ramp_s": 0.1}},
    "explorations": [{"materials": ["cork", "steel"], "repeat": 1, "body_parts": ["index", "middle"],
                      "motion": "lateral", "force_n": 2.0, "speed_m_s": 0.03, "duration_s": 2.0, "pause_s": 0.5}],
}
NAO = {
    "scene": {"name": "n", "robot": "nao", "seed": 5, "lead_in_s": 0.5},
    "effects": {"normal_force": {}},
    "explorations": [{"material": "param:box", "motion": "large_object", "weight_g": 1500, "body_parts": "all",
                      "slide_m": 0.03, "pause_s": 0.3}],
}


def scene_with(base, **effects):
    data = copy.deepcopy(base)
    data["effects"].update(effects)
    return parse_scene(data)


def cell(res, part):
    return next(c for c in res.cells.values() if c.body_part == part)


def in_contact(stream, timing):
    return (stream.t_ns >= timing.slide_start_ns) & (stream.t_ns < timing.slide_end_ns)


ALL_HAND = {"texture_vibration": {}, "electrode_deformation": {}, "stick_slip": {}, "sensor_noise": {},
            "bias_drift": {}, "adc": {}, "dropped_frames": {"probability": 0.01}, "bad_parity": {"probability": 0.01},
            "corrupt_frames": {"probability": 0.01}, "unplug": {"events": [{"cell": 2, "at_s": 1.0, "for_s": 0.5}]}}


def test_same_seed_same_output_other_seed_other_output():
    a = simulate(scene_with(HAND, **ALL_HAND))
    b = simulate(scene_with(HAND, **ALL_HAND))
    for cid in a.cells:
        for name, st in a.cells[cid].streams.items():
            other = b.cells[cid].streams[name]
            for attr in ("t_ns", "counts", "seq", "fault"):
                assert np.array_equal(getattr(st, attr), getattr(other, attr)), (cid, name, attr)
    data = copy.deepcopy(HAND)
    data["effects"].update(ALL_HAND)
    c = simulate(parse_scene(data, seed=12))
    assert not np.array_equal(c.cells[1].streams["pac"].counts, a.cells[1].streams["pac"].counts)


def test_streams_are_integer_counts_with_int64_ns_stamps():
    res = simulate(scene_with(HAND, texture_vibration={}, electrode_deformation={}, adc={}))
    c = cell(res, "index")
    assert set(c.streams) == {"pac", "pdc", "tac", "tdc", "electrodes"}
    pac, el = c.streams["pac"], c.streams["electrodes"]
    assert pac.rate_hz == 2200.0 and el.rate_hz == 100.0 and el.counts.shape[0] == 19
    assert pac.counts.shape[1] == 22 * el.counts.shape[1]
    for st in c.streams.values():
        assert st.t_ns.dtype == np.int64 and np.all(np.diff(st.t_ns) > 0)
        assert np.issubdtype(st.counts.dtype, np.integer)
        lo, hi = st.adc_range
        assert st.counts.min() >= lo and st.counts.max() <= hi
    assert np.array_equal(np.diff(pac.t_ns[:22]), np.diff(pac.t_ns[:22]))  # 22 per 10 ms frame
    assert pac.t_ns[22] - pac.t_ns[0] == 10_000_000
    n = simulate(scene_with(NAO, texture_vibration={}, adc={}))
    sc = next(iter(n.cells.values()))
    assert sc.streams["accel"].rate_hz == 1000.0
    assert min(c.streams["accel"].counts.min() for c in n.cells.values()) < 0  # signed
    assert sc.streams["force"].rate_hz == 250.0 and sc.streams["force"].counts.shape[0] == 3
    assert len(n.cells) == 116


def test_undeclared_effects_are_never_called(monkeypatch):
    called = []
    for name in engine.EFFECT_FUNCTIONS:
        original = engine.EFFECT_FUNCTIONS[name]

        def spy(ctx, params, _name=name, _orig=original):
            called.append(_name)
            return _orig(ctx, params)

        monkeypatch.setitem(engine.EFFECT_FUNCTIONS, name, spy)
    res = simulate(scene_with(HAND, texture_vibration={}))
    assert sorted(called) == ["normal_force", "texture_vibration"]
    assert res.effect_calls == {"normal_force": 1, "texture_vibration": 1}
    called.clear()
    res = simulate(scene_with(HAND, **ALL_HAND))
    assert sorted(called) == sorted(["normal_force", *ALL_HAND])
    assert all(v == 1 for v in res.effect_calls.values())


def test_without_effects_streams_sit_at_their_baselines():
    data = copy.deepcopy(HAND)
    data["effects"] = {}
    res = simulate(parse_scene(data))
    for c in res.cells.values():
        for st in c.streams.values():
            assert np.all(st.counts == st.counts[:, :1])
    assert res.effect_calls == {}


def test_normal_force_on_and_off():
    res = simulate(scene_with(HAND))
    pdc = cell(res, "index").streams["pdc"]
    t = res.explorations[0]
    rise = pdc.counts[0, in_contact(pdc, t)].mean() - pdc.counts[0, :10].mean()
    assert rise == pytest.approx(2.0 / 0.05, rel=0.35)  # F / n_per_count
    thumb = cell(res, "thumb").streams["pdc"]  # not in contact
    assert np.all(thumb.counts == thumb.counts[0, 0])
    data = copy.deepcopy(HAND)
    data["effects"] = {}
    off = cell(simulate(parse_scene(data)), "index").streams["pdc"]
    assert np.all(off.counts == off.counts[0, 0])


def test_texture_vibration_on_and_off():
    on = simulate(scene_with(HAND, texture_vibration={}))
    off = simulate(scene_with(HAND))
    t = on.explorations[0]
    p_on, p_off = cell(on, "index").streams["pac"], cell(off, "index").streams["pac"]
    assert p_on.counts[0, in_contact(p_on, t)].std() > 30
    assert p_off.counts[0].std() == 0
    # static contact before the slide has no texture
    ramp = (p_on.t_ns >= t.onset_ns) & (p_on.t_ns < t.onset_ns + 20_000_000)
    assert np.ptp(p_on.counts[0, ramp]) <= 1


def test_electrode_deformation_on_and_off():
    on = simulate(scene_with(HAND, texture_vibration={}, electrode_deformation={}))
    off = simulate(scene_with(HAND, texture_vibration={}))
    t = on.explorations[0]
    e_on, e_off = cell(on, "index").streams["electrodes"], cell(off, "index").streams["electrodes"]
    assert np.abs(e_on.counts[:, in_contact(e_on, t)] - e_on.counts[:, :1]).mean() > 2
    assert np.all(e_off.counts == e_off.counts[:, :1])


def test_stick_slip_on_and_off():
    on = simulate(scene_with(HAND, stick_slip={}))
    off = simulate(scene_with(HAND))
    assert on.slip_events and not off.slip_events
    ev = on.slip_events[0]
    pac = cell(on, ev["body_part"]).streams["pac"]
    burst = (pac.t_ns >= ev["t_ns"]) & (pac.t_ns < ev["t_ns"] + 100_000_000)
    assert np.ptp(pac.counts[0, burst]) > 20
    assert np.ptp(cell(off, ev["body_part"]).streams["pac"].counts) == 0


def test_sensor_noise_and_bias_drift_on_and_off():
    noisy = simulate(scene_with(HAND, sensor_noise={"std_counts": 3.0}))
    tac = cell(noisy, "thumb").streams["tac"].counts[0]
    assert tac.std() == pytest.approx(3.0, rel=0.15)
    drift = simulate(scene_with(HAND, bias_drift={"counts_per_s": 5.0}))
    tdc = np.concatenate([c.streams["tdc"].counts[0] for c in drift.cells.values()])
    spans = [abs(int(c.streams["tdc"].counts[0, -1]) - int(c.streams["tdc"].counts[0, 0])) for c in drift.cells.values()]
    assert max(spans) > 3 and tdc.size
    quiet = simulate(scene_with(HAND))
    assert cell(quiet, "thumb").streams["tac"].counts.std() == 0


def test_adc_clipping_on_and_off():
    data = copy.deepcopy(HAND)
    data["explorations"][0]["force_n"] = 150.0  # 3000 counts above a 2000 baseline
    with pytest.raises(SceneError) as info:
        simulate(parse_scene(data))
    assert info.value.key == "effects.adc"
    data["effects"]["adc"] = {}
    res = simulate(parse_scene(data))
    assert res.stats["clipped_samples"] > 0
    assert cell(res, "index").streams["pdc"].counts.max() == 4095


def test_dropped_frames_leave_gaps_in_every_stream_of_the_frame():
    res = simulate(scene_with(HAND, dropped_frames={"probability": 0.05}))
    total = 0
    for c in res.cells.values():
        pdc, pac = c.streams["pdc"], c.streams["pac"]
        n_frames = pdc.seq[-1] + 1 if pdc.seq.size else 0
        missing = np.setdiff1d(np.arange(n_frames), pdc.seq)
        total += missing.size
        assert np.array_equal(np.setdiff1d(np.arange(n_frames), c.streams["electrodes"].seq), missing)
        assert pac.seq.size == 22 * pdc.seq.size
        assert np.array_equal(np.unique(pac.seq // 22), pdc.seq)
    assert total > 0
    assert abs(total - res.faults["dropped_frames"]) <= 5  # a drop in the very last frame cannot be seen as a gap
    clean = simulate(scene_with(HAND))
    assert all(np.all(np.diff(c.streams["pdc"].seq) == 1) for c in clean.cells.values())


def test_bad_parity_and_corrupt_frames_mark_words():
    res = simulate(scene_with(HAND, bad_parity={"probability": 0.01}))
    marks = sum(int((st.fault == FAULT_PARITY).sum()) for c in res.cells.values() for st in c.streams.values())
    words = sum(st.fault.size for c in res.cells.values() for st in c.streams.values())
    assert marks == res.faults["parity_words"]
    assert marks / words == pytest.approx(0.01, rel=0.2)
    res = simulate(scene_with(HAND, corrupt_frames={"probability": 0.02}))
    c = cell(res, "index")
    bad_frames = np.nonzero((c.streams["pdc"].fault == FAULT_CORRUPT)[0])[0]
    assert bad_frames.size
    for f in bad_frames[:5]:
        assert np.all(c.streams["electrodes"].fault[:, f] == FAULT_CORRUPT)
        assert np.all(c.streams["pac"].fault[0, f * 22 : (f + 1) * 22] == FAULT_CORRUPT)
    clean = simulate(scene_with(HAND))
    assert all(np.all(st.valid) for c in clean.cells.values() for st in c.streams.values())


def test_unplug_removes_samples_and_rebiases():
    ev = {"cell": 1, "at_s": 1.0, "for_s": 0.5, "rebias_counts": 30}
    res = simulate(scene_with(HAND, unplug={"events": [ev]}))
    tdc = res.cells[1].streams["tdc"]
    gap = (tdc.t_ns >= 1_000_000_000) & (tdc.t_ns < 1_500_000_000)
    assert not gap.any()
    before = tdc.counts[0, tdc.t_ns < 1_000_000_000][-1]
    after = tdc.counts[0, tdc.t_ns >= 1_500_000_000][0]
    assert abs(int(after) - int(before)) == 30
    assert res.faults["unplugged"] == [{"cell": 1, "from_ns": 1_000_000_000, "to_ns": 1_500_000_000}]
    other = res.cells[2].streams["tdc"]
    assert ((other.t_ns >= 1_000_000_000) & (other.t_ns < 1_500_000_000)).any()


def test_nao_large_object_touches_every_body_part_and_proximity():
    res = simulate(scene_with(NAO, proximity={}, adc={}))
    t = res.explorations[0]
    for part in ("left_hand", "right_upper_arm", "chest"):
        c = cell(res, part)
        f = c.streams["force"]
        mean_n = (f.counts[:, in_contact(f, t)].mean() - f.counts[:, :5].mean()) * 0.002442
        assert mean_n > 0.15
        prox = c.streams["proximity"].counts[0]
        assert prox.max() == 4095 and prox[0] == 0
    off = simulate(scene_with(NAO))
    assert all(np.all(c.streams["proximity"].counts == 0) for c in off.cells.values())


def test_heavier_objects_press_harder_and_slide_faster():
    out = {}
    for w in (500, 1500):
        data = copy.deepcopy(NAO)
        data["explorations"][0]["weight_g"] = w
        res = simulate(parse_scene(data))
        f = cell(res, "left_hand").streams["force"]
        t = res.explorations[0]
        out[w] = (f.counts[:, in_contact(f, t)].mean(), t.exploration.speed_m_s, t.exploration.duration_s)
    assert out[1500][0] > out[500][0] and out[1500][1] > out[500][1] and out[1500][2] < out[500][2]


def test_chunks_join_seamlessly_and_match_the_whole_scene():
    data = copy.deepcopy(HAND)
    data["effects"].update({"texture_vibration": {}, "electrode_deformation": {}, "stick_slip": {}})
    data["explorations"][0]["repeat"] = 3
    scene = parse_scene(data)
    whole = simulate(scene)
    chunks = list(iter_simulate(scene, max_chunk_s=3.0))
    assert len(chunks) > 2
    for cid, c in whole.cells.items():
        for name, st in c.streams.items():
            joined = np.concatenate([ch.cells[cid].streams[name].counts for ch in chunks], axis=1)
            seq = np.concatenate([ch.cells[cid].streams[name].seq for ch in chunks])
            t = np.concatenate([ch.cells[cid].streams[name].t_ns for ch in chunks])
            assert np.array_equal(seq, st.seq) and np.array_equal(t, st.t_ns)
            assert np.array_equal(joined, st.counts), (cid, name)
    assert sum(len(ch.explorations) for ch in chunks) == 6
    assert sum(len(ch.slip_events) for ch in chunks) == len(whole.slip_events)


def test_save_npz_round_trip(tmp_path):
    res = simulate(scene_with(HAND, texture_vibration={}, dropped_frames={"probability": 0.01}))
    res.save_npz(tmp_path / "s.npz")
    z = np.load(tmp_path / "s.npz")
    assert np.array_equal(z["cell1/pac/counts"], res.cells[1].streams["pac"].counts)
    assert np.array_equal(z["cell1/pac/seq"], res.cells[1].streams["pac"].seq)
    truth = json.loads(str(z["ground_truth"]))
    assert [e["label"] for e in truth["explorations"]] == ["cork", "steel"]
    assert truth["explorations"][0]["onset_ns"] == res.explorations[0].onset_ns
