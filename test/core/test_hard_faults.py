"""Injected faults: unplug/replug, drops, stamp faults, clock jumps, full disk, SIGKILL during learning."""

from __future__ import annotations

import errno
import os
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from tactile_descriptors_ros.core.aggregation import describe_window
from tactile_descriptors_ros.core.descriptors import Quality
from tactile_descriptors_ros.core.learning import OnlineClassifier
from tactile_descriptors_ros.core.model_store import load_model, save_model
from tactile_descriptors_ros.core.robot import load_robot
from tactile_descriptors_ros.core.windowing import CellChunk, Windower
from tactile_descriptors_ros.errors import ModelError
from tactile_descriptors_ros.sim.engine import simulate
from tactile_descriptors_ros.sim.scene import parse_scene

MS = 1_000_000
SHADOW = load_robot("shadow_hand")


def _chunk(t0_ns: int, force_n: float, rng, n_frames: int = 10) -> CellChunk:
    frame_t = t0_ns + np.arange(n_frames, dtype=np.int64) * 10 * MS
    pac_t = (frame_t[:, None] + (np.arange(22) * 10 * MS) // 22).ravel()
    return CellChunk(rng.integers(0, 4096, (1, pac_t.size)), pac_t, rng.integers(0, 4096, (19, n_frames)),
                     frame_t, np.full(n_frames, force_n), frame_t)


# ------------------------------------------------------------------ stamps


def test_duplicate_out_of_order_and_clock_jump_are_counted():
    rng = np.random.default_rng(0)
    w = Windower(SHADOW, mode="fixed", length_s=1.0, hop_s=1.0)
    assert w.add(0, _chunk(0, 1.0, rng))
    assert w.add(0, _chunk(100 * MS, 1.0, rng))
    assert not w.add(0, _chunk(100 * MS, 1.0, rng))           # the same message again
    assert not w.add(0, _chunk(50 * MS, 1.0, rng))            # older than what we have
    bad = _chunk(200 * MS, 1.0, rng)
    bad.vibration_t_ns = bad.vibration_t_ns[::-1].copy()
    assert not w.add(0, bad)                                   # unsorted inside a message
    assert w.add(0, _chunk(200 * MS, 1.0, rng))
    assert w.faults["duplicate"] == 1 and w.faults["out_of_order"] == 1 and w.faults["unsorted_stamps"] == 1
    assert w.add(0, _chunk(100_000 * MS, 1.0, rng))            # forward jump: accepted
    assert w.add(0, _chunk(0, 1.0, rng))                       # backwards by 100 s: clock jump, buffer reset
    assert w.faults["clock_jump"] == 1
    assert w.add(0, _chunk(100 * MS, 1.0, rng))                # and the stream goes on after the jump
    assert not w.add(77, _chunk(0, 1.0, rng)) and w.faults["unknown_cell"] == 1


def test_windows_after_a_clock_jump_hold_only_new_data():
    rng = np.random.default_rng(1)
    w = Windower(SHADOW, mode="fixed", length_s=0.5, hop_s=0.5)
    for k in range(20):
        w.add(0, _chunk(50_000 * MS + k * 100 * MS, 1.0, rng))
        w.poll()
    wins = []
    for k in range(20):
        w.add(0, _chunk(k * 100 * MS, 1.0, rng))
        wins += w.poll()
    assert w.faults["clock_jump"] == 1 and wins
    for win in wins:
        assert win.end_ns <= 2_000 * MS
        assert all(c.vibration_t_ns.max() < 2_000 * MS for c in win.cells.values())


# ------------------------------------------------------------------ simulator: unplug, drops, parity


def _scene(effects: dict) -> dict:
    return {"scene": {"name": "hard", "robot": "shadow_hand", "seed": 3, "lead_in_s": 0.5},
            "effects": {"normal_force": {"ramp_s": 0.1}, "texture_vibration": {}, "electrode_deformation": {},
                        "sensor_noise": {"std_counts": 1.0}, "adc": {}, **effects},
            "defaults": {"pause_s": 1.0, "duration_s": 4.0, "force_n": 1.5, "speed_m_s": 0.02, "motion": "lateral"},
            "explorations": [{"materials": ["cork"], "body_parts": ["index"]}]}


def _feed_sim(result, windower: Windower, cell_id: int, chunk_ns: int = 100 * MS):
    """Feed one cell's simulated streams as 100 ms messages; return windows and accepted chunk times."""
    cell = result.cells[cell_id]
    pac, el, pdc = cell.streams["pac"], cell.streams["electrodes"], cell.streams["pdc"]
    tare = float(np.median(pdc.counts[0, :20]))
    n_per_count = SHADOW.cell_types["biotac"].force.n_per_count
    t0 = int(pac.t_ns[0])
    wins, accepted = [], []
    for start in range(t0, int(pac.t_ns[-1]) + 1, chunk_ns):
        sl = (pac.t_ns >= start) & (pac.t_ns < start + chunk_ns)
        fl = (el.t_ns >= start) & (el.t_ns < start + chunk_ns)
        if not sl.any():
            continue
        chunk = CellChunk(pac.counts[:, sl], pac.t_ns[sl], el.counts[:, fl], el.t_ns[fl],
                          (pdc.counts[0, fl] - tare) * n_per_count, el.t_ns[fl],
                          pac.valid[0, sl], el.valid.all(axis=0)[fl])
        if windower.add(cell_id, chunk):
            accepted.append(start)
        wins += windower.poll()
    return wins + windower.flush(), accepted


def test_unplug_and_replug_recovers_within_one_second():
    at_s, for_s = 2.5, 0.6
    result = simulate(parse_scene(_scene({"unplug": {"events": [{"cell": 1, "at_s": at_s, "for_s": for_s}]}})))
    (ev,) = result.faults["unplugged"]
    pac_t = result.cells[1].streams["pac"].t_ns
    assert not np.any((pac_t >= ev["from_ns"]) & (pac_t < ev["to_ns"]))  # really silent
    w = Windower(SHADOW, mode="fixed", length_s=0.5, hop_s=0.5)
    wins, accepted = _feed_sim(result, w, 1)
    after = [t for t in accepted if t >= ev["to_ns"] - 100 * MS]
    assert after and after[0] - ev["to_ns"] < 1_000 * MS         # data flows again within 1 s of replug
    covering = [x for x in wins if x.start_ns >= ev["to_ns"] and 1 in x.cells]
    assert covering and covering[0].start_ns - ev["to_ns"] < 1_000 * MS
    d = describe_window(SHADOW, covering[0].cells)
    assert np.all(np.isfinite(d.values))


def test_unplug_gap_inside_a_window_is_reported():
    result = simulate(parse_scene(_scene({"unplug": {"events": [{"cell": 1, "at_s": 2.5, "for_s": 0.6}]}})))
    (ev,) = result.faults["unplugged"]
    w = Windower(SHADOW, mode="fixed", length_s=2.0, hop_s=2.0)
    wins, _ = _feed_sim(result, w, 1)
    holed = [x for x in wins if x.start_ns < ev["from_ns"] and x.end_ns > ev["to_ns"]]
    assert holed
    d = describe_window(SHADOW, holed[0].cells)
    assert holed[0].cells[1].gap                               # the hole is seen in the window's cell
    assert d.body_parts[1].quality & Quality.GAP                 # flagged in the descriptor
    assert w.faults["gap"] == 1                                  # and counted once


def test_dropped_frames_and_bad_parity_are_counted_and_marked_invalid():
    result = simulate(parse_scene(_scene({"dropped_frames": {"probability": 0.02},
                                          "bad_parity": {"probability": 0.002}})))
    assert result.faults["dropped_frames"] > 0 and result.faults["parity_words"] > 0
    pac = result.cells[1].streams["pac"]
    assert np.any(np.diff(pac.seq) > 1)                       # drops leave holes in the sequence
    w = Windower(SHADOW, mode="exploration")
    wins, _ = _feed_sim(result, w, 1)
    assert [x.exploration_id for x in wins] == [1]
    d = describe_window(SHADOW, wins[0].cells)
    # parity errors fall inside the exploration: the finger is flagged INVALID and left out, never averaged in
    assert d.body_parts[1].quality & Quality.INVALID
    assert np.all(np.isfinite(d.values))


# ------------------------------------------------------------------ model saving


def _trained(labels=("a", "b")) -> OnlineClassifier:
    rng = np.random.default_rng(0)
    clf = OnlineClassifier([f"f{i}" for i in range(4)])
    for name in labels:
        clf.learn(rng.standard_normal(4), name)
    return clf


@pytest.mark.parametrize("target", ["fsync", "replace"])
def test_full_disk_while_saving_keeps_the_previous_model(tmp_path, monkeypatch, target):
    path = tmp_path / "model.json"
    save_model(_trained(("a",)), path)
    before = path.read_bytes()

    def enospc(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, target, enospc)
    with pytest.raises(ModelError, match="No space left"):
        save_model(_trained(("a", "b", "c")), path)
    monkeypatch.undo()
    assert path.read_bytes() == before
    assert load_model(path).classes == ["a"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model.json", "model.json.lock"]  # no temp file left


_WORKER = textwrap.dedent("""
    import sys
    import numpy as np
    from tactile_descriptors_ros.core.learning import OnlineClassifier
    from tactile_descriptors_ros.core.model_store import save_model
    path = sys.argv[1]
    rng = np.random.default_rng(0)
    clf = OnlineClassifier([f"f{i}" for i in range(8)])
    i = 0
    while True:
        clf.learn(rng.standard_normal(8), f"class_{i}")
        save_model(clf, path)
        print(i, flush=True)   # the save of class_<i> has returned
        i += 1
""")


def test_sigkill_while_learning_loses_no_saved_label(tmp_path):
    """Guarantee: every label whose update completed and whose save returned before the kill is in the
    reloaded model, and the file is never torn.  A process we start learns and saves in a loop; we kill
    it with SIGKILL (by its PID) at an arbitrary point after a few acknowledged saves."""
    path = tmp_path / "model.json"
    for round_ in range(3):
        proc = subprocess.Popen([sys.executable, "-c", _WORKER, str(path)], stdout=subprocess.PIPE, text=True,
                                env={**os.environ, "PYTHONPATH": os.getcwd()})
        acked = []
        try:
            while len(acked) < 5 + 7 * round_:
                line = proc.stdout.readline()
                assert line, "worker died"
                acked.append(int(line))
        finally:
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10)
            proc.stdout.close()
        assert proc.returncode == -signal.SIGKILL
        model = load_model(path)                   # never a torn file
        assert {f"class_{i}" for i in acked} <= set(model.classes)
        assert model.version >= len(acked)
