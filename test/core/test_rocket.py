"""The rocket feature group: the compiled transform against the reference, its fit, its files, the live path.

The comparison with aeon's MiniRocket (the independent reference) is in
the lab's tests (lab/test/evaluation/test_rocket_reference.py).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_descriptors_ros.core import fast, rocket
from tactile_descriptors_ros.errors import ConfigError, SignalError


@settings(max_examples=25, deadline=None)
@given(n_ch=st.integers(1, 4), n_t=st.integers(9, 60), seed=st.integers(0, 2**16))
def test_compiled_transform_counts_equal_the_reference(n_ch, n_t, seed):
    rng = np.random.default_rng(seed)
    x = rng.integers(-50, 50, size=(2, n_ch, n_t))
    p = rocket.fit(x, 168, seed=seed)
    ref = np.empty((2, p.n_features))
    rocket._transform_numpy(x.astype(np.float64), p, ref)
    assert fast.backend() == "numba"
    np.testing.assert_array_equal(rocket.transform(x, p), ref)


def test_convolve_by_hand():
    x = np.arange(12, dtype=float)[None, :]
    # kernel 0 has weight 2 at taps 0, 1, 2: C_t = sum_k w_k x[t + (k - 4) d], zeros past the ends
    c = rocket.convolve(x, 1, 0, np.array([0]))
    t = 6
    expected = 2 * (x[0, 2] + x[0, 3] + x[0, 4]) - (x[0, 5] + x[0, 6] + x[0, 7] + x[0, 8] + x[0, 9] + x[0, 10])
    assert c[t] == expected
    assert c[0] == -(x[0, 1] + x[0, 2] + x[0, 3] + x[0, 4])  # taps before the start read zeros


def test_fit_biases_are_quantiles_of_a_training_examples_convolution():
    rng = np.random.default_rng(3)
    x = rng.integers(0, 1000, size=(5, 2, 64))
    p = rocket.fit(x, 168, seed=11)
    q = rocket.quantiles(p.n_features)
    f = c0 = comb = 0
    for j, dil in enumerate(p.dilations):
        for k in range(rocket.N_KERNELS):
            m = int(p.features_per_dilation[j])
            chans = p.channel_indices[c0:c0 + p.channels_per_combination[comb]]
            outs = [rocket.convolve(x[i], int(dil), k, chans).astype(np.float32) for i in range(5)]
            want = p.biases[f:f + m]
            assert any(np.array_equal(np.quantile(o, q[f:f + m]).astype(np.float32), want) for o in outs)
            f += m
            c0 += int(p.channels_per_combination[comb])
            comb += 1
    assert np.all(p.channels_per_combination >= 1) and np.all(p.channels_per_combination <= 2)


def test_bad_input_is_refused():
    p = rocket.fit(np.zeros((2, 3, 50)), 84)
    with pytest.raises(SignalError, match=r"shape \(n, 3, n_samples\)"):
        rocket.transform(np.zeros((1, 2, 50)), p)
    with pytest.raises(SignalError, match="shorter than"):
        rocket.transform(np.zeros((1, 3, p.min_samples - 1)), p)
    x = np.ones((2, 3, 50))
    x[1, 0, 7] = np.nan
    out = rocket.transform(x, p)
    assert np.isfinite(out[0]).all() and np.isnan(out[1]).all()  # a missing sample never becomes a count
    with pytest.raises(ConfigError, match="at least 84 features"):
        rocket.fit(np.zeros((2, 1, 50)), 40)


def test_parameters_file_round_trip_and_corrupt_files(tmp_path):
    p = rocket.fit(np.random.default_rng(0).integers(0, 99, (3, 2, 40)), 168)
    path = tmp_path / "biotac.json"
    rocket.save_parameters(path, {"vibration": p, "slow": p}, description="test")
    back = rocket.load_parameters(path)
    assert back["slow"].state() == p.state()
    np.testing.assert_array_equal(back["vibration"].biases, p.biases)  # exact: shortest round-trip repr
    state = json.loads(path.read_text())
    state["signals"]["slow"]["biases"] = state["signals"]["slow"]["biases"][:-1]
    (tmp_path / "short.json").write_text(json.dumps(state))
    with pytest.raises(ConfigError, match=r"short.json: signals.slow: .*167 biases, expected 168"):
        rocket.load_parameters(tmp_path / "short.json")
    (tmp_path / "other.json").write_text("{}")
    with pytest.raises(ConfigError, match="other.json: not a rocket parameters file"):
        rocket.load_parameters(tmp_path / "other.json")
    with pytest.raises(ConfigError, match="missing.json: cannot read"):
        rocket.load_parameters(tmp_path / "missing.json")


def test_shipped_biotac_transforms_fit_the_biotac():
    from tactile_descriptors_ros.core.groups import group_labels, rocket_parameters
    from tactile_descriptors_ros.core.robot import load_robot

    ct = load_robot("shadow_hand").cell_types["biotac"]
    params = rocket_parameters(ct)
    assert params["vibration"].n_channels == 1 and params["slow"].n_channels == 22
    assert params["vibration"].dilations.max() <= 12  # the vibration's small dilations (docs/evaluation.md)
    labels = group_labels(ct, "rocket")
    assert len(labels) == params["vibration"].n_features + params["slow"].n_features
    assert labels[0] == "ppv_vibration_0000" and labels[-1].startswith("ppv_slow_")


def test_group_on_the_live_path_equals_the_transform_and_flags_a_missing_extra_value():
    import dataclasses

    from tactile_descriptors_ros.core.aggregation import CellSignals, describe_window
    from tactile_descriptors_ros.core.descriptors import Quality
    from tactile_descriptors_ros.core.groups import rocket_parameters
    from tactile_descriptors_ros.core.robot import load_robot

    hand = load_robot("shadow_hand")
    robot = dataclasses.replace(hand, body_parts=hand.body_parts[:1])  # the thumb's BioTac, id 0
    ct = robot.cell_types["biotac"]
    rng = np.random.default_rng(5)
    n = 100
    pac = rng.integers(1500, 2500, size=(1, 22 * n))
    e = rng.integers(2000, 3000, size=(19, n))
    extra = rng.integers(0, 500, size=(3, n)).astype(float)
    t_slow = np.arange(n, dtype=np.int64) * 10_000_000
    t_fast = np.arange(22 * n, dtype=np.int64) * (10_000_000 // 22)
    tare = rng.integers(1900, 2100, size=19).astype(float)
    sig = CellSignals(pac, t_fast, e, t_slow, np.full(n, 1.0), extra=extra, deformation_tare=tare)
    d = describe_window(robot, {0: sig}, groups=("rocket",))
    params = rocket_parameters(ct)
    slow = np.concatenate([e - tare[:, None], extra])[None]
    expected = np.concatenate([rocket.transform(pac[None], params["vibration"])[0],
                               rocket.transform(slow, params["slow"])[0]])
    np.testing.assert_array_equal(d.values, expected)
    extra[1, 10] = np.nan  # a lost temperature sample: the cell's slow series is not whole
    bad = describe_window(robot, {0: CellSignals(pac, t_fast, e, t_slow, np.full(n, 1.0), extra=extra,
                                                 deformation_tare=tare)}, groups=("rocket",))
    assert bad.body_parts[0].quality & int(Quality.INVALID)
    assert np.isfinite(bad.values).all()


def test_a_cell_type_without_fitted_transforms_cannot_feed_the_group():
    from tactile_descriptors_ros.core.groups import check_groups, feedable_groups
    from tactile_descriptors_ros.core.robot import load_robot

    ct = next(iter(load_robot("nao").cell_types.values()))
    with pytest.raises(ConfigError, match=r"'rocket' cannot be fed by cell type .*no fitted transform .*fit-rocket"):
        check_groups(ct, ("rocket",))
    assert "rocket" not in feedable_groups(ct, ct.channels) and "plain" in feedable_groups(ct, ct.channels)


def test_labels_follow_a_transform_file_written_again_in_the_same_process(tmp_path, monkeypatch):
    """The labels' caches key on the fitted sizes: a config directory whose ``rocket/biotac.json`` is written
    again with other sizes (``tactile fit-rocket`` in a running evaluation) gives labels of the new size,
    and the describe on the live path agrees with them."""
    import shutil

    from tactile_descriptors_ros.core.groups import group_labels, rocket_parameters, selection_labels
    from tactile_descriptors_ros.core.robot import load_robot
    from tactile_descriptors_ros.core.yamlreader import config_dir

    ct = load_robot("shadow_hand").cell_types["biotac"]
    shipped = len(group_labels(ct, "rocket"))
    cfg = tmp_path / "config"
    shutil.copytree(config_dir(), cfg)
    monkeypatch.setenv("TACTILE_CONFIG_DIR", str(cfg))
    assert len(selection_labels(ct, ("plain", "rocket"))) == len(group_labels(ct, "plain")) + shipped
    rng = np.random.default_rng(0)
    small = {"vibration": rocket.fit(rng.integers(-50, 50, size=(4, 1, 97)), 84, seed=1),
             "slow": rocket.fit(rng.integers(-50, 50, size=(4, 22, 100)), 168, seed=2)}
    rocket.save_parameters(cfg / "rocket" / "biotac.json", small)
    assert rocket_parameters(ct)["slow"].n_features == 168
    assert len(group_labels(ct, "rocket")) == 84 + 168
    assert len(selection_labels(ct, ("plain", "rocket"))) == len(group_labels(ct, "plain")) + 84 + 168
    monkeypatch.delenv("TACTILE_CONFIG_DIR")
    assert len(group_labels(ct, "rocket")) == shipped  # the shipped file again, from the cache
