"""``tactile report`` end to end on a small slice of the real recordings (the quick plan)."""

from __future__ import annotations

import json

import pytest

from tactile_descriptors_lab.evaluation.report import FEATURE_DEFINITION, SECTIONS
from tactile_descriptors_ros.tools.cli import main


@pytest.mark.realdata
@pytest.mark.slow
def test_quick_report_writes_every_section_and_figure(biotac_data_dir, tmp_path, capsys):
    out = tmp_path / "docs"
    rc = main(["report", "--data", str(biotac_data_dir), "--out", str(out), "--materials", "1-3",
               "--trials", "1-12", "--quick", "--jobs", "1", "--cache", str(tmp_path / "cache"), "--json"])
    assert rc == 0
    capsys.readouterr()
    md = (out / "results.md").read_text()
    for heading in ("## Headline", "## Accuracy against window length", "## Robustness to touch length",
                    "## Short windows", "## Ablations", "## Cross-validation over trials"):
        assert heading in md
    assert "train trials 1-8, test trials 9-12" in md
    for fig in ("accuracy_vs_window", "time_vs_window", "length_robustness", "pa_curves", "confusion_svm"):
        png = out / "figures" / f"{fig}.png"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    res = json.loads((out / "results.json").read_text())
    head = res["headline"]["combined | 1"]
    assert head["n_features"] == 261 and head["config"]["gate"] is False
    assert set(head["classifiers"]) == {"svm", "pa", "gmm"}
    # three well-separated materials: far above chance (1/3) even on 1 s windows and 8 trials
    assert head["classifiers"]["svm"]["accuracy"] >= 0.75
    pa_rows = {k: v for k, v in res["ablation"].items() if "online:" in k}
    assert len(pa_rows) == 3 and all(set(v["classifiers"]) == {"pa"} for v in pa_rows.values())
    # each online row runs the update it names
    assert {(v["config"]["pa_update"], v["config"]["pa_average"]) for v in pa_rows.values()} == {
        ("prediction", False), ("max_loss", False), ("max_loss", True)}
    assert "with the classifier node's default update, AROW (second-order" in md
    assert res["ablation"]["paper | with the contact gate (F_t on tared PDC)"]["config"]["gate"] is True
    # the touch-length sections: one model per variant scored on every test length, the block-averaged
    # default first, trial CV of the default
    assert set(res["length"]) == {"combined | 1", "combined | 0.5-2", "window | 1", "window | 0.5-2"}
    assert res["length"]["combined | 0.5-2"]["test_window_frames"] == [50, 100, 150, 200]
    assert res["length"]["combined | 1"]["config"]["block_s"] == 1.0
    assert res["length"]["window | 1"]["config"]["block_s"] is None
    assert set(res["length_cv"]) == {"combined | 1", "combined | 0.5-2"}
    assert len(res["length_cv"]["combined | 1"]["classifiers"]["svm"]["fold_accuracy"]) == 2
    assert "| combined | 1 s | random 0.5-2 s |" in md
    # trial CV scores plain statistics (the floor) beside the descriptor, with their spread over folds
    assert set(res["trial_cv"]) == {"paper | 1", "plain | 1"}
    assert len(res["trial_cv"]["plain | 1"]["classifiers"]["svm"]["fold_accuracy"]) == 2
    assert "| plain | " in md and "`plain` (mean, sd, min and max of every channel) is the floor" in md
    # the other labs' layouts, each read back through its mapping: plain against the default mode by trial CV
    ds = res["datasets"]
    assert list(ds) == ["shared BioTac", "Penn BOLT layout", "iCub taxel pad", "simulated NAO"]
    assert (ds["shared BioTac"]["classes"], ds["shared BioTac"]["trials"], ds["shared BioTac"]["mode"]) == (
        3, 36, "combined")
    assert ds["Penn BOLT layout"]["classes"] == 3 and ds["Penn BOLT layout"]["trials"] == 3 * 6  # 2 trials a run
    assert (ds["iCub taxel pad"]["mode"], ds["iCub taxel pad"]["left_out"]) == ("levels+statistics",
                                                                                ["per_channel", "bands"])
    assert (ds["simulated NAO"]["classes"], ds["simulated NAO"]["trials"]) == (3, 18)
    for row in ds.values():
        assert set(row["cv"]) == {"plain", row["mode"]}
        assert all(len(cv["classifiers"][c]["fold_accuracy"]) == 3 for cv in row["cv"].values() for c in ("svm", "pa"))
        # the choice between the two, made in each fold's training trials, one per classifier and fold
        for c in ("svm", "pa"):
            assert len(row["selected"]["classifiers"][c]["chosen"]) == 3
            assert set(row["selected"]["classifiers"][c]["chosen"]) <= {"plain", row["mode"]}
    assert "## Across data sets: the default descriptor against plain statistics" in md
    assert "| iCub taxel pad: 3 materials, 36 trials of a 60-taxel pressure-only pad at 50 Hz" in md
    # the convolution group beside the shipped ones: every candidate on the dev split and by trial CV, and the
    # choice made inside the training trials, scored once on the test split
    conv = res["convolutions"]
    assert list(conv) == ["svm", "online"]
    assert list(conv["svm"]["candidates"]) == ["plain", "combined_rocket"]
    assert conv["svm"]["candidates"]["combined_rocket"]["split"]["n_features"] == 1521
    assert list(conv["online"]["candidates"]) == ["combined_rocket, 1 s blocks", "combined_rocket, whole window"]
    assert conv["online"]["candidates"]["combined_rocket, whole window"]["block_s"] is None
    assert conv["svm"]["transform"]["file"] == "biotac.json"
    assert conv["svm"]["transform"]["description"].startswith("fitted by tactile fit-rocket")
    for r in conv.values():
        sel = r["selection"]
        assert set(sel["inner"]) == set(r["candidates"]) and len(sel["folds"]) == 3
        assert sel["test"] == r["candidates"][sel["chosen_label"]]["split"]  # the same windows and seeds
        # the choice is the best by inner accuracy, the first listed on a tie
        best = max(v["accuracy"] for v in sel["inner"].values())
        assert sel["chosen_label"] == next(k for k, v in sel["inner"].items() if v["accuracy"] >= best - 1e-12)
        assert all(len(c["cv"]["fold_accuracy"]) == 2 for c in r["candidates"].values())
    assert "## With the convolutions: 1 s windows (SVM) and 2 s windows (online)" in md
    assert md.count("**(chosen)**") == 2

    # --only length recomputes those sections alone, keeps the rest and renders the page again
    head_before = res["headline"]
    (out / "results.md").write_text("stale")
    rc = main(["report", "--data", str(biotac_data_dir), "--out", str(out), "--materials", "1-3",
               "--trials", "1-12", "--quick", "--jobs", "1", "--cache", str(tmp_path / "cache"),
               "--only", "length"])
    assert rc == 0
    again = json.loads((out / "results.json").read_text())
    assert again["headline"] == head_before
    for name in ("svm", "pa"):  # the same results (times differ from run to run)
        for field in ("accuracy", "confusion"):
            assert (again["length"]["combined | 1"]["classifiers"][name][field]
                    == res["length"]["combined | 1"]["classifiers"][name][field])
    assert set(again["section_runtime_s"]) == {"length", "length_cv", "short"}
    # every recomputed section records when and with which feature definition it was measured
    assert set(res["provenance"]) == set(SECTIONS)
    assert all(p["features"] == FEATURE_DEFINITION for p in again["provenance"].values())
    md2 = (out / "results.md").read_text()
    assert "## Headline" in md2 and "## Robustness to touch length" in md2



def test_the_full_report_scores_plain_statistics_beside_the_shipped_groups_by_trial():
    from tactile_descriptors_lab.evaluation.report import FULL_PLAN

    assert {"combined", "plain"} <= set(FULL_PLAN.trial_cv_modes)
