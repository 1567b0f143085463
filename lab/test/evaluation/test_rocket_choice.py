"""Evaluating with another fitted rocket transform, and choosing among transforms inside the training trials.

``tactile evaluate --rocket FILE`` and ``--select-rocket FILE,FILE``
(:func:`~tactile_descriptors_lab.evaluation.rocket_fit.transform_in_use`,
:func:`~tactile_descriptors_lab.evaluation.experiments.select_mode`).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from tactile_descriptors_lab.evaluation import experiments
from tactile_descriptors_lab.evaluation.experiments import EvalConfig, evaluate_selected, select_mode
from tactile_descriptors_lab.evaluation.rocket_fit import transform_in_use
from tactile_descriptors_ros.core import rocket
from tactile_descriptors_ros.core.groups import group_labels, rocket_parameters
from tactile_descriptors_ros.core.robot import load_robot
from tactile_descriptors_ros.core.yamlreader import config_dir
from tactile_descriptors_ros.errors import ConfigError
from tactile_descriptors_ros.tools.cli import main

SHIPPED = config_dir() / "rocket" / "biotac.json"


def _biotac():
    return load_robot("shadow_hand").cell_types["biotac"]


def _small_file(path: Path, slow_channels: int = 22) -> Path:
    """A transform of other sizes than the shipped one (84 + 168 features), fitted on noise."""
    rng = np.random.default_rng(3)
    rocket.save_parameters(path, {"vibration": rocket.fit(rng.integers(-50, 50, size=(4, 1, 97)), 84, seed=1),
                                  "slow": rocket.fit(rng.integers(-50, 50, size=(4, slow_channels, 100)), 168,
                                                     seed=2)})
    return path


@pytest.mark.parametrize("before", [None, "keep"])
def test_transform_in_use_is_what_the_engine_reads_inside_and_only_inside(tmp_path, monkeypatch, before):
    ct = _biotac()
    if before is None:
        monkeypatch.delenv("TACTILE_CONFIG_DIR", raising=False)
    else:
        monkeypatch.setenv("TACTILE_CONFIG_DIR", str(config_dir()))
    env = os.environ.get("TACTILE_CONFIG_DIR")
    shipped = len(group_labels(ct, "rocket"))
    small = _small_file(tmp_path / "small.json")
    with transform_in_use(small, ct) as used:
        assert used == small.resolve()
        inside = config_dir()
        assert rocket_parameters(ct)["vibration"].n_features == 84
        assert len(group_labels(ct, "rocket")) == 84 + 168
        assert (inside / "shadow_hand.yaml").is_file() and (inside / "nao.yaml").is_file()  # the rest as before
    assert os.environ.get("TACTILE_CONFIG_DIR") == env
    assert not inside.exists()
    assert len(group_labels(ct, "rocket")) == shipped
    with pytest.raises(RuntimeError, match="boom"), transform_in_use(small, ct):
        raise RuntimeError("boom")
    assert os.environ.get("TACTILE_CONFIG_DIR") == env  # restored on an error too
    with transform_in_use(None, ct) as used:
        assert used is None and os.environ.get("TACTILE_CONFIG_DIR") == env


def test_a_transform_that_cannot_serve_is_refused_naming_the_file(tmp_path):
    ct = _biotac()
    wrong = _small_file(tmp_path / "three_slow_channels.json", slow_channels=3)
    with pytest.raises(ConfigError, match=r"three_slow_channels\.json: the 'slow' transform takes 3 channels, cell "
                                          r"type 'biotac' has 22"):
        with transform_in_use(wrong, ct):
            pass
    with pytest.raises(ConfigError, match="no such file"):
        with transform_in_use(tmp_path / "missing.json", ct):
            pass
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    with pytest.raises(ConfigError, match=r"bad\.json: not a rocket parameters file"):
        with transform_in_use(bad, ct):
            pass
    assert "TACTILE_CONFIG_DIR" not in os.environ or Path(os.environ["TACTILE_CONFIG_DIR"]).is_dir()


@dataclass(frozen=True)
class _Rec:
    trial: int
    path: str = ""


def test_selection_tries_each_rocket_mode_with_each_file_and_scores_the_test_with_the_choice(monkeypatch):
    table = {("plain", None): 0.80, ("rocket", "a.json"): 0.90, ("rocket", "b.json"): 0.93,
             ("combined_rocket", "a.json"): 0.91, ("combined_rocket", "b.json"): 0.92}
    calls: list = []

    def fake(train, test, cfg):
        calls.append((cfg.mode, cfg.rocket_file, sorted({r.trial for r in test})))
        return {"classifiers": {cfg.classifiers[0]: {"accuracy": table[(cfg.mode, cfg.rocket_file)]}}}

    monkeypatch.setattr(experiments, "evaluate", fake)
    train, test = [_Rec(t) for t in range(1, 10)], [_Rec(t) for t in range(10, 13)]
    cfg = EvalConfig(window="1", mode="plain", classifiers=("pa",), block_s=None, block_hop_s=None)
    out = evaluate_selected(train, test, cfg, ["plain", "rocket", "combined_rocket"], rockets=["a.json", "b.json"])
    sel = out["selection"]
    assert list(sel["candidates"]) == ["plain", "rocket, transform a.json", "rocket, transform b.json",
                                       "combined_rocket, transform a.json", "combined_rocket, transform b.json"]
    assert sel["candidates"]["plain"]["rocket_file"] is None  # a mode without the group runs once
    assert sel["chosen_label"] == "rocket, transform b.json"
    assert sel["chosen"] == "rocket" and sel["rocket_file"] == "b.json"
    assert calls[-1] == ("rocket", "b.json", [10, 11, 12])  # the test split once, with the chosen transform
    assert sum(1 for c in calls if c[2] == [10, 11, 12]) == 1
    with pytest.raises(ConfigError, match="no candidate mode holds the group"):
        select_mode(train, cfg, ["plain", "combined"], rockets=["a.json"])


@pytest.mark.realdata
def test_cli_evaluates_with_a_transform_file_and_chooses_among_files(biotac_data_dir, tmp_path, capsys):
    """End to end on three materials: ``--rocket`` runs the file's sizes (in the worker processes too, with
    one bank cache for all), ``--select-rocket`` chooses inside the training trials and scores the test as
    the choice given by hand does."""
    small = _small_file(tmp_path / "small.json")
    common = ["evaluate", "--train", str(biotac_data_dir), "--test", str(biotac_data_dir), "--materials", "1-3",
              "--train-trials", "1-6", "--test-trials", "7-8", "--window", "1", "--classifier", "pa",
              "--train-windows", "2", "--jobs", "2", "--cache", str(tmp_path / "cache"), "--json"]
    assert main(common + ["--channels", "rocket", "--rocket", str(small)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["n_features"] == 84 + 168 and out["config"]["rocket_file"] == str(small)
    assert main(common + ["--channels", "rocket"]) == 0  # the same cache, the shipped transform
    shipped = json.loads(capsys.readouterr().out)
    assert shipped["n_features"] == len(group_labels(_biotac(), "rocket")) != 84 + 168
    assert shipped["config"]["rocket_file"] is None
    assert main(common + ["--select", "plain,rocket", "--select-rocket", f"{SHIPPED},{small}"]) == 0
    out = json.loads(capsys.readouterr().out)
    sel = out["selection"]
    assert set(sel["candidates"]) == {"plain", f"rocket, transform {SHIPPED}", f"rocket, transform {small}"}
    best = max(v["accuracy"] for v in sel["candidates"].values())
    assert sel["candidates"][sel["chosen_label"]]["accuracy"] == best
    by_hand = ["--channels", sel["chosen"]] + (["--rocket", sel["rocket_file"]] if sel["rocket_file"] else [])
    assert main(common + by_hand) == 0
    alone = json.loads(capsys.readouterr().out)
    assert alone["classifiers"]["pa"]["accuracy"] == out["classifiers"]["pa"]["accuracy"]
    assert alone["n_features"] == out["n_features"]


@pytest.mark.parametrize("extra, message", [
    (["--select-rocket", "x.json"], "--select-rocket chooses among transforms with --select"),
    (["--select", "rocket", "--select-rocket", ","], "--select-rocket needs at least one transform file"),
    (["--select", "rocket", "--select-rocket", "{small}", "--rocket", "{small}"], "not both"),
    (["--channels", "paper", "--rocket", "{small}"], "mode paper has no rocket group"),
    (["--channels", "rocket", "--rocket", "{missing}"], "missing.json: no such file"),
    (["--select", "rocket", "--select-rocket", "{small},{missing}"], "missing.json: no such file"),
])
def test_cli_refuses_bad_transform_options_before_reading_data(tmp_path, capsys, extra, message):
    small = _small_file(tmp_path / "small.json")
    extra = [e.format(small=small, missing=tmp_path / "missing.json") for e in extra]
    no_data = str(tmp_path / "no_such_data")  # read first, the error would name this folder
    assert main(["evaluate", "--train", no_data, "--test", no_data] + extra) == 2
    err = capsys.readouterr().err
    assert message in err and "no_such_data" not in err
