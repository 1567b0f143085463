"""``tactile report`` end to end on a small slice of the real recordings (the quick plan)."""

from __future__ import annotations

import json

import pytest

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
    for heading in ("## Headline", "## Accuracy against window length", "## Exploration-time robustness",
                    "## Ablations", "## Cross-validation over trials"):
        assert heading in md
    assert "train trials 1-8, test trials 9-12" in md
    for fig in ("accuracy_vs_window", "time_vs_window", "exploration_time", "pa_curves", "confusion_svm"):
        png = out / "figures" / f"{fig}.png"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    res = json.loads((out / "results.json").read_text())
    head = res["headline"]["combined | 1"]
    assert head["n_features"] == 261 and head["config"]["gate"] is False
    assert set(head["classifiers"]) == {"svm", "pa", "gmm"}
    # three well-separated materials: far above chance (1/3) even on 1 s windows and 8 trials
    assert head["classifiers"]["svm"]["accuracy"] >= 0.75
    pa_rows = {k: v for k, v in res["ablation"].items() if "PA:" in k}
    assert len(pa_rows) == 3 and all(set(v["classifiers"]) == {"pa"} for v in pa_rows.values())
    assert res["ablation"]["paper | with the contact gate (F_t on tared PDC)"]["config"]["gate"] is True
