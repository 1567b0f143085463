"""Feature groups of the core (core/features.py): known answers, against scipy, selection checks."""

from __future__ import annotations

import copy
import warnings

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy import signal, stats

from tactile_descriptors_ros.core.aggregation import CellSignals, describe_window
from tactile_descriptors_ros.core.descriptors import Quality, hjorth
from tactile_descriptors_ros.core.features import (
    band_hjorth,
    band_powers,
    level_values,
    moments,
    power_spectrum,
    spectral_length,
)
from tactile_descriptors_ros.core.groups import (
    GROUPS,
    check_groups,
    deformation_bands,
    group_labels,
    groups_in_labels,
    parse_group,
    selection_labels,
    vibration_bands,
)
from tactile_descriptors_ros.core.robot import load_robot, parse_robot, robot_config_path
from tactile_descriptors_ros.errors import ConfigError, SignalError


def _biotac_cell(rng, force=1.0, n_frames=200, extra=True):
    frame_t = np.arange(n_frames, dtype=np.int64) * 10_000_000
    pac_t = (frame_t[:, None] + np.arange(22) * 10_000_000 // 22).ravel()
    pac = np.clip(np.rint(2000 + np.convolve(rng.normal(0, 30, pac_t.size + 2), [1, .7, .2], "valid")), 0, 4095)
    el = np.clip(np.rint(2500 + rng.normal(0, 3, (19, n_frames)).cumsum(axis=1)), 0, 4095)
    ex = np.stack([rng.normal(40, 2, n_frames), rng.normal(2000, 5, n_frames), rng.normal(1500, 5, n_frames)])
    return CellSignals(pac.astype(np.int64)[None], pac_t, el.astype(np.int64), frame_t, np.full(n_frames, force),
                       extra=ex if extra else None)


def _skin_cell(rng, force=1.0, n=2000, prox=True, temp=31.5):
    ta = np.arange(n, dtype=np.int64) * 1_000_000
    tf = np.arange(n // 4, dtype=np.int64) * 4_000_000
    acc = np.rint(rng.normal(0, 10, (3, n))).astype(np.int32)
    f = np.rint(400 + rng.normal(0, 5, (3, n // 4))).astype(np.int32)
    ex = np.stack([rng.normal(900, 10, n // 4) if prox else np.full(n // 4, np.nan), np.full(n // 4, temp)])
    return CellSignals(acc, ta, f, tf, np.full(n // 4, force), extra=ex)


# ------------------------------------------------------------------ against scipy
@settings(max_examples=60, deadline=None)
@given(arrays(np.float64, st.tuples(st.integers(1, 3), st.integers(4, 300)),
              elements=st.floats(-1e3, 1e3, allow_nan=False)))
def test_moments_equal_scipy_skew_and_kurtosis(x):
    lv, sk, ku = moments(x)
    np.testing.assert_allclose(lv, np.log1p(x.var(axis=-1)), rtol=1e-10, atol=1e-12)
    flat = x.var(axis=-1) <= 1e-12 * np.maximum(1.0, np.abs(x).max(axis=-1)) ** 2
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        want_sk, want_ku = stats.skew(x, axis=-1), stats.kurtosis(x, axis=-1)
    # a flat signal has no shape: 0 by definition (scipy gives NaN there); nearly flat signals lose
    # precision in both (scipy warns), so they are compared where the spread is well above rounding
    clear = x.var(axis=-1) > 1e-8 * np.maximum(1.0, np.abs(x).max(axis=-1)) ** 2
    np.testing.assert_allclose(sk[clear], want_sk[clear], rtol=1e-7, atol=1e-7)
    np.testing.assert_allclose(ku[clear], want_ku[clear], rtol=1e-7, atol=1e-7)
    assert np.all(sk[flat] == 0) and np.all(ku[flat] == 0)


def _circular_hjorth(y, fs):
    d = (np.roll(y, -1) - y) * fs
    dd = (np.roll(d, -1) - d) * fs
    a, a1, a2 = y.var(), d.var(), dd.var()
    m = np.sqrt(a1 / a)
    return a, m, np.sqrt(a2 / a1) / m


@pytest.mark.parametrize("n", [4400, 4401, 1000])
def test_band_hjorth_equals_time_domain_hjorth_of_the_band_limited_signal(n):
    """The spectral moments give what the time domain gives on irfft of the masked spectrum."""
    rng = np.random.default_rng(n)
    x = rng.normal(0, 10, (2, 1, n)) + 3000
    got = band_hjorth(x, 2200.0)
    bands = vibration_bands(2200.0)
    m = spectral_length(n)  # 4401 -> its last 4400 samples
    f = np.fft.rfftfreq(m, 1 / 2200.0)
    for c in range(2):
        X = np.fft.rfft(x[c, 0, n - m:] - x[c, 0, n - m:].mean())
        for b, (lo, hi) in enumerate(bands):
            y = np.fft.irfft(np.where((f >= lo) & (f < hi), X, 0.0), m)
            np.testing.assert_allclose(got[c, [b, len(bands) + b, 2 * len(bands) + b]], _circular_hjorth(y, 2200.0),
                                       rtol=1e-9)


def test_band_hjorth_close_to_a_butterworth_bandpass_in_the_band_middle():
    """For noise, the ideal band-pass and scipy's 4th-order Butterworth agree on Mobility within a few %."""
    rng = np.random.default_rng(0)
    x = rng.normal(0, 10, (1, 1, 22000))
    got = band_hjorth(x, 2200.0)[0]
    bands = vibration_bands(2200.0)
    for b, (lo, hi) in enumerate(bands[1:4], start=1):
        sos = signal.butter(4, [lo, hi], btype="bandpass", fs=2200.0, output="sos")
        h = hjorth(signal.sosfilt(sos, x[0, 0]), 2200.0)
        assert got[len(bands) + b] == pytest.approx(float(h.mobility), rel=0.05)


def test_band_hjorth_puts_a_sine_in_its_band():
    t = np.arange(4400) / 2200.0
    x = (100 * np.sin(2 * np.pi * 300 * t))[None, None]
    got = band_hjorth(x, 2200.0)[0]
    bands = vibration_bands(2200.0)
    act = got[:len(bands)]
    k = [i for i, (lo, hi) in enumerate(bands) if lo <= 300 < hi][0]
    # a 4th-order band-pass: the neighbour band keeps under 1/20 of the power (-13 dB) at 300 Hz
    assert np.argmax(act) == k and act[k] > 20 * np.delete(act, k).max()
    assert act[k] == pytest.approx(100**2 / 2, rel=0.02)  # the sine's variance
    assert got[len(bands) + k] == pytest.approx(2 * 2200 * np.sin(np.pi * 300 / 2200), rel=0.02)  # Mobility, rad/s


def test_spectral_length_keeps_the_robots_windows_and_drops_few_samples_of_others():
    # the windows the robots and the evaluation cut (skin 2 s, BioTac 2 s and 1 s blocks, 0.5-6 s touches)
    for n in (2000, 500, 4400, 200, 2200, 100, 1100, 6600, 13200, 150, 600):
        assert spectral_length(n) == n
    assert spectral_length(501) == 500 and spectral_length(2003) == 2000 and spectral_length(0) == 0
    for n in range(1, 20000, 7):
        m = spectral_length(n)
        assert m <= n and n - m <= (0.022 * n if n >= 1000 else 0.06 * n if n >= 100 else n / 2)
        assert max(_prime_factors(m), default=1) <= 11


def _prime_factors(m):
    out, p = [], 2
    while p * p <= m:
        while m % p == 0:
            out.append(p)
            m //= p
        p += 1
    return out + ([m] if m > 1 else [])


@pytest.mark.parametrize("dtype", [np.int32, np.int64, np.float64, np.float32])
def test_power_spectrum_of_an_odd_length_is_that_of_its_last_fast_length(dtype):
    rng = np.random.default_rng(5)
    x = rng.integers(-500, 500, (4, 3, 501)).astype(dtype)
    got = power_spectrum(x)
    assert got.shape == (4, 3, 251)
    want = power_spectrum(x[..., 1:])
    np.testing.assert_array_equal(got, want)
    # Parseval over those samples
    rtol = 1e-5 if dtype == np.float32 else 1e-12
    np.testing.assert_allclose(got.sum(-1), x[..., 1:].astype(np.float64).var(axis=-1), rtol=rtol)
    out = np.empty_like(got, dtype=np.float64)
    assert power_spectrum(x, out=out) is out and np.array_equal(out, got)


@pytest.mark.parametrize("shape", [(116, 3, 2000), (7, 5, 501), (1, 4400)])
def test_power_spectrum_of_many_signals_is_each_signal_s_own_bit_for_bit(shape):
    """The compiled path transforms the signals in blocks (a NAO window's 348 in blocks of 32): each signal's
    spectrum is the one it has alone, which is what the evaluation computes cell by cell."""
    n = spectral_length(shape[-1])
    x = np.random.default_rng(11).integers(-512, 512, shape).astype(np.int32)
    got = power_spectrum(x)
    rows = x.reshape(-1, shape[-1])
    want = np.stack([power_spectrum(r[None])[0] for r in rows]).reshape(got.shape)
    assert np.array_equal(got, want)
    np.testing.assert_allclose(got.sum(-1), x[..., shape[-1] - n:].astype(np.float64).var(axis=-1), rtol=1e-12)


def test_band_powers_equal_scipy_periodogram_sums():
    rng = np.random.default_rng(1)
    x = rng.normal(0, 1, (3, 200)) + 5
    got = band_powers(x, 100.0, ((0.0, 2.0), (2.0, 10.0), (10.0, 50.0)))
    f, p = signal.periodogram(x, fs=100.0)  # boxcar, mean removed, one-sided density
    df = f[1] - f[0]
    want = np.stack([p[:, (f >= 0) & (f < 2)].sum(-1), p[:, (f >= 2) & (f < 10)].sum(-1), p[:, f >= 10].sum(-1)], -1)
    np.testing.assert_allclose(got, np.log1p(want * df), rtol=1e-12)
    # bands covering the spectrum add up to the variance (Parseval)
    np.testing.assert_allclose(np.expm1(got).sum(-1), x.var(axis=-1), rtol=1e-12)


def test_bands_clip_to_each_rate():
    assert vibration_bands(2200.0)[-1] == (800.0, 1050.0)
    assert vibration_bands(1000.0) == ((20.0, 50.0), (50.0, 100.0), (100.0, 200.0), (200.0, 400.0), (400.0, 490.0))
    assert deformation_bands(100.0) == ((0.0, 2.0), (2.0, 10.0), (10.0, 50.0))
    assert deformation_bands(250.0)[-1] == (50.0, 125.0)


# ------------------------------------------------------------------ levels, labels
def test_levels_known_answer_with_tare_and_missing_samples():
    ct = load_robot("nao").cell_types["skin_cell"]
    dfm = np.array([[[10, 20, 30, 40], [0, 0, 0, 4], [5, 5, 5, 5]]])
    extra = np.array([[[1.0, np.nan, 3.0, np.nan], [np.nan] * 4]])
    got = level_values(ct, "levels", dfm, np.array([[5.0, 1.0, 0.0]]), extra)
    np.testing.assert_array_equal(got[0, :4], [20.0, 0.0, 5.0, 2.0])
    assert np.isnan(got[0, 4])  # no temperature sample at all
    sub = level_values(ct, "levels:proximity,f1", dfm, np.zeros((1, 3)), extra)
    np.testing.assert_array_equal(sub, [[2.0, 25.0]])


@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.uint16, np.int32, np.uint32, np.int64, np.float64])
def test_levels_of_counts_are_the_float_means_bit_for_bit(dtype):
    """Counts are averaged from their exact integer sum: the same bits as numpy's mean of the float copy."""
    ct = load_robot("nao").cell_types["skin_cell"]
    rng = np.random.default_rng(3)
    hi = np.iinfo(dtype).max if np.dtype(dtype).kind in "iu" else 1e6
    dfm = rng.integers(0, min(hi, 2**31 - 1), (9, 3, 777), endpoint=True).astype(dtype)
    got = level_values(ct, "levels", dfm, np.zeros((9, 3)), np.zeros((9, 2, 777)))
    np.testing.assert_array_equal(got[:, :3], dfm.astype(np.float64).mean(axis=-1))


def test_labels_carry_the_group_and_name_it():
    ct = load_robot("shadow_hand").cell_types["biotac"]
    assert len(group_labels(ct, "paper")) == 8 and len(group_labels(ct, "per_channel")) == 98
    assert len(group_labels(ct, "bands")) == 18 and len(group_labels(ct, "levels")) == 22
    assert group_labels(ct, "levels")[-3:] == ("level_pdc", "level_tdc", "level_tac")
    assert len(group_labels(ct, "statistics")) == 3 * 20 + 6 + 19 * 3
    labels = selection_labels(ct, ("per_channel", "bands", "levels", "statistics"))
    assert len(labels) == 261 and labels[0] == "per_channel/A_pac" and labels[98] == "bands/A_pac_20-50Hz"
    assert groups_in_labels(["thumb/" + lab for lab in labels]) == ("per_channel", "bands", "levels", "statistics")
    assert groups_in_labels(["thumb/A_pac"]) == ("?",)
    skin = load_robot("nao").cell_types["skin_cell"]
    assert group_labels(skin, "levels") == ("level_f1", "level_f2", "level_f3", "level_proximity", "level_temperature")
    assert group_labels(skin, "bands")[:2] == ("A_ax_20-50Hz", "A_ax_50-100Hz")


# ------------------------------------------------------------------ selections
def test_check_groups_names_group_and_cell_type():
    biotac = load_robot("shadow_hand").cell_types["biotac"]
    with pytest.raises(ConfigError, match=r"'levels:temperature'.*'biotac'"):
        check_groups(biotac, ("paper", "levels:temperature"))
    with pytest.raises(ConfigError, match="unknown feature group 'texture'"):
        check_groups(biotac, ("texture",))
    with pytest.raises(ConfigError, match="twice"):
        check_groups(biotac, ("bands", "bands"))
    with pytest.raises(ConfigError, match="takes no channel list"):
        parse_group("bands:pac")
    assert check_groups(biotac, tuple(GROUPS)) == tuple(GROUPS)


def _nao_yaml():
    with open(robot_config_path("nao"), encoding="utf-8") as fh:
        return yaml.safe_load(fh)


def test_robot_yaml_groups_validated_at_load():
    data = _nao_yaml()
    data["descriptor"] = {"layout": "concat", "groups": ["paper", "bands", "levels:f1,f2,f3,temperature"]}
    robot = parse_robot(copy.deepcopy(data), source="nao_test.yaml")
    assert robot.descriptor.groups == ("paper", "bands", "levels:f1,f2,f3,temperature")
    data["cell_types"]["skin_cell"]["extra_channels"] = ["proximity"]  # this skin has no temperature sensor
    with pytest.raises(ConfigError, match=r"nao_test.yaml.*descriptor.groups.*'levels:f1,f2,f3,temperature'.*"
                                          r"'skin_cell'.*'temperature'"):
        parse_robot(copy.deepcopy(data), source="nao_test.yaml")
    data["descriptor"] = {"groups": ["paper", "wavelets"]}
    with pytest.raises(ConfigError, match="wavelets"):
        parse_robot(copy.deepcopy(data), source="nao_test.yaml")
    data["descriptor"] = {"groups": ["paper"], "channels": "averaged"}
    with pytest.raises(ConfigError, match="not both"):
        parse_robot(copy.deepcopy(data), source="nao_test.yaml")


def test_legacy_channels_is_an_alias_of_groups():
    data = _nao_yaml()
    for channels, groups in (("averaged", ("paper",)), ("per_channel", ("per_channel",))):
        data["descriptor"] = {"channels": channels}
        assert parse_robot(copy.deepcopy(data)).descriptor.groups == groups
    data["descriptor"] = {"channels": "everything"}
    with pytest.raises(ConfigError, match="channels"):
        parse_robot(copy.deepcopy(data))


def test_extra_channel_declared_twice_is_refused():
    data = _nao_yaml()
    data["cell_types"]["skin_cell"]["extra_channels"] = ["proximity", "f1"]
    with pytest.raises(ConfigError, match="extra_channels.*'f1' is already declared"):
        parse_robot(data)


# ------------------------------------------------------------------ describe_window
def test_selection_is_the_concatenation_of_its_groups():
    robot = load_robot("shadow_hand")
    rng = np.random.default_rng(3)
    cells = {0: _biotac_cell(rng), 2: _biotac_cell(rng), 3: _biotac_cell(rng, force=0.0)}
    sel = ("per_channel", "bands", "levels", "statistics")
    whole = describe_window(robot, cells, groups=sel)
    parts = [describe_window(robot, cells, groups=(g,)) for g in sel]
    for p, bp in enumerate(whole.body_parts):
        np.testing.assert_array_equal(bp.values, np.concatenate([d.body_parts[p].values for d in parts]))
        assert bp.labels == selection_labels(robot.cell_types["biotac"], sel)
    assert whole.channels == "per_channel+bands+levels+statistics"
    assert whole.labels[0] == "thumb/per_channel/A_pac"
    assert not whole.body_parts[3].contact and not whole.body_parts[3].values.any()
    # paper alone is the kernel's eq. 17 descriptor, exactly
    np.testing.assert_array_equal(describe_window(robot, cells, groups=("paper",)).values,
                                  describe_window(robot, cells, channels="averaged").values)


def test_body_part_groups_are_means_over_cells_in_contact():
    robot = load_robot("nao")
    rng = np.random.default_rng(4)
    hand = robot.body_part("left_hand")
    cells = {hand.cells[0].id: _skin_cell(rng), hand.cells[1].id: _skin_cell(rng),
             hand.cells[2].id: _skin_cell(rng, force=0.05)}
    d = describe_window(robot, cells, groups=("bands", "levels"))
    bp = d.body_parts[0]
    touching = [cells[hand.cells[k].id] for k in (0, 1)]
    ct = robot.cell_types["skin_cell"]
    want_b = np.mean([band_hjorth(c.vibration[None], 1000.0)[0] for c in touching], axis=0)
    want_l = np.mean([level_values(ct, "levels", c.deformation[None], np.zeros((1, 3)), c.extra[None])[0]
                      for c in touching], axis=0)
    np.testing.assert_allclose(bp.values, np.concatenate([want_b, want_l]), rtol=1e-12)
    assert bp.cells_in_contact == 2 and not bp.quality & Quality.INVALID


def test_missing_extra_channel_is_zero_and_flagged_never_silent():
    robot = load_robot("nao")
    rng = np.random.default_rng(5)
    cid = robot.body_part("chest").cells[0].id
    d = describe_window(robot, {cid: _skin_cell(rng, temp=np.nan)}, groups=("levels",))
    chest = d.body_parts[-1]
    assert chest.values[-1] == 0.0 and chest.quality & Quality.INVALID
    ok = describe_window(robot, {cid: _skin_cell(rng)}, groups=("levels",)).body_parts[-1]
    assert ok.values[-1] == pytest.approx(31.5) and not ok.quality & Quality.INVALID
    bad = _skin_cell(rng)
    bad.extra = bad.extra[:1]
    with pytest.raises(SignalError, match="extra channels"):
        describe_window(robot, {cid: bad}, groups=("levels",))


def test_describe_window_refuses_a_group_the_cell_type_cannot_feed():
    robot = load_robot("shadow_hand")
    with pytest.raises(ConfigError, match="'biotac'"):
        describe_window(robot, {0: _biotac_cell(np.random.default_rng(6))}, groups=("levels:proximity",))


def test_plain_group_is_mean_sd_min_max_of_every_channel_and_a_lost_extra_sample_is_skipped():
    from tactile_descriptors_ros.core.features import plain_values
    from tactile_descriptors_ros.core.groups import group_labels
    from tactile_descriptors_ros.core.robot import load_robot

    ct = load_robot("shadow_hand").cell_types["biotac"]
    rng = np.random.default_rng(1)
    s, v = rng.integers(0, 4096, (2, 1, 220)), rng.integers(0, 4096, (2, 19, 10))
    e = rng.normal(size=(2, 3, 10))
    e[1, 2, 4] = np.nan
    e[1, 0, :] = np.nan  # no sample at all: NaN, flagged by the caller
    out = plain_values(s, v, e)
    labels = group_labels(ct, "plain")
    assert out.shape == (2, len(labels)) == (2, 4 * 23)
    for q, f in (("avg", np.nanmean), ("std", np.nanstd), ("min", np.nanmin), ("max", np.nanmax)):
        assert out[0, labels.index(f"{q}_pac")] == f(s[0, 0])
        assert out[0, labels.index(f"{q}_e7")] == f(v[0, 6])
        assert out[1, labels.index(f"{q}_tac")] == pytest.approx(f(e[1, 2]), rel=1e-12)
        assert np.isnan(out[1, labels.index(f"{q}_pdc")])
