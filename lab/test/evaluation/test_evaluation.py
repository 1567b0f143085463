"""Tests of the evaluation library and ``tactile evaluate`` (small: 3 materials, few trials, short windows)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tactile_descriptors_lab.datasets.biotac_slide import load_recordings
from tactile_descriptors_lab.evaluation.bank import (
    DESCRIPTOR_MODES,
    bank_labels,
    compute_bank,
    drop_quantities,
    select_features,
)
from tactile_descriptors_lab.evaluation.classifiers import C_GRID, cv_splits, fit_svm, gmm_nmi, pa_curve
from tactile_descriptors_lab.evaluation.sampling import (
    common_length_frames,
    default_train_windows,
    draw_windows,
    format_trials,
    parse_trials,
    window_frames,
)
from tactile_descriptors_ros.errors import ConfigError
from tactile_descriptors_ros.tools.cli import main


def _blobs(n_classes=4, per_class=30, dim=6, sep=10.0, seed=0):
    rng = np.random.default_rng(seed)
    centres = rng.normal(size=(n_classes, dim)) * sep
    X = np.concatenate([c + rng.normal(size=(per_class, dim)) for c in centres])
    y = np.repeat(np.arange(1, n_classes + 1), per_class)
    trial = np.tile(np.arange(1, per_class + 1), n_classes)
    return X, y, trial


def test_c_grid_is_the_papers():
    expected = [1e-4, 5 ** -4, 3 ** -4, 2 ** -4, 2 ** -3, 2 ** -2, 2 ** -1, 1, 2, 4, 8, 16, 81, 625, 1e4]
    assert np.allclose(C_GRID, expected)
    assert list(C_GRID) == sorted(C_GRID)


def test_svm_selects_from_grid_with_repeated_cv():
    X, y, trial = _blobs()
    labels = [f"M_x{i}" for i in range(X.shape[1])]
    res = fit_svm(X, y, y * 100 + trial, labels, repeats=2, scaling="standardize")
    assert res.best_c in C_GRID
    assert sorted(res.cv_scores) == sorted(C_GRID)
    assert res.cv_accuracy == max(res.cv_scores.values())
    assert np.mean(res.predict(X) == y) == 1.0


def test_c_selection_prints_an_estimate_first_and_scores_every_fit_as_cross_val_score(capsys):
    """The selection's estimate is printed before the first fit; a bar counts fits (not C values); each C's
    mean is scikit-learn's cross_val_score on the same splits; the first r repeats are those of r repeats."""
    from sklearn.model_selection import cross_val_score

    from tactile_descriptors_lab.evaluation.classifiers import _svm_pipeline

    X, y, trial = _blobs()
    labels = [f"M_x{i}" for i in range(X.shape[1])]
    grid = (0.01, 1.0, 100.0)
    res = fit_svm(X, y, y * 100 + trial, labels, repeats=3, scaling="standardize", c_grid=grid, progress=True)
    err = capsys.readouterr().err
    first = err.index(f"choosing C: 3 values x 15 CV fits (5-fold x 3 repeats) of {len(y)} training windows, "
                      "about ")
    assert first < err.index("0/45 [")  # the estimate, then the bar: 3 C x 15 fits, moving a fit at a time
    assert "1/45 [" in err or "fit/s]" in err
    assert res.estimate_s is not None and res.estimate_s > 0
    splits = cv_splits(y, y * 100 + trial, 5, 3, 0)
    for c in grid:
        ref = cross_val_score(_svm_pipeline("standardize", labels, C=c), X, y, cv=splits)
        assert res.cv_split_scores[c] == pytest.approx(list(ref), abs=0)
        assert res.cv_scores[c] == pytest.approx(float(np.mean(ref)), abs=1e-15)
    one = fit_svm(X, y, y * 100 + trial, labels, repeats=1, scaling="standardize", c_grid=grid)
    assert all(one.cv_split_scores[c] == res.cv_split_scores[c][:5] for c in grid)


def test_cv_splits_keep_trials_together_and_repeat():
    X, y, trial = _blobs(per_class=10)
    groups = np.repeat(np.arange(20), 2)  # two windows per trial
    y2 = np.repeat(np.arange(4), 10)
    splits = cv_splits(y2, groups, folds=5, repeats=3, seed=1)
    assert len(splits) == 15
    for tr, va in splits:
        assert not set(groups[tr]) & set(groups[va])
    one_per = cv_splits(y, np.arange(len(y)), folds=5, repeats=10)
    assert len(one_per) == 50
    with pytest.raises(ConfigError):
        cv_splits(np.array([1, 1, 2, 2]), np.arange(4), folds=5)


def test_pa_curve_learns_separable_classes():
    X, y, trial = _blobs(per_class=12, sep=6.0)
    Xte, yte, _ = _blobs(per_class=10, sep=6.0, seed=0)  # same centres (same seed), new noise below
    Xte = Xte + np.random.default_rng(5).normal(scale=0.5, size=Xte.shape)
    labels = [f"M_x{i}" for i in range(X.shape[1])]
    curve = pa_curve(X, y, trial, Xte, yte, labels, n_max=30, orders=3, seed=0)
    assert curve.n_per_class.tolist() == list(range(1, 13))  # capped by the trials available
    assert curve.accuracy[-1] >= 0.95
    assert curve.accuracy[-3:].mean() >= curve.accuracy[:2].mean()
    assert curve.update_s > 0 and curve.predict_s > 0


def test_nmi_is_one_on_separable_clusters():
    X, y, _ = _blobs(n_classes=5, per_class=20, sep=50.0)
    labels = [f"M_x{i}" for i in range(X.shape[1])]
    res = gmm_nmi(X, y, X, y, labels, scaling="standardize", seed=0)
    assert res.nmi_test == pytest.approx(1.0)
    assert res.nmi_train == pytest.approx(1.0)
    assert res.accuracy == 1.0


def test_parse_trials():
    assert parse_trials("1-3,7") == [1, 2, 3, 7]
    assert parse_trials("all") is None
    assert format_trials([1, 2, 3, 7, 9, 10]) == "1-3,7,9-10"
    for bad in ("3-1", "x", "0-2"):
        with pytest.raises(ConfigError):
            parse_trials(bad)


def test_drop_quantities_and_modes():
    labels = bank_labels()
    assert len(labels["paper"]) == 8 and len(labels["per_channel"]) == 98 and len(labels["bands"]) == 18
    keep = drop_quantities(labels["paper"], ["L", "N"])
    assert keep.sum() == 6
    with pytest.raises(ConfigError):
        drop_quantities(labels["paper"], ["Q"])
    assert set(DESCRIPTOR_MODES) >= {"paper", "per_channel", "multiband", "baseline"}


@pytest.fixture(scope="module")
def small_recs(biotac_data_dir):
    if not biotac_data_dir.is_dir():
        pytest.skip("real recordings not found")
    return load_recordings(biotac_data_dir, trials=range(1, 5), materials=[1, 2, 3])


@pytest.mark.realdata
def test_crop_rule_no_duration_leak(small_recs, tmp_path):
    lengths = {r.material: r.n_frames for r in small_recs}
    assert lengths[1] < lengths[2]  # material 1 is shorter: the leak we guard against
    common = common_length_frames(small_recs)
    assert common == min(r.n_frames for r in small_recs)
    n = window_frames("1", 100.0, common)
    wins = draw_windows(small_recs, n, common, per_trial=3, seed=4)
    assert {w.n_frames for w in wins} == {n}
    assert all(0 <= w.start and w.start + w.n_frames <= common for w in wins)
    assert wins == draw_windows(small_recs, n, common, per_trial=3, seed=4)  # seeded
    whole = draw_windows(small_recs, window_frames("whole", 100.0, common), common, per_trial=3)
    assert len(whole) == len(small_recs) and {(w.start, w.n_frames) for w in whole} == {(0, common)}
    with pytest.raises(ConfigError):
        window_frames(str(common / 100.0 + 1.0), 100.0, common)
    bank = compute_bank(small_recs, whole, cache_dir=tmp_path, subwindows=True)
    for mode in DESCRIPTOR_MODES:
        X, labels = select_features(bank, mode)
        assert X.shape == (len(whole), len(labels)) and np.all(np.isfinite(X))
    # the cache returns the same values
    again = compute_bank(small_recs, whole, cache_dir=tmp_path)
    assert np.array_equal(again.groups["per_channel"], bank.groups["per_channel"])
    # gate: windows out of contact are zeros
    bank.in_contact[0] = False
    X, _ = select_features(bank, "paper")
    assert not X[0].any() and X[1].any()
    X, _ = select_features(bank, "paper", gate=False)
    assert X[0].any()


@pytest.mark.realdata
def test_cli_evaluate_json_shape(biotac_data_dir, tmp_path, capsys):
    common = ["evaluate", "--train", str(biotac_data_dir), "--test", str(biotac_data_dir),
              "--materials", "1-3", "--train-trials", "1-5", "--test-trials", "6-7", "--window", "0.5",
              "--channels", "per_channel", "--cv-repeats", "1", "--train-windows", "1", "--test-windows", "2",
              "--jobs", "1", "--cache", str(tmp_path), "--json"]
    assert main(common + ["--classifier", "svm"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert 0.0 <= out["accuracy"] <= 1.0
    assert out["accuracy"] == out["classifiers"]["svm"]["accuracy"]
    assert out["n_test"] == 3 * 2 * 2 and out["n_features"] == 98
    assert out["train_windows_per_trial"] == 1 and out["n_train"] == 3 * 5 * 1
    cm = np.array(out["classifiers"]["svm"]["confusion"])
    assert cm.shape == (3, 3) and cm.sum() == out["n_test"]
    assert out["classifiers"]["svm"]["best_c"] in C_GRID
    assert main(common + ["--classifier", "all"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["classifiers"]) == {"svm", "pa", "gmm"}
    for res in out["classifiers"].values():
        assert 0.0 <= res["accuracy"] <= 1.0
    assert 0.0 <= out["classifiers"]["gmm"]["nmi"] <= 1.0
    assert len(out["classifiers"]["pa"]["curve"]["accuracy"]) == 5


def test_default_training_windows_add_up_to_16_s_per_trial_and_never_fewer_than_8():
    assert default_train_windows([200], 100.0) == 8
    assert default_train_windows([599], 100.0) == 8
    assert default_train_windows([100], 100.0) == 16
    assert default_train_windows([50], 100.0) == 32
    assert default_train_windows([150], 100.0) == 11  # ceil(16 / 1.5)
    assert default_train_windows([100, 150, 200], 100.0) == 16  # a range of lengths: its shortest


@pytest.mark.realdata
def test_cli_draws_the_default_training_windows_of_the_window_length(biotac_data_dir, tmp_path, capsys):
    common = ["evaluate", "--train", str(biotac_data_dir), "--test", str(biotac_data_dir),
              "--materials", "1-2", "--train-trials", "1-5", "--test-trials", "6", "--window", "1",
              "--channels", "paper", "--cv-repeats", "1", "--test-windows", "1", "--jobs", "1",
              "--cache", str(tmp_path), "--json"]
    assert main(common) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["train_windows_per_trial"] == 16 and out["n_train"] == 2 * 5 * 16
    assert out["config"]["train_per_trial"] is None


@pytest.mark.realdata
def test_cli_rejects_overlapping_trials(biotac_data_dir, tmp_path, capsys):
    rc = main(["evaluate", "--train", str(biotac_data_dir), "--test", str(biotac_data_dir), "--materials", "1-2",
               "--train-trials", "1-5", "--test-trials", "5-6", "--cache", str(tmp_path)])
    assert rc == 2
    assert "share" in capsys.readouterr().err


def test_one_source_splits_by_trial_two_thirds_to_training_by_default():
    from tactile_descriptors_lab.verbs.cmd_evaluate import default_trials, split_trials

    thirty = list(range(1, 31))
    assert split_trials(thirty, None, None, False, False) == (list(range(1, 21)), list(range(21, 31)))
    assert split_trials([3, 5, 9], None, None, False, False) == ([3, 5], [9])
    assert split_trials(thirty, [1, 2], None, True, False) == ([1, 2], list(range(3, 31)))
    with pytest.raises(ConfigError, match="share trials 5"):
        split_trials(thirty, [1, 5], [5, 6], True, True)
    with pytest.raises(ConfigError, match="too few"):
        split_trials([4], None, None, False, False)
    assert default_trials("a", "b", None, None) == (None, None)
    assert default_trials("a", "b", "1-3", "all") == ([1, 2, 3], None)


@pytest.mark.realdata
def test_cli_scores_a_separate_folder_whose_trial_numbers_collide(biotac_data_dir, tmp_path, capsys):
    """A second set of recordings numbered from 1 again is scored on its own files, with the default mode."""
    unseen = tmp_path / "unseen"
    for m in (1, 2, 3):
        d = unseen / "raw_data" / f"mat{m}"
        d.mkdir(parents=True)
        for new, old in ((1, 21), (2, 22)):
            (d / f"mat{m}_{new}_bio.csv").symlink_to(biotac_data_dir / "raw_data" / f"mat{m}" / f"mat{m}_{old}_bio.csv")
    args = ["evaluate", "--train", str(biotac_data_dir), "--test", str(unseen), "--materials", "1-3",
            "--train-trials", "1-5", "--window", "0.5", "--cv-repeats", "1", "--train-windows", "1",
            "--test-windows", "1", "--jobs", "1", "--cache", str(tmp_path / "cache"), "--json"]
    assert main(args + ["--classifier", "pa"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["test_trials"] == [1, 2] and out["train_trials"] == [1, 2, 3, 4, 5]
    assert out["n_features"] == 261 and out["config"]["mode"] == "combined"
    assert out["config"]["gate"] is False
    assert (out["config"]["pa_update"], out["config"]["pa_average"]) == ("arow", False)
    assert out["n_test"] == 3 * 2 and 0.0 <= out["accuracy"] <= 1.0
    # the test split's windows come from the test folder's files: the same windows described from the
    # original files (trials 21, 22 renamed 1, 2) give the same descriptors
    from tactile_descriptors_lab.evaluation.bank import compute_bank
    from tactile_descriptors_lab.evaluation.sampling import Window, load_split

    renamed = load_split(unseen, None, [1, 2, 3])
    original = load_split(biotac_data_dir, [21, 22], [1, 2, 3])
    w_new = [Window(1, 2, 17, 50)]
    w_old = [Window(1, 22, 17, 50)]
    got = compute_bank(renamed, w_new, jobs=1).groups["per_channel"]
    want = compute_bank(original, w_old, jobs=1).groups["per_channel"]
    np.testing.assert_array_equal(got, want)
    with pytest.raises(ConfigError, match="twice"):
        compute_bank(renamed + load_split(biotac_data_dir, [1, 2], [1]), w_new, jobs=1)


@pytest.mark.realdata
def test_subwindow_group_is_mean_and_sd_over_the_pieces(small_recs, tmp_path):
    from tactile_descriptors_lab.evaluation.bank import N_SUBWINDOWS, subwindow_starts
    from tactile_descriptors_lab.evaluation.sampling import Window

    wins = [Window(2, 3, 10, 203), Window(1, 1, 0, 203)]
    bank = compute_bank(small_recs, wins, cache_dir=tmp_path, subwindows=True)
    labels = bank.labels["subwindows"]
    assert len(labels) == 2 * (98 + 18) and labels[0] == "subwindows/mean_" + bank.labels["per_channel"][0].split("/")[1]
    pieces = subwindow_starts(wins[0])
    assert [(p.start, p.n_frames) for p in pieces] == [(10, 50), (60, 50), (110, 50), (160, 50)]  # 3 frames unused
    each = compute_bank(small_recs, pieces)
    vals = np.concatenate([each.groups["per_channel"], each.groups["bands"]], axis=1)
    names = bank.labels["per_channel"] + bank.labels["bands"]
    act = np.array([n.split("/")[1].startswith("A_") for n in names])
    vals[:, act] = np.log1p(vals[:, act])
    want = np.concatenate([vals.mean(axis=0), vals.std(axis=0)])
    np.testing.assert_allclose(bank.groups["subwindows"][0], want, rtol=1e-12, atol=1e-12)
    assert N_SUBWINDOWS == 4 and np.all(np.isfinite(bank.groups["subwindows"]))
    # "without A" also drops the pieces' Activity statistics
    keep = drop_quantities(labels, ["A"])
    assert not any(lab.split("/")[1].split("_")[1] == "A" for lab, k in zip(labels, keep) if k)
    assert keep.sum() < len(labels)
    with pytest.raises(ConfigError, match="subwindows=True"):
        select_features(compute_bank(small_recs, wins), "combined_subwindows")
    with pytest.raises(ConfigError, match="too short"):
        subwindow_starts(Window(1, 1, 0, 11))
