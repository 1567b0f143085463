"""Tests of the selection inside the training trials (``tactile evaluate --select``, ``--select-blocks``).

The selection's logic is checked with a stand-in :func:`evaluate` that
scores from a table (which configurations run, on which trials, what is
chosen); the command end to end on three materials of the real recordings.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import pytest

from tactile_descriptors_lab.evaluation import experiments
from tactile_descriptors_lab.evaluation.experiments import EvalConfig, evaluate_selected, select_mode
from tactile_descriptors_ros.errors import ConfigError
from tactile_descriptors_ros.tools.cli import main


@dataclass(frozen=True)
class _Rec:
    trial: int
    path: str = ""


def _scoring(table: dict[tuple[str, float | None], float], calls: list):
    """A stand-in for :func:`evaluate`: accuracy from ``table`` by (mode, block_s); every call recorded."""

    def fake(train, test, cfg):
        calls.append((cfg.mode, cfg.block_s, cfg.block_hop_s, sorted({r.trial for r in train}),
                      sorted({r.trial for r in test})))
        return {"classifiers": {cfg.classifiers[0]: {"accuracy": table[(cfg.mode, cfg.block_s)]}}}

    return fake


TRAIN = [_Rec(t) for t in range(1, 10)]
TEST = [_Rec(t) for t in range(10, 13)]


def test_selection_tries_every_mode_and_block_on_training_trials_only(monkeypatch):
    table = {("plain", 1.0): 0.80, ("plain", None): 0.82, ("plain", 0.25): 0.81, ("combined", 1.0): 0.90,
             ("combined", None): 0.93, ("combined", 0.25): 0.91}
    calls: list = []
    monkeypatch.setattr(experiments, "evaluate", _scoring(table, calls))
    cfg = EvalConfig(window="2", mode="plain", classifiers=("pa",), block_s=1.0, block_hop_s=0.5)
    sel = select_mode(TRAIN, cfg, ["plain", "combined"], blocks=[1, 0, 0.25], block_hop_s=0.5)
    assert sel["chosen"] == "combined" and sel["block_s"] is None and sel["block_hop_s"] is None
    assert sel["chosen_label"] == "combined, whole window"
    assert list(sel["candidates"]) == ["plain, 1 s blocks", "plain, whole window", "plain, 0.25 s blocks",
                                       "combined, 1 s blocks", "combined, whole window", "combined, 0.25 s blocks"]
    ran = {(m, b, h) for m, b, h, _, _ in calls}
    assert ("combined", 0.25, 0.25) in ran  # a block shorter than the hop steps by the block
    assert ("combined", 1.0, 0.5) in ran
    for _, _, _, inner_train, inner_test in calls:
        assert set(inner_train) | set(inner_test) <= set(range(1, 10))  # never a test trial
        assert not set(inner_train) & set(inner_test)
    assert sel["folds"] == [[1, 3], [4, 6], [7, 9]]


def test_selection_without_blocks_runs_each_mode_as_itself(monkeypatch):
    """``--select A,B`` alone: each candidate is scored with its own mode and ``cfg``'s blocks (not the
    first mode under every label, which would tie and always choose the first)."""
    table = {("plain", 1.0): 0.80, ("combined", 1.0): 0.90, ("per_channel", 1.0): 0.85}
    calls: list = []
    monkeypatch.setattr(experiments, "evaluate", _scoring(table, calls))
    cfg = EvalConfig(window="2", mode="plain", classifiers=("pa",), block_s=1.0, block_hop_s=0.5)
    out = evaluate_selected(TRAIN, TEST, cfg, ["plain", "combined", "per_channel"])
    sel = out["selection"]
    assert {label: v["accuracy"] for label, v in sel["candidates"].items()} == pytest.approx({
        "plain": 0.80, "combined": 0.90, "per_channel": 0.85}, abs=1e-12)
    assert {label: v["mode"] for label, v in sel["candidates"].items()} == {
        "plain": "plain", "combined": "combined", "per_channel": "per_channel"}
    assert sel["chosen"] == "combined" and sel["block_s"] == 1.0
    assert [c[0] for c in calls] == ["plain"] * 3 + ["combined"] * 3 + ["per_channel"] * 3 + ["combined"]
    assert {(c[1], c[2]) for c in calls} == {(1.0, 0.5)}  # cfg's blocks for every candidate


def test_selection_ties_go_to_the_candidate_listed_first(monkeypatch):
    table = {("plain", 1.0): 0.9, ("plain", None): 0.9, ("combined", 1.0): 0.9, ("combined", None): 0.9}
    monkeypatch.setattr(experiments, "evaluate", _scoring(table, []))
    cfg = EvalConfig(window="2", mode="plain", classifiers=("pa",), block_s=1.0, block_hop_s=0.5)
    assert select_mode(TRAIN, cfg, ["combined", "plain"], blocks=[0, 1])["chosen_label"] == "combined, whole window"
    assert select_mode(TRAIN, cfg, ["combined", "plain"], blocks=[1, 0])["chosen_label"] == "combined, 1 s blocks"


def test_subwindows_pair_with_the_whole_window_only(monkeypatch):
    table = {("combined_subwindows", None): 0.95, ("combined", 1.0): 0.94, ("combined", None): 0.93}
    calls: list = []
    monkeypatch.setattr(experiments, "evaluate", _scoring(table, calls))
    cfg = EvalConfig(window="2", mode="combined", classifiers=("pa",), block_s=1.0, block_hop_s=0.5)
    out = evaluate_selected(TRAIN, TEST, cfg, ["combined", "combined_subwindows"], blocks=[1, 0])
    sel = out["selection"]
    assert "combined_subwindows, 1 s blocks" in sel["skipped"]
    assert "combined_subwindows, 1 s blocks" not in sel["candidates"]
    assert sel["chosen_label"] == "combined_subwindows, whole window"
    # the test split is scored once, afterwards, with the chosen mode and blocks
    assert calls[-1][:2] == ("combined_subwindows", None) and calls[-1][4] == [10, 11, 12]
    assert sum(1 for c in calls if c[4] == [10, 11, 12]) == 1
    with pytest.raises(ConfigError, match="whole window only"):
        select_mode(TRAIN, cfg, ["combined_subwindows"], blocks=[1, 0.5])
    with pytest.raises(ConfigError, match="do not combine"):
        select_mode(TRAIN, cfg, ["combined", "combined_subwindows"])  # before any candidate runs
    with pytest.raises(ConfigError, match=">= 0 s"):
        select_mode(TRAIN, cfg, ["combined"], blocks=[-1])


@pytest.mark.realdata
def test_cli_selects_blocks_inside_training_and_scores_the_test_as_the_choice_alone(biotac_data_dir, tmp_path,
                                                                                    capsys):
    common = ["evaluate", "--train", str(biotac_data_dir), "--test", str(biotac_data_dir), "--materials", "1-3",
              "--train-trials", "1-6", "--test-trials", "7-8", "--window", "1", "--classifier", "pa",
              "--train-windows", "2", "--jobs", "1", "--cache", str(tmp_path), "--json"]
    assert main(common + ["--select", "paper,per_channel", "--select-blocks", "0.5,0"]) == 0
    out = json.loads(capsys.readouterr().out)
    sel = out["selection"]
    assert set(sel["candidates"]) == {"paper, 0.5 s blocks", "paper, whole window", "per_channel, 0.5 s blocks",
                                      "per_channel, whole window"}
    best = max(v["accuracy"] for v in sel["candidates"].values())
    assert sel["candidates"][sel["chosen_label"]]["accuracy"] == best
    assert out["config"]["mode"] == sel["chosen"] and out["config"]["block_s"] == sel["block_s"]
    # the same command with the choice given by hand scores the same test windows the same
    block = sel["block_s"] or 0
    assert main(common + ["--channels", sel["chosen"], "--block", f"{block:g}"]) == 0
    alone = json.loads(capsys.readouterr().out)
    assert alone["classifiers"]["pa"]["accuracy"] == out["classifiers"]["pa"]["accuracy"]
    assert alone["n_features"] == out["n_features"]


def test_cli_select_blocks_needs_modes_and_seconds(biotac_data_dir, tmp_path, capsys):
    base = ["evaluate", "--train", str(biotac_data_dir), "--test", str(biotac_data_dir), "--cache", str(tmp_path)]
    assert main(base + ["--select-blocks", "1,0"]) == 2
    assert "--select" in capsys.readouterr().err
    for value, message in [("1,x", "block lengths in seconds (0 = the whole window) joined by ','"),
                           ("-1", "must lie in [0, inf)")]:
        with pytest.raises(SystemExit) as exc:  # argparse's one line, before any data is read
            main(base + ["--select", "paper", "--select-blocks", value])
        assert exc.value.code == 2
        err = capsys.readouterr().err
        assert "argument --select-blocks: " in err
        assert message in err
    with pytest.raises(SystemExit):
        main(base + ["--c-grid", "0.25,0"])
    assert "argument --c-grid: C values must lie in (0, inf)" in capsys.readouterr().err


def test_trial_cv_of_a_selection_chooses_in_each_fold_without_its_test_block(monkeypatch):
    """Each outer block is scored once, by the mode its own training trials chose, one choice per classifier:
    here the SVM prefers ``combined`` and the online learner ``plain`` inside every training set, but the
    outer block 7-9 scores ``combined`` below ``plain`` (what the test block alone would have chosen)."""
    calls: list = []

    def fake(train, test, cfg):
        name = cfg.classifiers[0]
        outer_test = sorted({r.trial for r in test})
        calls.append((cfg.mode, name, sorted({r.trial for r in train}), outer_test))
        inner_pref = {"svm": {"combined": 0.9, "plain": 0.8}, "pa": {"combined": 0.7, "plain": 0.75}}
        acc = inner_pref[name][cfg.mode]
        if outer_test == [7, 8, 9]:
            acc = {"combined": 0.5, "plain": 0.6}[cfg.mode]
        return {"classifiers": {name: {"accuracy": acc}}}

    monkeypatch.setattr(experiments, "evaluate", fake)
    recs = [_Rec(t) for t in range(1, 10)]
    cfg = EvalConfig(window="2", classifiers=("svm", "pa"))
    out = experiments.selected_trial_cv(recs, cfg, ["plain", "combined"], folds=3)
    assert out["folds"] == [[1, 3], [4, 6], [7, 9]]
    svm, pa = out["classifiers"]["svm"], out["classifiers"]["pa"]
    assert svm["chosen"] == ["combined"] * 3 and pa["chosen"] == ["plain"] * 3
    assert svm["fold_accuracy"] == pytest.approx([0.9, 0.9, 0.5])  # block 7-9 scored with the choice made before
    assert pa["fold_accuracy"] == pytest.approx([0.75, 0.75, 0.6])
    assert svm["accuracy"] == pytest.approx(2.3 / 3) and svm["accuracy_std"] > 0
    # per classifier and block: 2 modes x 3 inner folds, then the block scored once; the inner runs read
    # the block's training trials only
    assert len(calls) == 2 * 3 * 7
    for k in range(0, len(calls), 7):
        *inner, (_, _, outer_train, outer_test) = calls[k:k + 7]
        assert len(outer_test) == 3 and len(outer_train) == 6
        for _, _, train, test in inner:
            assert set(train) | set(test) <= set(outer_train) and not set(train) & set(test)
