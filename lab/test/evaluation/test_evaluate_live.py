"""``tactile evaluate --live``: real trials replayed through the window and classifier node processes.

The live descriptors must be the evaluation's for the same windows and the live predictions the
same as the classifier node's protocol run offline on them; a small run (4 materials, 3 training
and 2 test trials) goes through the real command.  The offline checks (what a mismatch looks like,
which windows force alone cannot find) run without ROS.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from tactile_descriptors_lab.evaluation.live_check import (
    LiveStep,
    OfflineReplay,
    check_segmentable,
    compare,
    plan_steps,
)
from tactile_descriptors_ros.errors import ConfigError


def _offline(n: int = 4) -> OfflineReplay:
    steps = [LiveStep(1 + k % 2, 1 + k // 2, f"c{k % 2}", k < 2) for k in range(n)]
    values = np.arange(1.0, 1.0 + 3 * n).reshape(n, 3)
    return OfflineReplay(steps, values, ("per_channel/A_pac", "per_channel/M_pac", "per_channel/L_e1"),
                         [None, "c0", "c1", "c1"][:n])


def test_compare_accepts_equal_runs_and_scores_only_test_windows():
    off = _offline()
    labels = ("index/per_channel/A_pac", "index/per_channel/M_pac", "index/per_channel/L_e1")
    out = compare(off, off.values + 1e-13, labels, list(off.predictions))
    assert out["descriptors_match"] and out["predictions_match"] and out["prediction_agreement"] == 1.0
    assert (out["train_windows"], out["test_windows"]) == (2, 2)
    assert out["live_accuracy"] == 0.5 == out["offline_accuracy"]  # test windows: c0 predicted c1, c1 predicted c1


def test_compare_reports_a_moved_value_and_a_different_prediction():
    off = _offline()
    live = off.values.copy()
    live[2, 1] *= 1 + 1e-6
    preds = list(off.predictions)
    preds[3] = "c0"
    out = compare(off, live, ("index/per_channel/A_pac", "index/per_channel/M_pac", "index/per_channel/L_e1"), preds)
    assert not out["descriptors_match"] and out["max_relative_descriptor_difference"] == pytest.approx(1e-6)
    assert not out["predictions_match"] and out["prediction_agreement"] == 0.75
    assert [(m["material"], m["trial"]) for m in out["mismatched_windows"]] == [(1, 2), (2, 2)]


def test_compare_refuses_another_layout():
    off = _offline()
    with pytest.raises(ConfigError, match="layout"):
        compare(off, off.values, ("index/per_channel/A_pac", "index/per_channel/C_pac", "index/per_channel/L_e1"),
                list(off.predictions))


def test_plan_puts_every_trial_in_one_split_in_import_order():
    class Rec:
        def __init__(self, material, trial):
            self.material, self.trial, self.class_name = material, trial, f"class{material}"

    steps = plan_steps([Rec(2, 3), Rec(1, 1), Rec(2, 1)], [1], [3])
    assert [(s.material, s.trial, s.class_name, s.train) for s in steps] == [
        (1, 1, "class1", True), (2, 1, "class2", True), (2, 3, "class2", False)]
    with pytest.raises(ConfigError, match="neither"):
        plan_steps([Rec(1, 2)], [1], [3])
    with pytest.raises(ConfigError, match="both"):
        plan_steps([Rec(1, 1)], [1], [1, 3])


def test_windows_force_cannot_delimit_are_refused():
    class Rec:  # the only fields the check reads
        def __init__(self, pdc, trial=1):
            self.material, self.trial, self.path, self.pdc, self.n_frames = 1, trial, f"mat1_{trial}", pdc, len(pdc)

    steps = [LiveStep(1, 1, "x", True)]
    check_segmentable([Rec(np.array([3, 1, 2, 5, 0, 0]))], steps, 4)  # zeros after the window do not matter
    with pytest.raises(ConfigError, match="frame 2 of the 4-frame window"):
        check_segmentable([Rec(np.array([3, 2, 0, 1]))], steps, 4)
    with pytest.raises(ConfigError, match="shorter than"):
        check_segmentable([Rec(np.array([3, 2]))], steps, 4)


@pytest.mark.realdata
def test_imported_stream_stays_in_order_into_the_release_gap(biotac_data_dir, tmp_path):
    """Bath towel trial 13: its 200th frame's PAC samples run 1.7 ms past the median frame period."""
    from tactile_descriptors_lab.datasets.importer import ImportOptions, import_recordings
    from tactile_descriptors_lab.evaluation.sampling import load_split
    from tactile_descriptors_ros.bags.io import BagReader

    rec = load_split(biotac_data_dir, [13], [3])[0]
    report = import_recordings([rec], tmp_path / "bag", options=ImportOptions(max_frames=200))
    stamps = []
    with BagReader(tmp_path / "bag") as reader:
        for m in reader.messages(["/tactile/index/frames"]):
            msg = reader.deserialize(m)
            t0 = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            stamps.append(t0 + np.asarray(msg.pac_offset_ns))
    pac_t = np.concatenate(stamps)
    assert np.all(np.diff(pac_t) > 0)
    last_trial_sample = int(rec.crop_frames(0, 200).pac_t_ns[-1] - rec.frame_t_ns[0] + report.trials[0].start_ns)
    assert report.trials[0].end_ns == last_trial_sample + 1


@pytest.mark.ros
def test_a_replay_the_matched_window_node_received_nothing_of_says_so():
    """The error names a delivery stall only when frames went out, both sides matched and none arrived."""
    from types import SimpleNamespace

    from tactile_descriptors_lab.evaluation.live_replay import _nothing_delivered

    player = SimpleNamespace(report=SimpleNamespace(published={"/tactile/index/frames": 412}))
    stalled = {"messages_received": "0", "index_publishers": "1"}
    assert "received none of the 412 frames messages sent" in _nothing_delivered(player, stalled, "index")
    assert _nothing_delivered(player, {**stalled, "messages_received": "3"}, "index") == ""
    assert _nothing_delivered(player, {**stalled, "index_publishers": "0"}, "index") == ""  # discovery, not delivery
    assert _nothing_delivered(SimpleNamespace(report=SimpleNamespace(published={"/f": 0})), stalled, "index") == ""
    assert _nothing_delivered(None, stalled, "index") == ""


@pytest.mark.ros
@pytest.mark.realdata
@pytest.mark.slow
def test_evaluate_live_gives_the_offline_descriptors_and_predictions(biotac_data_dir, tmp_path):
    env = dict(os.environ)
    cmd = [sys.executable, "-m", "tactile_descriptors_ros.tools.cli", "evaluate", "--live", "--json",
           "--train", str(biotac_data_dir), "--test", str(biotac_data_dir), "--train-trials", "1-3",
           "--test-trials", "4-5", "--materials", "2,9,14,16", "--window", "2",
           "--cache", "", "--jobs", "1", "--timeout", "60"]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=240)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert (out["windows"], out["train_windows"], out["test_windows"]) == (20, 12, 8)
    assert out["labels_taught"] == 12 and out["mode"] == "combined" and out["n_features"] == 261  # shipped groups
    assert (out["block_s"], out["block_hop_s"]) == (1.0, 0.5)  # evaluate's default: block averaging on
    assert out["descriptors_match"] and out["max_relative_descriptor_difference"] < 1e-9
    assert out["predictions_match"] and out["live_accuracy"] == out["offline_accuracy"]
    assert out["window_node_faults"].get("lost_frames", 0) == 0


@pytest.mark.parametrize("extra, option", [
    (["--select", "paper,combined"], "--select"),
    (["--channels", "paper", "--select-blocks", "1,0"], "--select-blocks"),
    (["--channels", "rocket", "--rocket", "biotac_4x.json"], "--rocket"),
    (["--channels", "rocket", "--select-rocket", "biotac_4x.json"], "--select-rocket"),
    (["--gate"], "--gate"),
])
def test_live_refuses_what_the_nodes_do_not_run_before_reading(biotac_data_dir, tmp_path, capsys, extra, option):
    """The replay runs the nodes' one descriptor: an option it would ignore is refused, never dropped."""
    from tactile_descriptors_ros.tools.cli import main

    data = str(biotac_data_dir)
    assert main(["evaluate", "--train", data, "--test", data, "--live", "--cache", str(tmp_path)] + extra) == 2
    assert f"leave out {option}" in capsys.readouterr().err
