"""``tactile bench --model-save``: the journal and the whole-file rewrite both save every label (no timing asserted)."""

from __future__ import annotations

import json

from tactile_descriptors_ros.tools.cli import main


def test_model_save_bench_json(capsys):
    code = main(["bench", "--model-save", "--model-save-classes", "20", "--json"])
    assert code == 0
    res = json.loads(capsys.readouterr().out)
    assert res["classes"] == 20 and res["labels"] == 50
    for key in ("journal", "journal_append", "rewrite", "sync_floor"):
        assert res[key]["n"] == 50 and 0 < res[key]["median_ms"] <= res[key]["max_ms"]
    assert res["ratio"] == res["rewrite"]["median_ms"] / res["journal"]["median_ms"]
    assert res["target_met"] == (res["journal"]["median_ms"] <= 5.0)


def test_model_save_bench_refuses_a_model_of_one_class(capsys):
    assert main(["bench", "--model-save", "--model-save-classes", "1"]) == 2
    assert "classes must be at least 2" in capsys.readouterr().err
