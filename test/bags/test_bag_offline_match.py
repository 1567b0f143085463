"""Real recordings imported into a bag and replayed through the live graph match the offline evaluation.

Offline: each cropped trial read straight from its CSV, one descriptor per
whole trial with the core (``describe_window``), and the same online PA-I
learner scored prequentially (predict, then learn the label) in the bag's
order.  Live: the bag replayed onto real topics through ``window_node``
(exploration windows found from the force) and ``classifier_node``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from test_bag_graph import _run_graph  # noqa: E402  (same folder; pytest puts it on sys.path)

pytestmark = [pytest.mark.ros, pytest.mark.realdata, pytest.mark.slow]

MATERIALS = [1, 2, 4, 6, 9, 12, 14, 16, 18, 20]
TRIALS = [1, 2, 3]
FRAMES = 300


def _offline(biotac_data_dir: Path):
    from tactile_descriptors_ros.core.aggregation import CellSignals, describe_window
    from tactile_descriptors_ros.core.learning import RECOMMENDED_PA_AVERAGE, RECOMMENDED_PA_UPDATE, OnlineClassifier
    from tactile_descriptors_ros.core.robot import load_robot
    from tactile_descriptors_ros.datasets.biotac_slide import read_biotac_csv

    robot = load_robot("shadow_hand")
    n_per_count = robot.cell_types["biotac"].force.n_per_count
    order = [(t, m) for t in TRIALS for m in MATERIALS]  # the importer's default "trial" order
    clf, values, predictions, correct = None, [], [], 0
    for t, m in order:
        rec = read_biotac_csv(biotac_data_dir / "raw_data" / f"mat{m}" / f"mat{m}_{t}_bio.csv").crop_frames(0, FRAMES)
        cell = CellSignals(rec.pac[None], rec.pac_t_ns, rec.electrodes, rec.frame_t_ns, rec.pdc * n_per_count)
        d = describe_window(robot, {1: cell})
        index = d.body_parts[1].values
        if clf is None:  # classifier_node's defaults
            clf = OnlineClassifier(d.labels, update=RECOMMENDED_PA_UPDATE, average=RECOMMENDED_PA_AVERAGE)
        clf.observe(d.values)
        guess, _ = clf.predict(d.values)
        truth = rec.class_name
        correct += int(guess == truth)
        predictions.append(guess)
        values.append(index)
        clf.learn(d.values, truth)
    return np.array(values), predictions, correct / len(order)


def test_imported_real_recording_through_live_graph_matches_offline(ros_context, tmp_path, biotac_data_dir,
                                                                   repo_dir):
    from tactile_descriptors_ros.bags.importer import ImportOptions, import_biotac_slide

    bag = tmp_path / "real"
    report = import_biotac_slide(biotac_data_dir, bag, trials=TRIALS, materials=MATERIALS,
                                 options=ImportOptions(max_frames=FRAMES))
    desc, pred = _run_graph(ros_context, bag, tmp_path / "model.json", rate=8.0)
    off_values, off_pred, off_acc = _offline(biotac_data_dir)

    n = len(report.trials)
    assert n == len(TRIALS) * len(MATERIALS)
    assert len(desc) == n and len(pred) == n, "one exploration per trial"
    truth = [t.material_name for t in report.trials]
    live_pred = [p[2] if p[1] else None for p in pred]
    live_acc = sum(a == b for a, b in zip(live_pred, truth)) / n

    # Descriptors: the live exploration window runs from the contact onset
    # (the trial's first frame here) to the release: the same samples.
    assert all(len(d[1]) == 8 for d in desc)  # the window node serves the index finger only
    live_index = np.array([d[1] for d in desc])
    rel = np.abs(live_index - off_values) / (np.abs(off_values) + 1e-9)
    assert float(rel.max()) < 1e-9
    agreement = float(np.mean([a == b for a, b in zip(live_pred, off_pred)]))
    summary = {"explorations": n, "live_accuracy": live_acc, "offline_accuracy": off_acc,
               "prediction_agreement": agreement, "max_relative_descriptor_difference": float(rel.max())}
    out = Path(os.environ.get("ROS_LOG_DIR", tmp_path)).parent / "offline_match.json"
    out.write_text(json.dumps(summary))
    print(json.dumps(summary))
    assert agreement == 1.0 and live_acc == off_acc
