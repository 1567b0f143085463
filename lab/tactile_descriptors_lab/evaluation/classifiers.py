"""The paper's three learners on descriptor matrices (Kaboli et al. 2018, section VI).

* Batch: linear SVM (scikit-learn ``SVC(kernel="linear")``, libsvm one-vs-one), C chosen by 5-fold
  cross-validation repeated :data:`CV_REPEATS` times over :data:`C_GRID`, then refit on all
  training data; features scaled by a pipeline fitted on the training data.
  When a training trial contributes several windows, the folds keep a
  trial's windows together (``StratifiedGroupKFold`` reshuffled per repeat)
  so that validation never sees a window of a trial it trained on; with one
  window per trial this is ``RepeatedStratifiedKFold``.
* Online: the core's PA-I (eq. 30-32) behind :class:`~..core.learning.OnlineClassifier`
  (log-Activity + running standardisation): the learning curve of test
  accuracy after 1..N training trials per class.
* Unsupervised: EM for a spherical Gaussian mixture with k = number of
  classes, initialised by k-means with 20 restarts, 100 EM iterations, scored
  by NMI with the arithmetic-mean normalisation (eq. 34).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment
from sklearn.base import clone
from sklearn.cluster import KMeans
from sklearn.exceptions import ConvergenceWarning
from sklearn.metrics import confusion_matrix, normalized_mutual_info_score
from sklearn.mixture import GaussianMixture
from sklearn.model_selection import RepeatedStratifiedKFold, StratifiedGroupKFold, cross_val_score
from sklearn.pipeline import Pipeline, make_pipeline
from sklearn.preprocessing import FunctionTransformer, StandardScaler
from sklearn.svm import SVC

from tactile_descriptors_lab.evaluation.modes import CV_REPEATS, SCALINGS
from tactile_descriptors_ros.core.learning import OnlineClassifier
from tactile_descriptors_ros.core.scaling import activity_mask, log_activity
from tactile_descriptors_ros.errors import ConfigError

__all__ = [
    "C_GRID",
    "C_GRID_TEXT",
    "SVC_MAX_ITER",
    "SCALINGS",
    "make_scaler",
    "cv_splits",
    "CV_REPEATS",
    "estimate_selection_s",
    "SvmResult",
    "fit_svm",
    "PaCurve",
    "pa_curve",
    "GmmResult",
    "gmm_nmi",
]

#: The paper's C grid: 1e-4, 5^-4, 3^-4, 2^-4 ... 2^4 (integer powers), 3^4, 5^4, 1e4 (15 values).
C_GRID: tuple[float, ...] = tuple(
    [1e-4, 5.0 ** -4, 3.0 ** -4] + [2.0 ** k for k in range(-4, 5)] + [3.0 ** 4, 5.0 ** 4, 1e4])
C_GRID_TEXT = "{1e-4, 5^-4, 3^-4, 2^-4, 2^-3, 2^-2, 2^-1, 1, 2, 4, 8, 16, 3^4, 5^4, 1e4}"


#: Iteration cap of libsvm per binary problem (reached only without feature scaling at large C).
SVC_MAX_ITER: int = 10_000


def make_scaler(scaling: str, labels: Sequence[str]) -> Pipeline | None:
    """A scikit-learn transformer for a scaling name (None for ``none``).

    ``log_standardize`` uses the core's :func:`~..core.scaling.log_activity`
    on the Activity columns (labels whose quantity is ``A``), then
    ``StandardScaler``.
    """
    if scaling == "none":
        return None
    if scaling == "standardize":
        return make_pipeline(StandardScaler())
    if scaling == "log_standardize":
        mask = activity_mask(labels)
        return make_pipeline(FunctionTransformer(log_activity, kw_args={"mask": mask}), StandardScaler())
    raise ConfigError(f"unknown scaling {scaling!r}; choose from {SCALINGS}", key="scaling")


def cv_splits(y: np.ndarray, groups: np.ndarray, folds: int = 5, repeats: int = 10,
              seed: int = 0) -> list[tuple[np.ndarray, np.ndarray]]:
    """Train/validation index pairs of ``folds``-fold CV repeated ``repeats`` times.

    One sample per group: ``RepeatedStratifiedKFold``.  Several samples per
    group (windows of one trial): ``StratifiedGroupKFold`` with a new shuffle
    per repeat, so a trial is never on both sides.
    """
    y = np.asarray(y)
    groups = np.asarray(groups)
    _, counts = np.unique(y, return_counts=True)
    if counts.min() < folds:
        raise ConfigError(f"{folds}-fold CV needs at least {folds} training samples per class, "
                          f"the smallest class has {counts.min()}")
    x_dummy = np.zeros((y.shape[0], 1))
    if np.unique(groups).size == groups.size:
        cv = RepeatedStratifiedKFold(n_splits=folds, n_repeats=repeats, random_state=seed)
        return list(cv.split(x_dummy, y))
    n_groups = np.unique(groups).size
    if n_groups < folds:
        raise ConfigError(f"{folds}-fold CV over trials (choosing the SVM's C) needs at least {folds} training "
                          f"trials, there are {n_groups}: train on more trials, or use a classifier without CV "
                          "(pa)", key="classifier")
    out = []
    for r in range(repeats):
        cv = StratifiedGroupKFold(n_splits=folds, shuffle=True, random_state=seed + r)
        out += list(cv.split(x_dummy, y, groups))
    return out


def _svm_pipeline(scaling: str, labels: Sequence[str], C: float = 1.0) -> Pipeline:
    scaler = make_scaler(scaling, labels)
    # libsvm is capped so that a badly scaled problem at C = 1e4 cannot run for minutes
    svc = SVC(C=C, kernel="linear", cache_size=500, max_iter=SVC_MAX_ITER)
    steps = list(scaler.steps) if scaler is not None else []
    return Pipeline(steps + [("svc", svc)])


@dataclass
class SvmResult:
    """A fitted SVM and its scores."""

    model: Pipeline
    best_c: float
    cv_accuracy: float
    cv_scores: dict[float, float]
    fit_s: float
    select_s: float
    estimate_s: float | None = None
    cv_split_scores: dict[float, list[float]] | None = None

    def predict(self, X: np.ndarray) -> np.ndarray:
        return self.model.predict(X)


def _fit_score(pipe: Pipeline, c: float, X: np.ndarray, y: np.ndarray, train: np.ndarray,
               test: np.ndarray) -> float:
    """Accuracy on ``test`` of ``pipe`` at ``C = c`` fitted on ``train`` (one CV fit, as cross_val_score)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model = clone(pipe).set_params(svc__C=c).fit(X[train], y[train])
    return float(model.score(X[test], y[test]))


def estimate_selection_s(pipe: Pipeline, X: np.ndarray, y: np.ndarray,
                         splits: Sequence[tuple[np.ndarray, np.ndarray]], c_grid: Sequence[float]) -> float:
    """Seconds that choosing C will take, from timing one CV fit at the grid's middle C and one at its
    largest (libsvm's time grows with C), times the number of fits.

    A rough figure (the fits at other C differ, the machine's load changes), printed so that a selection
    of hours is known before it starts.  It counts no speed-up from parallel jobs: on the 2-core machine
    shared with other work the parallel fits of 3,200 windows ran 3.5 times slower each than the timed
    fit (an estimate divided by 2 jobs said 2 min, the selection took 7.7 min; undivided it says 4.4).
    """
    train, test = splits[0]
    probes = sorted({float(np.median(c_grid)), float(max(c_grid))})
    t0 = time.perf_counter()
    for c in probes:
        _fit_score(pipe, c, X, y, train, test)
    per_fit = (time.perf_counter() - t0) / len(probes)
    return per_fit * len(c_grid) * len(splits)


def _duration_text(seconds: float) -> str:
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def fit_svm(X: np.ndarray, y: np.ndarray, groups: np.ndarray, labels: Sequence[str], *,
            scaling: str = "log_standardize", folds: int = 5, repeats: int = CV_REPEATS, seed: int = 0,
            c_grid: Sequence[float] = C_GRID, jobs: int = 1, progress: bool = False) -> SvmResult:
    """Linear SVM with C chosen by repeated stratified CV, refit on all training data.

    The CV runs one fit at a time (the splits and scores of scikit-learn's
    ``cross_val_score``, which ``GridSearchCV`` would use), so ``progress``
    can print an estimate of the whole selection before it starts
    (:func:`estimate_selection_s`) and show a bar on stderr that moves with
    every fit: choosing C is minutes of work on the full recordings.  With
    ``jobs`` > 1 the fits of one C run in parallel and the bar moves a C at
    a time.

    Returns
    -------
    SvmResult
        ``best_c`` (the smallest C among those with the best mean CV
        accuracy), its CV accuracy, the CV accuracy of every C, the refit
        time, the selection time, (with ``progress``) the estimate, and the
        accuracy of every C on every split (repeat r's folds are
        ``splits[r * folds:(r + 1) * folds]``; the first r repeats are those
        of a selection with r repeats).
    """
    pipe = _svm_pipeline(scaling, labels)
    splits = cv_splits(y, groups, folds, repeats, seed)
    n_jobs = jobs if len(y) >= 400 else 1  # process start-up costs more than small fits
    bar = None
    estimate = None
    if progress:
        import sys

        from tqdm import tqdm

        estimate = estimate_selection_s(pipe, X, y, splits, c_grid)
        print(f"choosing C: {len(c_grid)} values x {len(splits)} CV fits ({folds}-fold x {repeats} repeats) of "
              f"{len(y)} training windows, about {_duration_text(estimate)} (from 2 timed fits)"
              + ("; fewer repeats (--cv-repeats) or windows make it shorter" if estimate > 1800 else ""),
              file=sys.stderr, flush=True)
        bar = tqdm(total=len(c_grid) * len(splits), desc="choosing C", unit="fit")
    t0 = time.perf_counter()
    means_list = []
    per_split: dict[float, list[float]] = {}
    try:
        for c in c_grid:
            if n_jobs > 1:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", ConvergenceWarning)
                    scores = list(cross_val_score(clone(pipe).set_params(svc__C=c), X, y, cv=splits,
                                                  n_jobs=n_jobs, error_score="raise"))
                if bar is not None:
                    bar.update(len(splits))
            else:
                scores = []
                for train, test in splits:
                    scores.append(_fit_score(pipe, c, X, y, train, test))
                    if bar is not None:
                        bar.update(1)
            means_list.append(float(np.mean(scores)))
            per_split[float(c)] = [float(v) for v in scores]
            if bar is not None:
                bar.set_postfix(C=f"{c:g}", cv_accuracy=f"{means_list[-1]:.3f}")
    finally:
        if bar is not None:
            bar.close()
    means = np.array(means_list)
    select_s = time.perf_counter() - t0
    best = float(np.max(means))
    best_c = float(min(c for c, m in zip(c_grid, means) if m >= best - 1e-12))
    model = clone(pipe).set_params(svc__C=best_c)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(X, y)
    fit_s = time.perf_counter() - t0
    return SvmResult(model, best_c, best, {float(c): float(m) for c, m in zip(c_grid, means)}, fit_s, select_s,
                     estimate, per_split)


@dataclass
class PaCurve:
    """Online PA-I learning curve.

    Attributes
    ----------
    n_per_class : numpy.ndarray of int
        Training trials per class seen (1..N).
    accuracy : numpy.ndarray
        Test accuracy after each round, mean over the orders.
    accuracy_std : numpy.ndarray
        Its standard deviation over the orders.
    update_s, predict_s : float
        Median time of one ``learn`` (scaling + PA-I update) and of one ``predict``.
    orders : int
    final_confusion, final_predictions
        Of the first presentation order after the last round.
    hits : numpy.ndarray of bool, shape (orders, rounds, n_test)
        Whether each test window was predicted right after each round of
        each order (the curve is its mean over windows, then orders; a
        subset's curve is the same mean over the subset).
    """

    n_per_class: np.ndarray
    accuracy: np.ndarray
    accuracy_std: np.ndarray
    update_s: float
    predict_s: float
    orders: int
    final_confusion: np.ndarray | None = None
    final_predictions: np.ndarray | None = None
    hits: np.ndarray | None = None


def pa_curve(X_train: np.ndarray, y_train: np.ndarray, trial_train: np.ndarray, X_test: np.ndarray,
             y_test: np.ndarray, labels: Sequence[str], *, n_max: int = 30, orders: int = 5, seed: int = 0,
             scaling: str = "log_standardize", eta: float = 1.0, update: str = "prediction",
             average: bool = False) -> PaCurve:
    """Test accuracy of online PA-I after 1..n_max training trials per class.

    Each round presents one new training trial of every class (classes in a
    random order, all windows of that trial), predicting before updating
    (prediction-based update): the running feature statistics are updated
    with the sample (:meth:`OnlineClassifier.observe`) and the model learns
    it.  After every round the test set is scored.  The curve is averaged
    over ``orders`` random presentation orders.  ``update`` and ``average``
    choose the PA variant (:class:`~..core.learning.PassiveAggressive`;
    the defaults are the paper's eq. 30-32).
    """
    if scaling not in SCALINGS:
        raise ConfigError(f"unknown scaling {scaling!r}; choose from {SCALINGS}", key="scaling")
    classes = np.unique(y_train)
    per_class = {c: np.unique(trial_train[y_train == c]) for c in classes}
    n_avail = min(len(t) for t in per_class.values())
    n = min(n_max, n_avail)
    if n < 1:
        raise ConfigError("PA curve needs at least one training trial per class")
    rng = np.random.default_rng(seed)
    hits = np.zeros((orders, n, len(y_test)), dtype=bool)
    upd_times: list[float] = []
    pred_times: list[float] = []
    final_pred = None
    for o in range(orders):
        clf = OnlineClassifier(labels, eta=eta, log_activity=scaling == "log_standardize",
                               standardize=scaling != "none", update=update, average=average)
        trial_order = {c: rng.permutation(per_class[c])[:n] for c in classes}
        for k in range(n):
            for c in rng.permutation(classes):
                idx = np.flatnonzero((y_train == c) & (trial_train == trial_order[c][k]))
                for i in idx:
                    clf.observe(X_train[i])
                    t0 = time.perf_counter()
                    clf.learn(X_train[i], str(c))
                    upd_times.append(time.perf_counter() - t0)
            preds = []
            for x in X_test:
                t0 = time.perf_counter()
                p, _ = clf.predict(x)
                pred_times.append(time.perf_counter() - t0)
                preds.append(p)
            pred = np.array([int(p) for p in preds])
            hits[o, k] = pred == y_test
        if o == 0:
            final_pred = pred
    acc = hits.mean(axis=2)
    cm = confusion_matrix(y_test, final_pred, labels=classes)
    return PaCurve(np.arange(1, n + 1), acc.mean(axis=0), acc.std(axis=0), float(np.median(upd_times)),
                   float(np.median(pred_times)), orders, cm, final_pred, hits)


@dataclass
class GmmResult:
    """Unsupervised EM result: NMI (eq. 34) and mapped accuracy."""

    nmi_test: float
    nmi_train: float
    accuracy: float
    predictions: np.ndarray
    fit_s: float
    clusters: np.ndarray | None = None


def gmm_nmi(X_train: np.ndarray, y_train: np.ndarray, X_test: np.ndarray, y_test: np.ndarray,
            labels: Sequence[str], *, scaling: str = "log_standardize", seed: int = 0,
            n_components: int | None = None, kmeans_restarts: int = 20, max_iter: int = 100) -> GmmResult:
    """Spherical GMM by EM, k-means (20 restarts) initialisation, NMI with arithmetic normalisation.

    The mixture is fitted on the (scaled) training windows without labels;
    NMI is reported on the training windows and on the test windows
    (clusters predicted by the fitted mixture).  For an accuracy, clusters are
    mapped to classes one-to-one on the training set (Hungarian assignment).
    """
    k = int(n_components or np.unique(y_train).size)
    scaler = make_scaler(scaling, labels)
    Ztr = scaler.fit_transform(X_train) if scaler is not None else np.asarray(X_train, float)
    Zte = scaler.transform(X_test) if scaler is not None else np.asarray(X_test, float)
    t0 = time.perf_counter()
    km = KMeans(n_clusters=k, n_init=kmeans_restarts, random_state=seed).fit(Ztr)
    gmm = GaussianMixture(n_components=k, covariance_type="spherical", max_iter=max_iter,
                          means_init=km.cluster_centers_, random_state=seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        gmm.fit(Ztr)
    fit_s = time.perf_counter() - t0
    ctr, cte = gmm.predict(Ztr), gmm.predict(Zte)
    classes = np.unique(y_train)
    cont = np.zeros((k, classes.size))
    for c_idx, cls in enumerate(classes):
        np.add.at(cont[:, c_idx], ctr[y_train == cls], 1)
    rows, cols = linear_sum_assignment(-cont)
    mapping = {int(r): classes[c] for r, c in zip(rows, cols)}
    pred = np.array([mapping.get(int(c), -1) for c in cte])
    return GmmResult(
        nmi_test=float(normalized_mutual_info_score(y_test, cte, average_method="arithmetic")),
        nmi_train=float(normalized_mutual_info_score(y_train, ctr, average_method="arithmetic")),
        accuracy=float(np.mean(pred == y_test)), predictions=pred, fit_s=fit_s, clusters=cte)
