"""Online PA-I (eq. 30-32), feature scaling, atomic model files."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from tactile_descriptors_ros.core.learning import OnlineClassifier, PassiveAggressive
from tactile_descriptors_ros.core.model_store import load_model, save_model
from tactile_descriptors_ros.core.scaling import FeatureScaler, RunningStandardizer, activity_mask
from tactile_descriptors_ros.errors import ModelError, SignalError


def test_pa_first_update_by_hand():
    pa = PassiveAggressive(2)
    pa.add_class("a")
    pa.add_class("b")
    x = np.array([1.0, 2.0])  # with bias: [1, 2, 1], ||x||^2 = 6
    loss = pa.partial_fit(x, "b")  # scores tie at 0: a tie is a mistake
    assert loss == 1.0
    theta = min(1.0, 1.0 / (2 * 6.0))
    np.testing.assert_allclose(pa.weights[1], theta * np.array([1, 2, 1]))
    np.testing.assert_allclose(pa.weights[0], -theta * np.array([1, 2, 1]))
    assert pa.predict(x) == "b"
    assert pa.partial_fit(x, "b") == 0.0  # correct now: passive


def test_pa_step_is_capped_by_eta():
    pa = PassiveAggressive(1, eta=0.01)
    pa.add_class("a")
    pa.partial_fit(np.array([0.1]), "b")
    pa.partial_fit(np.array([0.1]), "a")
    assert np.all(np.abs(pa.weights) <= 0.01 * 1.1 + 1e-12)


def test_pa_learns_separable_classes_online_and_open_ended():
    rng = np.random.default_rng(0)
    centres = rng.normal(size=(5, 8)) * 4
    pa = PassiveAggressive(8)
    for t in range(200):
        k = t % 5 if t < 150 else t % 6  # a sixth class appears at run time
        c = centres[k] if k < 5 else np.full(8, 6.0)
        pa.partial_fit(c + rng.normal(size=8) * 0.3, f"class{k}")
    correct = sum(pa.predict(centres[k] + rng.normal(size=8) * 0.3) == f"class{k}" for k in range(5) for _ in range(20))
    assert correct >= 98 and "class5" in pa.classes


def test_pa_rejects_bad_input():
    pa = PassiveAggressive(3)
    with pytest.raises(SignalError):
        pa.partial_fit(np.ones(4), "a")
    with pytest.raises(SignalError):
        pa.partial_fit(np.array([1.0, np.nan, 0.0]), "a")


def test_max_loss_update_learns_from_a_small_margin_and_prediction_update_does_not():
    x = np.array([1.0, 0.0])  # with bias: [1, 0, 1], ||x||^2 = 2
    models = {u: PassiveAggressive(2, update=u) for u in ("prediction", "max_loss")}
    for pa in models.values():
        pa.add_class("a")
        pa.add_class("b")
        pa.weights[0] = [0.1, 0.0, 0.0]  # "a" wins on x by a margin of 0.1 < 1
    assert models["prediction"].partial_fit(x, "a") == 0.0
    np.testing.assert_allclose(models["prediction"].weights[0], [0.1, 0, 0])
    loss = models["max_loss"].partial_fit(x, "a")
    assert loss == pytest.approx(0.9)
    theta = 0.9 / (2 * 2.0)
    np.testing.assert_allclose(models["max_loss"].weights[0], [0.1 + theta, 0, theta])
    np.testing.assert_allclose(models["max_loss"].weights[1], [-theta, 0, -theta])
    assert models["max_loss"].mistakes == 0  # learning without a mistake
    with pytest.raises(SignalError):
        PassiveAggressive(2, update="max-loss")


@pytest.mark.parametrize("update", ["prediction", "max_loss"])
def test_averaged_weights_are_the_mean_of_every_snapshot(update):
    rng = np.random.default_rng(3)
    pa = PassiveAggressive(4, eta=0.5, update=update, average=True)
    snapshots = []
    for t in range(60):
        k = int(rng.integers(0, 3 if t < 30 else 4))  # a class appears half way
        pa.partial_fit(rng.normal(size=4) + k, f"c{k}")
        w = np.zeros((4, 5))
        w[: len(pa.classes)] = pa.weights
        snapshots.append(w)
    expected = np.mean(snapshots, axis=0)[: len(pa.classes)]
    np.testing.assert_allclose(pa.decision_weights, expected, atol=1e-12)
    x = rng.normal(size=4)
    np.testing.assert_allclose(pa.scores(x), expected @ np.append(x, 1.0), atol=1e-12)
    back = PassiveAggressive.from_state(json.loads(json.dumps(pa.state())))
    assert (back.update, back.average) == (update, True)
    np.testing.assert_allclose(back.decision_weights, pa.decision_weights)


def test_model_state_without_the_new_options_loads_as_the_papers_pa():
    pa = PassiveAggressive(2)
    pa.partial_fit(np.array([1.0, 0.0]), "a")
    pa.partial_fit(np.array([0.0, 1.0]), "b")
    state = pa.state()
    for key in ("update", "average", "weighted_sum"):
        del state[key]
    back = PassiveAggressive.from_state(state)
    assert (back.update, back.average) == ("prediction", False)
    np.testing.assert_allclose(back.weights, pa.weights)


def test_running_standardizer_equals_batch_statistics():
    rng = np.random.default_rng(1)
    x = rng.normal(5, 3, size=(500, 4))
    s = RunningStandardizer(4)
    for row in x:
        s.partial_fit(row)
    np.testing.assert_allclose(s.mean, x.mean(axis=0))
    np.testing.assert_allclose(s.std, x.std(axis=0))
    np.testing.assert_allclose(s.transform(x).std(axis=0), 1.0)


def test_log_activity_only_touches_activity():
    labels = ["index/A_pac", "index/M_pac", "A_E", "L_pac_E"]
    assert activity_mask(labels).tolist() == [True, False, True, False]
    sc = FeatureScaler(labels, standardize=False)
    np.testing.assert_allclose(sc.transform(np.array([np.e - 1, 5.0, 0.0, 0.5])), [1.0, 5.0, 0.0, 0.5])


def test_model_round_trip_and_layout_check(tmp_path):
    labels = ["A_x", "M_x"]
    clf = OnlineClassifier(labels)
    rng = np.random.default_rng(2)
    for _ in range(20):
        v = rng.normal(size=2)
        clf.observe(v)
        clf.learn(v, "pos" if v[0] > 0 else "neg")
    path = tmp_path / "model.json"
    save_model(clf, path)
    back = load_model(path, labels)
    v = rng.normal(size=2)
    assert back.predict(v)[0] == clf.predict(v)[0]
    np.testing.assert_allclose(back.predict(v)[1], clf.predict(v)[1])
    assert back.version == clf.version == 20
    with pytest.raises(ModelError, match="another descriptor layout"):
        load_model(path, ["A_x"])
    path.write_text("{not json")
    with pytest.raises(ModelError):
        load_model(path)


def test_failed_save_keeps_previous_model(tmp_path, monkeypatch):
    clf = OnlineClassifier(["A_x"])
    path = tmp_path / "model.json"
    save_model(clf, path)
    before = path.read_text()
    clf.learn(np.array([1.0]), "a")

    def full_disk(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "fsync", full_disk)
    with pytest.raises(ModelError, match="No space left"):
        save_model(clf, path)
    assert path.read_text() == before and json.loads(before)["version"] == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model.json", "model.json.lock"]  # no temp file left


# ------------------------------------------------------------ corrupt but parseable model files


def _valid_state() -> dict:
    clf = OnlineClassifier(["A_x", "M_x", "C_x"])
    rng = np.random.default_rng(5)
    for i in range(12):
        v = rng.uniform(0.5, 3.0, 3)
        clf.observe(v)
        clf.learn(v, f"c{i % 3}")
    return json.loads(json.dumps(clf.state()))


def _set(state: dict, dotted: str, value) -> dict:
    *head, last = dotted.split(".")
    node = state
    for key in head:
        node = node[key]
    node[last] = value
    return state


@pytest.mark.parametrize("mutate, match", [
    (lambda s: _set(s, "pa.weights", [[float("nan")] * 4] + s["pa"]["weights"][1:]), "pa.weights.*non-finite"),
    (lambda s: _set(s, "pa.weighted_sum", [[float("inf")] * 4] * 3), "pa.weighted_sum.*non-finite"),
    (lambda s: _set(s, "pa.classes", ["c0", "c1", "c0"]), "'c0' more than once"),
    (lambda s: _set(s, "pa.updates", -3), "pa.updates.*at least 0"),
    (lambda s: _set(s, "pa.mistakes", 99), "pa.mistakes.*exceeds"),
    (lambda s: _set(s, "version", -1), "version.*at least 0"),
    (lambda s: _set(s, "scaler.standardizer.n", -2), "standardizer.n.*at least 0"),
    (lambda s: _set(s, "scaler.standardizer.mean", [0.0, 0.0]), r"standardizer.mean.*shape \(2,\), expected \(3,\)"),
    (lambda s: _set(s, "scaler.standardizer.m2", [1.0, -1.0, 1.0]), "negative sums of squares"),
    (lambda s: _set(s, "pa.weights", np.zeros((4, 3)).tolist()), r"pa.weights.*shape \(4, 3\), expected \(3, 4\)"),
    (lambda s: _set(s, "pa.classes", ["c0", 1, "c2"]), "pa.classes"),
    (lambda s: _set(s, "pa.eta", float("nan")), "pa.eta"),
    (lambda s: _set(s, "scaler.log_activity", "yes"), "scaler.log_activity"),
    (lambda s: {}, "not a model of this package"),
    (lambda s: [], "not a model of this package"),
    (lambda s: {k: v for k, v in s.items() if k != "pa"}, "'pa' is missing"),
])
def test_corrupt_but_parseable_model_is_refused_naming_path_and_key(tmp_path, mutate, match):
    path = tmp_path / "model.json"
    path.write_text(json.dumps(mutate(_valid_state())))  # json writes NaN/Infinity: parseable by json.loads
    with pytest.raises(ModelError, match=match) as info:
        load_model(path)
    assert str(path) in str(info.value)


def test_the_valid_state_of_those_cases_loads(tmp_path):
    path = tmp_path / "model.json"
    path.write_text(json.dumps(_valid_state()))
    assert load_model(path).classes == ["c0", "c1", "c2"]


# ------------------------------------------------------------ AROW (second-order, shared covariance)


def _arow_reference(samples, n_features, r_per_feature):
    """AROW written from Crammer, Kulesza & Dredze (2009) with the multiclass max-loss rival, full matrices."""
    d = n_features + 1
    W, S, classes = {}, np.eye(d), []
    for x, y in samples:
        xb = np.append(x, 1.0)
        if y not in W:
            W[y] = np.zeros(d)
            classes.append(y)
        if len(classes) < 2:
            continue
        scores = {c: W[c] @ xb for c in classes}
        rival = max((c for c in classes if c != y), key=lambda c: (scores[c], -classes.index(c)))
        margin = scores[y] - scores[rival]
        if margin >= 1.0:
            continue
        confidence = xb @ S @ xb * 2.0  # x' Sigma_y x + x' Sigma_r x with one shared Sigma
        beta = 1.0 / (confidence + r_per_feature * d)
        alpha = (1.0 - margin) * beta
        W[y] = W[y] + alpha * S @ xb
        W[rival] = W[rival] - alpha * S @ xb
        S = S - beta * np.outer(S @ xb, xb @ S)
    return np.array([W[c] for c in classes]), S, classes


def test_arow_equals_the_algorithm_written_from_its_paper():
    rng = np.random.default_rng(4)
    samples = [(rng.normal(size=5) + k, f"c{k}") for k in rng.integers(0, 4, 80)]
    pa = PassiveAggressive(5, update="arow", r_per_feature=0.3)
    for x, y in samples:
        pa.partial_fit(x, y)
    W, S, classes = _arow_reference(samples, 5, 0.3)
    assert pa.classes == classes
    np.testing.assert_allclose(pa.weights, W, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(pa.covariance, S, rtol=1e-10, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(pa.covariance) > 0)  # stays a covariance


def test_arow_first_update_by_hand():
    pa = PassiveAggressive(2, update="arow", r_per_feature=1.0)
    pa.add_class("a")
    x = np.array([1.0, 2.0])  # with bias [1, 2, 1]: x'x = 6, Sigma = I
    assert pa.partial_fit(x, "b") == 1.0  # scores tie at 0: margin 0, loss 1
    beta = 1.0 / (2 * 6.0 + 3.0)  # R = 1 x 3 features with the bias
    np.testing.assert_allclose(pa.weights[1], beta * np.array([1, 2, 1]))
    np.testing.assert_allclose(pa.weights[0], -beta * np.array([1, 2, 1]))
    xb = np.array([1.0, 2.0, 1.0])
    np.testing.assert_allclose(pa.covariance, np.eye(3) - beta * np.outer(xb, xb))
    assert pa.predict(x) == "b"


def test_arow_makes_its_covariance_at_the_first_update_not_for_predicting(tmp_path):
    """A new AROW model predicts without its n x n covariance (a NAO descriptor's is 918 x 918, 5 ms to make);
    the first update makes it, as the identity it starts from, and a saved model holds it either way."""
    pa = PassiveAggressive(2, update="arow", r_per_feature=1.0)
    pa.add_class("a")
    assert pa.predict(np.array([1.0, 2.0])) == "a" and pa._covariance is None
    pa.partial_fit(np.array([1.0, 2.0]), "b")
    assert pa._covariance is not None and pa.covariance.shape == (3, 3)
    fresh = OnlineClassifier(["x/1", "x/2"], update="arow")
    fresh.observe(np.array([1.0, 2.0]))
    fresh.predict(np.array([1.0, 2.0]))
    assert fresh.pa._covariance is None
    save_model(fresh, tmp_path / "m.json")
    np.testing.assert_array_equal(load_model(tmp_path / "m.json").pa.covariance, np.eye(3))
    assert PassiveAggressive(2, update="max_loss").covariance is None


def test_arow_is_open_ended_and_learns_separable_classes():
    rng = np.random.default_rng(0)
    centres = rng.normal(size=(6, 8)) * 4
    pa = PassiveAggressive(8, update="arow")
    for t in range(240):
        k = t % 5 if t < 150 else t % 6  # a sixth class appears at run time
        pa.partial_fit(centres[k] + rng.normal(size=8) * 0.3, f"class{k}")
    correct = sum(pa.predict(centres[k] + rng.normal(size=8) * 0.3) == f"class{k}" for k in range(6) for _ in range(20))
    assert correct >= 118 and pa.classes[-1] == "class5"


def test_arow_model_round_trip_and_version_1_files_still_load(tmp_path):
    rng = np.random.default_rng(2)
    clf = OnlineClassifier(["A_x", "M_x", "C_x"], update="arow", average=True, r_per_feature=0.7)
    for i in range(20):
        v = rng.uniform(0.5, 3.0, 3)
        clf.observe(v)
        clf.learn(v, f"c{i % 4}")
    path = tmp_path / "model.json"
    save_model(clf, path)
    back = load_model(path)
    assert (back.pa.update, back.pa.r_per_feature) == ("arow", 0.7)
    np.testing.assert_array_equal(back.pa.covariance, clf.pa.covariance)  # exact: float64 bytes
    assert json.dumps(back.state()) == json.dumps(clf.state())
    v1 = OnlineClassifier(["A_x"], update="max_loss")
    v1.learn(np.array([1.0]), "a")
    old = v1.state() | {"format_version": 1}  # a PA-I file of the previous format
    (tmp_path / "old.json").write_text(json.dumps(old))
    assert load_model(tmp_path / "old.json").classes == ["a"]
    (tmp_path / "future.json").write_text(json.dumps(old | {"format_version": 3}))
    with pytest.raises(ModelError, match="v3, expected .* v1 or v2"):
        load_model(tmp_path / "future.json")


def _arow_state() -> dict:
    clf = OnlineClassifier(["A_x", "M_x"], update="arow")
    for i, v in enumerate(([1.0, 2.0], [2.0, 0.5], [0.3, 1.0])):
        clf.observe(np.array(v))
        clf.learn(np.array(v), f"c{i}")
    return json.loads(json.dumps(clf.state()))


@pytest.mark.parametrize("mutate, match", [
    (lambda s: s["pa"].pop("covariance"), "pa.covariance' is missing"),
    (lambda s: s["pa"]["covariance"].update(shape=[2, 2]), r"pa.covariance.*shape \[2, 2\], expected \[3, 3\]"),
    (lambda s: s["pa"]["covariance"].update(float64_le_base64="AAAA"), "holds 3 bytes, expected 72"),
    (lambda s: s["pa"]["covariance"].update(float64_le_base64="not base64!"), "not valid base64"),
    (lambda s: s["pa"]["covariance"].update(
        float64_le_base64=__import__("base64").b64encode(np.full(9, np.nan).tobytes()).decode()), "9 non-finite"),
    (lambda s: s["pa"].update(r_per_feature=0.0), "r_per_feature' must be positive"),
    (lambda s: s["pa"].update(update="max_loss"), "covariance' given for the 'max_loss' update"),
])
def test_corrupt_arow_state_is_refused_naming_the_key(tmp_path, mutate, match):
    state = _arow_state()
    mutate(state)
    path = tmp_path / "model.json"
    path.write_text(json.dumps(state))
    with pytest.raises(ModelError, match=match):
        load_model(path)


def _learn_some(clf: OnlineClassifier, store, n: int, rng, classes: int = 5) -> None:
    for i in range(n):
        v = rng.uniform(0.5, 3.0, len(clf.labels))
        clf.observe(v)
        clf.learn(v, f"c{i % classes}")
        store.record(clf)


def test_arow_journal_replays_to_the_same_bits(tmp_path):
    from tactile_descriptors_ros.core.model_store import ModelStore, journal_path

    path = tmp_path / "model.json"
    clf = OnlineClassifier(["A_x", "M_x", "C_x"], update="arow", average=True)
    store = ModelStore(path)
    _learn_some(clf, store, 40, np.random.default_rng(7), classes=6)
    assert journal_path(path).exists() and store.compactions == 0
    back = load_model(path)
    np.testing.assert_array_equal(back.pa.covariance, clf.pa.covariance)
    assert json.dumps(back.state()) == json.dumps(clf.state())
