"""Touch length: window ranges, mixed-length banks, one training scored on several lengths, the report section."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from tactile_descriptors_lab.datasets.biotac_slide import load_recordings
from tactile_descriptors_lab.evaluation.bank import compute_bank
from tactile_descriptors_lab.evaluation.experiments import (
    EvalConfig,
    describe_windows,
    draw_spec_windows,
    evaluate,
    evaluate_many,
)
from tactile_descriptors_lab.evaluation.sampling import (
    Window,
    block_windows,
    draw_mixed_windows,
    draw_windows,
    is_length_range,
    window_lengths,
)
from tactile_descriptors_ros.errors import ConfigError


def _recs(n_frames: int = 599, materials=(1, 2, 3), trials=(1, 2, 3, 4)):
    """Stand-ins for recordings: draw_*_windows read only material, trial, n_frames and path."""
    return [SimpleNamespace(material=m, trial=t, n_frames=n_frames, path=f"/x/mat{m}_{t}.csv")
            for m in materials for t in trials]


def test_a_range_of_lengths_is_a_half_second_grid_ending_at_the_crop():
    assert window_lengths("1-6", 100.0, 599) == (100, 150, 200, 250, 300, 350, 400, 450, 500, 550, 599)
    assert window_lengths("0.5-2", 100.0, 599) == (50, 100, 150, 200)
    assert window_lengths("2", 100.0, 599) == (200,)
    assert window_lengths("whole", 100.0, 599) == (599,)
    assert is_length_range("1-6") and is_length_range("0.5 - 2") and not is_length_range("2")
    for bad in ("6-1", "2-2", "0.01-1", "7-9"):
        with pytest.raises(ConfigError):
            window_lengths(bad, 100.0, 599)


def test_mixed_windows_cover_the_grid_inside_the_crop_seeded_per_trial():
    recs = _recs()
    lengths = window_lengths("1-6", 100.0, 599)
    wins = draw_mixed_windows(recs, lengths, 599, per_trial=30, seed=3)
    assert len(wins) == 30 * len(recs)
    assert {w.n_frames for w in wins} == set(lengths)  # 360 draws over 11 lengths: every length occurs
    assert all(0 <= w.start and w.start + w.n_frames <= 599 for w in wins)
    assert wins == draw_mixed_windows(recs, lengths, 599, per_trial=30, seed=3)
    assert wins != draw_mixed_windows(recs, lengths, 599, per_trial=30, seed=4)
    # a trial's windows do not depend on which other trials are loaded
    alone = draw_mixed_windows(recs[5:6], lengths, 599, per_trial=30, seed=3)
    assert alone == [w for w in wins if (w.material, w.trial) == (recs[5].material, recs[5].trial)]
    # length is independent of the class: every material sees short and long windows alike
    by_mat = {m: np.mean([w.n_frames for w in wins if w.material == m]) for m in (1, 2, 3)}
    assert max(by_mat.values()) - min(by_mat.values()) < 120  # grid spans 499 frames
    # one length keeps the single-length positions (cache entries and published figures stay valid)
    one, got = draw_spec_windows(recs, "2", 100.0, 599, 4, 7)
    assert got == (200,) and one == draw_windows(recs, 200, 599, 4, 7)
    with pytest.raises(ConfigError):
        draw_mixed_windows(recs, [100, 600], 599)


@pytest.fixture(scope="module")
def small_recs(biotac_data_dir):
    if not biotac_data_dir.is_dir():
        pytest.skip("real recordings not found")
    return load_recordings(biotac_data_dir, trials=range(1, 7), materials=[1, 2, 3])


@pytest.mark.realdata
def test_a_mixed_length_bank_holds_each_windows_own_descriptor_in_order(small_recs, tmp_path):
    wins = [Window(2, 3, 10, 120), Window(1, 1, 0, 60), Window(3, 2, 5, 120), Window(1, 4, 33, 60)]
    bank = describe_windows(small_recs, wins, cache_dir=tmp_path)
    assert bank.windows == wins and list(bank.y) == [2, 1, 3, 1]
    for i, w in enumerate(wins):
        one = compute_bank(small_recs, [w])
        for g, rows in one.groups.items():
            np.testing.assert_array_equal(bank.groups[g][i], rows[0])
        assert bank.mean_force_n[i] == one.mean_force_n[0]
    # the two lengths give different descriptors of the same start: rows were not mixed up
    assert not np.array_equal(bank.groups["per_channel"][0], bank.groups["per_channel"][2])


@pytest.mark.realdata
def test_one_training_scored_on_several_lengths_equals_separate_evaluations(small_recs, tmp_path):
    train = [r for r in small_recs if r.trial <= 4]
    test = [r for r in small_recs if r.trial > 4]
    cfg = EvalConfig(window="1", mode="per_channel", classifiers=("svm", "pa", "gmm"), train_per_trial=2,
                     test_per_trial=2, cv_repeats=1, pa_orders=2, jobs=1, cache_dir=str(tmp_path))
    many = evaluate_many(train, test, cfg, ["0.5", "0.5-2"])
    for spec in ("0.5", "0.5-2"):
        alone = evaluate(train, test, replace(cfg, test_window=spec))
        for name in ("svm", "pa", "gmm"):
            assert many[spec]["classifiers"][name]["accuracy"] == alone["classifiers"][name]["accuracy"]
            assert many[spec]["classifiers"][name]["confusion"] == alone["classifiers"][name]["confusion"]
        assert many[spec]["classifiers"]["pa"]["curve"] == alone["classifiers"]["pa"]["curve"]
        assert many[spec]["classifiers"]["gmm"]["nmi"] == pytest.approx(alone["classifiers"]["gmm"]["nmi"])
    assert many["0.5"]["test_window_frames"] == 50
    assert many["0.5-2"]["test_window_frames"] == [50, 100, 150, 200]
    assert many["0.5-2"]["config"]["test_window"] == "0.5-2"


def test_blocks_spread_evenly_and_cover_the_window():
    w = Window(3, 7, 40, 200)
    assert block_windows(w, 100, 50) == [Window(3, 7, 40, 100), Window(3, 7, 90, 100), Window(3, 7, 140, 100)]
    blocks = block_windows(Window(1, 1, 0, 599), 100, 50)
    starts = [b.start for b in blocks]
    assert len(blocks) == 11 and starts[0] == 0 and starts[-1] == 499  # first and last frame covered
    assert max(np.diff(starts)) <= 50 and {b.n_frames for b in blocks} == {100}
    assert block_windows(Window(1, 1, 5, 80), 100, 50) == [Window(1, 1, 5, 80)]  # shorter: its own block
    with pytest.raises(ConfigError):
        block_windows(w, 100, 0)
    with pytest.raises(ConfigError):
        block_windows(w, 2, 1)


@pytest.mark.realdata
def test_block_mean_bank_is_the_mean_of_its_blocks_with_activity_in_log(small_recs, tmp_path):
    from tactile_descriptors_ros.core.scaling import activity_mask

    w = Window(2, 3, 10, 200)
    bank = describe_windows(small_recs, [w, Window(1, 2, 0, 100)], block_frames=100, hop_frames=50,
                            cache_dir=tmp_path)
    blocks = compute_bank(small_recs, block_windows(w, 100, 50))
    for g, rows in blocks.groups.items():
        mask = activity_mask(blocks.labels[g])
        want = rows.mean(axis=0)
        want[mask] = np.expm1(np.log1p(rows[:, mask]).mean(axis=0))
        np.testing.assert_allclose(bank.groups[g][0], want, rtol=1e-12, atol=1e-12)
        assert mask.any() == (g in ("paper", "per_channel", "bands"))  # the groups holding Activity
    assert bank.mean_force_n[0] == pytest.approx(blocks.mean_force_n.mean())
    # a window of one block length is that block
    one = compute_bank(small_recs, [Window(1, 2, 0, 100)])
    np.testing.assert_allclose(bank.groups["per_channel"][1], one.groups["per_channel"][0], rtol=1e-12)


def _length_shift(recs, cache, **blocks) -> float:
    """Mean |shift| of the scaled features between whole-trial and 2 s windows of the same trials."""
    from tactile_descriptors_lab.evaluation.bank import select_features
    from tactile_descriptors_lab.evaluation.classifiers import make_scaler
    from tactile_descriptors_lab.evaluation.sampling import common_length_frames

    common = common_length_frames(recs)
    two = describe_windows(recs, draw_windows(recs, 200, common, 4, 0), cache_dir=cache, **blocks)
    whole = describe_windows(recs, draw_windows(recs, common, common, 1, 0), cache_dir=cache, **blocks)
    X2, labels = select_features(two, "combined", gate=False)
    Xw, _ = select_features(whole, "combined", gate=False)
    scaler = make_scaler("log_standardize", labels).fit(X2)
    return float(np.mean(np.abs(scaler.transform(Xw).mean(axis=0) - scaler.transform(X2).mean(axis=0))))


@pytest.mark.realdata
@pytest.mark.slow
def test_block_averaging_keeps_the_descriptor_where_2s_training_put_it_on_whole_trials(small_recs, tmp_path):
    """The cause of the touch-length loss, on real trials: whole-window descriptors drift away from 2 s ones."""
    recs = [r for r in small_recs if r.trial <= 4]
    window = _length_shift(recs, tmp_path)
    blocks = _length_shift(recs, tmp_path, block_frames=100, hop_frames=50)
    # measured on these 12 trials: 1.61 (one descriptor per window) against 0.27 (blocks), in training sd units
    assert window > 1.0
    assert blocks < 0.35 * window
