"""Texture models: AR fitting, rescaling, theoretical PSD, model files, parametric materials."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import signal

from tactile_descriptors_ros.errors import DataFormatError, SceneError
from tactile_descriptors_ros.sim import textures as tx


def _ar_sample(a, n, seed=0):
    rng = np.random.default_rng(seed)
    return tx.render_ar(np.array(a), 1.0, n, rng)[0]


def test_yule_walker_recovers_a_known_ar2():
    a_true = np.array([1.2, -0.5])
    x = _ar_sample(a_true, 200_000)
    a, s2 = tx.yule_walker(tx.autocovariance(x, 2))
    assert np.allclose(a, a_true, atol=0.01)
    assert s2 == pytest.approx(1.0, rel=0.02)


def test_process_variance_matches_closed_form_and_sample():
    assert tx.ar_process_variance(np.array([0.5]), 1.0) == pytest.approx(1 / 0.75)
    a = np.array([1.2, -0.5])
    x = _ar_sample(a, 400_000, seed=3)
    assert x.var() == pytest.approx(tx.ar_process_variance(a, 1.0), rel=0.03)


def test_rescale_keeps_variance_and_moves_the_resonance():
    fs = 2200.0
    a = tx._ar_from_resonances(fs, [100.0], [10.0], 0.9)
    a2, s2 = tx.rescale_ar(a, 1.0, 2.0)  # twice the speed: resonance at 200 Hz
    assert tx.ar_process_variance(a2, s2) == pytest.approx(tx.ar_process_variance(a, 1.0), rel=1e-9)
    f = np.linspace(1, 1000, 4000)
    peak = f[np.argmax(tx.ar_psd(a2, s2, fs, f) * (f > 50))]
    assert peak == pytest.approx(200.0, abs=3.0)
    a1, s1 = tx.rescale_ar(a, 1.0, 1.0)
    assert np.array_equal(a1, a) and s1 == 1.0


def test_rescale_drops_poles_beyond_nyquist():
    a = tx._ar_from_resonances(2200.0, [600.0], [30.0], 0.9)
    a2, _ = tx.rescale_ar(a, 1.0, 2.0)  # 1200 Hz > 1100 Hz Nyquist
    assert a2.size == 1


def test_rescale_rejects_bad_scale():
    with pytest.raises(SceneError):
        tx.rescale_ar(np.array([0.5]), 1.0, 0.0)


@pytest.mark.parametrize("name", ["cork", "steel", "soft_sponge"])
def test_rendered_pac_spectrum_matches_the_fitted_model(name):
    """Welch PSD of rendered PAC vs the AR model's theoretical PSD, 20-1000 Hz."""
    m = tx.get_material(name)
    a, s2 = np.array(m.vibration.ar), m.vibration.sigma2
    fs = m.vibration.fs_hz
    x = tx.render_ar(a, s2, 2200 * 200, np.random.default_rng(1))[0]
    f, p = signal.welch(x, fs=fs, nperseg=1024)
    band = (f >= 20) & (f <= 1000)
    ratio = p[band] / tx.ar_psd(a, s2, fs, f[band])
    assert np.median(np.abs(np.log(ratio))) < 0.08
    assert np.max(np.abs(np.log(ratio))) < 0.5


def test_speed_rescaled_spectrum_matches_theory():
    m = tx.get_material("cork")
    a, s2 = m.vibration.at(2200.0, 0.04, m.reference_speed_m_s)
    x = tx.render_ar(a, s2, 2200 * 100, np.random.default_rng(2))[0]
    f, p = signal.welch(x, fs=2200.0, nperseg=1024)
    band = (f >= 20) & (f <= 1000)
    ratio = p[band] / tx.ar_psd(a, s2, 2200.0, f[band])
    assert np.median(np.abs(np.log(ratio))) < 0.1


def test_every_shipped_model_loads_and_is_small():
    lib = tx.material_library()
    assert len(lib) == 20
    for path in tx.models_dir().glob("*.json"):
        assert path.stat().st_size < 8000
    m = lib["steel"]
    assert m.deformation.n_electrodes == 19
    assert m.vibration.fs_hz == 2200.0 and len(m.vibration.ar) == 12


def test_model_json_round_trip(tmp_path):
    m = tx.get_material("felt")
    tx.save_material(m, tmp_path / "felt.json")
    assert tx.load_material(tmp_path / "felt.json") == m


def test_bad_model_file_is_a_clear_error(tmp_path):
    (tmp_path / "x.json").write_text(json.dumps({"format": "something else"}))
    with pytest.raises(DataFormatError, match="not a texture model"):
        tx.load_material(tmp_path / "x.json")
    data = tx.get_material("felt").to_json()
    del data["vibration"]["ar"]
    (tmp_path / "y.json").write_text(json.dumps(data))
    with pytest.raises(DataFormatError, match="ar"):
        tx.load_material(tmp_path / "y.json")


def test_parametric_materials_are_deterministic_and_distinct():
    a = tx.parametric_material("param:box_1", 5)
    assert a == tx.parametric_material("param:box_1", 5)
    assert a != tx.parametric_material("param:box_2", 5)
    assert a != tx.parametric_material("param:box_1", 6)
    assert 40 ** 2 < a.vibration.variance < 260 ** 2


def test_unknown_material_names_the_known_ones():
    with pytest.raises(SceneError, match="cork"):
        tx.get_material("unobtainium")


def test_slow_parametric_textures_have_a_finite_variance():
    """Poles near z = 1 defeat the step-down recursion; the impulse-response sum still gives the variance."""
    a = -np.real(np.poly([0.9995, 0.9994 * np.exp(0.01j), 0.9994 * np.exp(-0.01j), 0.985]))[1:]
    var = tx.ar_process_variance(a, 1.0)
    # the same number from a long simulated realisation (sample variance within 10 %)
    x = signal.lfilter([1.0], np.r_[1.0, -a], np.random.default_rng(0).normal(size=2_000_000))[200_000:]
    assert np.isfinite(var) and x.var() == pytest.approx(var, rel=0.1)
    # agrees with the step-down formula where that one is well conditioned
    b = np.array([1.5, -0.56])
    k = tx._reflection_coefficients(b)
    assert tx.ar_process_variance(b, 2.0) == pytest.approx(2.0 / np.prod(1 - k * k), rel=1e-12)
    c = -np.real(np.poly([0.995, 0.5]))[1:]  # radius above 0.99: impulse-response path
    k = tx._reflection_coefficients(c)
    assert tx.ar_process_variance(c, 1.0) == pytest.approx(1.0 / np.prod(1 - k * k), rel=1e-9)
    with pytest.raises(SceneError):
        tx.ar_process_variance(np.array([1.0]), 1.0)  # a pole on the unit circle


def test_a_parametric_material_is_the_same_texture_in_every_scene():
    from tactile_descriptors_ros.sim.engine import SimContext

    ctx_a = object.__new__(SimContext)
    ctx_b = object.__new__(SimContext)
    for ctx, seed in ((ctx_a, 5), (ctx_b, 77)):
        ctx._materials = {}
        ctx.scene = type("S", (), {"seed": seed})()
    assert ctx_a.material("param:probe_001") == ctx_b.material("param:probe_001")
