"""Evaluation protocols on the BioTac sliding recordings: one split, sweeps, ablations, trial CV.

Every protocol crops all trials to the common length (see
:mod:`.windows`), draws seeded random windows, computes (or reads from the
cache) the feature bank (:mod:`.features`), selects a descriptor mode and
runs the learners of :mod:`.classifiers`.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
from sklearn.metrics import confusion_matrix

from ..core.learning import RECOMMENDED_PA_AVERAGE, RECOMMENDED_PA_UPDATE
from ..datasets.recording import BiotacRecording
from ..errors import ConfigError
from .classifiers import C_GRID, C_GRID_TEXT, fit_svm, gmm_nmi, pa_curve
from .features import DEFAULT_MODE, compute_bank, mode_groups, select_features
from .windows import WINDOW_PLACEMENTS, common_length_frames, draw_contact_windows, draw_windows, window_frames

__all__ = ["EvalConfig", "CLASSIFIERS", "evaluate", "trial_folds", "trial_cv", "descriptor_seconds"]

#: Learners of ``tactile evaluate --classifier``.
CLASSIFIERS: tuple[str, ...] = ("svm", "pa", "gmm")


@dataclass(frozen=True)
class EvalConfig:
    """Parameters of one evaluation (train windows -> model -> test windows).

    Attributes
    ----------
    window : str
        Training window: seconds (``"2"``) or ``"whole"`` (the common length).
    test_window : str or None
        Test window (defaults to ``window``): the exploration-time protocol
        trains on one length and tests on others.
    mode : str
        Descriptor mode (:data:`~.features.DESCRIPTOR_MODES`, or ``averaged``);
        default :data:`~.features.DEFAULT_MODE`.
    classifiers : tuple of str
    seed : int
        Window positions and CV shuffles.
    train_per_trial, test_per_trial : int
        Random windows per trial (one when the window is the whole trial).
    scaling : str
        ``none``, ``standardize`` or ``log_standardize``.
    gate : bool
        Contact gate on (eq. 16).  Off by default here: every recorded trial
        is a slide in contact, and the gate, fed by PDC that the recording
        setup tared and clipped at 0, misfires on soft materials (35 of 120
        windows of material 16 read < 0.02 N); a gated window becomes zeros
        and costs accuracy (docs/results.md, ablation "with contact gate").
    drop : tuple of str
        Quantities left out (ablation).
    cv_folds, cv_repeats : int
        SVM C selection (5 x 10 in the paper).
    pa_max, pa_orders : int
        PA curve length (training trials per class) and presentation orders.
    pa_update, pa_average
        PA variant (:class:`~..core.learning.PassiveAggressive`): default the
        max-loss update with averaged weights; ``"prediction"`` and ``False``
        are the paper's eq. 30-32.
    windows : {"random", "contact"}
        Window placement: seeded random positions in the common-length crop,
        or random positions wholly in contact (:func:`~.windows.draw_contact_windows`).
    jobs : int
    cache_dir : str or None
    progress : bool
    """

    window: str = "2"
    test_window: str | None = None
    mode: str = DEFAULT_MODE
    classifiers: tuple[str, ...] = ("svm",)
    seed: int = 0
    train_per_trial: int = 8
    test_per_trial: int = 2
    scaling: str = "log_standardize"
    gate: bool = False
    drop: tuple[str, ...] = ()
    cv_folds: int = 5
    cv_repeats: int = 10
    pa_max: int = 30
    pa_orders: int = 5
    pa_update: str = RECOMMENDED_PA_UPDATE
    pa_average: bool = RECOMMENDED_PA_AVERAGE
    windows: str = "random"
    jobs: int = 2
    cache_dir: str | None = "build/cache"
    progress: bool = False


def descriptor_seconds(bank, mode: str) -> float:
    """Median compute time per window of a mode's feature groups (each group timed on its own)."""
    return float(np.median(sum(bank.seconds[g] for g in mode_groups(mode))))


def _check_classifiers(names: Iterable[str]) -> tuple[str, ...]:
    names = tuple(names)
    bad = [n for n in names if n not in CLASSIFIERS]
    if bad or not names:
        raise ConfigError(f"unknown classifier(s) {bad}; choose from {', '.join(CLASSIFIERS)} or all",
                          key="classifier")
    return names


def evaluate(train: Sequence[BiotacRecording], test: Sequence[BiotacRecording], cfg: EvalConfig) -> dict:
    """Train on windows of ``train`` trials, score on windows of ``test`` trials.

    Returns
    -------
    dict
        JSON-ready: the configuration, window and crop lengths, sample
        counts, descriptor time per window, and one entry per classifier
        (``accuracy``, ``confusion``, times; SVM: ``best_c``, ``cv_accuracy``;
        PA: the learning curve; GMM: ``nmi``).
    """
    classifiers = _check_classifiers(cfg.classifiers)
    if not train or not test:
        raise ConfigError("train and test sets must both hold recordings")
    # The same file in both splits is a leak; the same (material, trial) numbers in two different
    # folders are two different recordings (a separate test set may number its trials from 1 again).
    overlap = {str(Path(r.path).resolve()) for r in train} & {str(Path(r.path).resolve()) for r in test}
    if overlap:
        raise ConfigError(f"train and test share {len(overlap)} recordings (e.g. {sorted(overlap)[0]}): "
                          "use disjoint trial ranges")
    common = common_length_frames(list(train) + list(test))
    rate = float(np.median([r.frame_rate_hz for r in list(train) + list(test)]))
    rate = 100.0 if abs(rate - 100.0) < 1.0 else rate
    n_train = window_frames(cfg.window, rate, common)
    n_test = window_frames(cfg.test_window or cfg.window, rate, common)
    without: list[str] = []
    if cfg.windows == "random":
        w_train = draw_windows(train, n_train, common, cfg.train_per_trial, cfg.seed)
        w_test = draw_windows(test, n_test, common, cfg.test_per_trial, cfg.seed + 1)
    elif cfg.windows == "contact":
        from ..core.robot import load_robot

        robot = load_robot("shadow_hand")
        npc, ft = robot.cell_types["biotac"].force.n_per_count, robot.contact.force_threshold_n
        w_train, miss_tr = draw_contact_windows(train, n_train, cfg.train_per_trial, cfg.seed, npc, ft)
        w_test, miss_te = draw_contact_windows(test, n_test, cfg.test_per_trial, cfg.seed + 1, npc, ft)
        without = [f"{r.class_name} trial {r.trial}" for r in miss_tr + miss_te]
        if not w_train or not w_test:
            raise ConfigError(f"no {'training' if not w_train else 'test'} window of {n_train} frames lies wholly "
                              f"in contact (force >= {ft:g} N): shorten --window, or check the tare", key="windows")
    else:
        raise ConfigError(f"windows must be one of {', '.join(WINDOW_PLACEMENTS)}, got {cfg.windows!r}",
                          key="windows")
    # Each split's windows are looked up in that split's recordings only: (material, trial) names a
    # recording uniquely inside one folder, not across two.
    sub = "subwindows" in mode_groups(cfg.mode)
    b_train = compute_bank(train, w_train, cache_dir=cfg.cache_dir, jobs=cfg.jobs, progress=cfg.progress,
                           desc="train descriptors", subwindows=sub)
    b_test = compute_bank(test, w_test, cache_dir=cfg.cache_dir, jobs=cfg.jobs, progress=cfg.progress,
                          desc="test descriptors", subwindows=sub)
    X_tr, labels = select_features(b_train, cfg.mode, gate=cfg.gate, drop=cfg.drop)
    X_te, _ = select_features(b_test, cfg.mode, gate=cfg.gate, drop=cfg.drop)
    y_tr, y_te = b_train.y, b_test.y
    classes = np.unique(np.concatenate([y_tr, y_te]))
    names = {r.material: r.class_name for r in list(train) + list(test)}
    missing = sorted(set(y_te) - set(y_tr))
    if missing:
        raise ConfigError(f"test materials {missing} have no training trials")
    out: dict = {
        "config": {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(cfg).items()
                   if k not in ("progress", "jobs", "cache_dir")},
        "common_length_frames": common,
        "common_length_s": common / rate,
        "train_window_frames": n_train,
        "test_window_frames": n_test,
        "n_train": int(len(y_tr)),
        "n_test": int(len(y_te)),
        "n_features": int(X_tr.shape[1]),
        "train_trials": sorted({r.trial for r in train}),
        "test_trials": sorted({r.trial for r in test}),
        "classes": [int(c) for c in classes],
        "class_names": [names[int(c)] for c in classes],
        "trials_without_contact_window": without,
        "in_contact_fraction": float(np.mean(np.concatenate([b_train.in_contact, b_test.in_contact]))),
        "descriptor_s_per_window": descriptor_seconds(b_test, cfg.mode),
        "classifiers": {},
    }
    if "svm" in classifiers:
        res = fit_svm(X_tr, y_tr, b_train.groups_id, labels, scaling=cfg.scaling, folds=cfg.cv_folds,
                      repeats=cfg.cv_repeats, seed=cfg.seed, jobs=cfg.jobs)
        pred = res.predict(X_te)
        per_pred = []
        for x in X_te[: min(50, len(X_te))]:
            t0 = time.perf_counter()
            res.model.predict(x[None, :])
            per_pred.append(time.perf_counter() - t0)
        out["classifiers"]["svm"] = {
            "accuracy": float(np.mean(pred == y_te)),
            "confusion": confusion_matrix(y_te, pred, labels=classes).tolist(),
            "best_c": res.best_c, "cv_accuracy": res.cv_accuracy, "cv_scores": res.cv_scores,
            "c_grid": list(C_GRID), "c_grid_text": C_GRID_TEXT,
            "cv": f"{cfg.cv_folds}-fold x {cfg.cv_repeats} repeats",
            "fit_s": res.fit_s, "select_s": res.select_s,
            "update_s": res.fit_s, "predict_s": float(np.median(per_pred)),
        }
    if "pa" in classifiers:
        curve = pa_curve(X_tr, y_tr, b_train.trials, X_te, y_te, labels, n_max=cfg.pa_max,
                         orders=cfg.pa_orders, seed=cfg.seed, scaling=cfg.scaling, update=cfg.pa_update,
                         average=cfg.pa_average)
        out["classifiers"]["pa"] = {
            "accuracy": float(curve.accuracy[-1]),
            "confusion": curve.final_confusion.tolist(),
            "curve": {"n_per_class": curve.n_per_class.tolist(), "accuracy": curve.accuracy.tolist(),
                      "accuracy_std": curve.accuracy_std.tolist(), "orders": curve.orders},
            "update_s": curve.update_s, "predict_s": curve.predict_s,
        }
    if "gmm" in classifiers:
        g = gmm_nmi(X_tr, y_tr, X_te, y_te, labels, scaling=cfg.scaling, seed=cfg.seed)
        out["classifiers"]["gmm"] = {
            "accuracy": g.accuracy, "nmi": g.nmi_test, "nmi_train": g.nmi_train,
            "confusion": confusion_matrix(y_te, g.predictions, labels=classes).tolist(),
            "fit_s": g.fit_s,
        }
    return out


def trial_folds(trials: Sequence[int], folds: int) -> list[list[int]]:
    """Contiguous blocks of trial numbers (1-10, 11-20, 21-30 for 30 trials and 3 folds)."""
    t = sorted(set(trials))
    if folds < 2 or folds > len(t):
        raise ConfigError(f"trial CV needs 2..{len(t)} folds, got {folds}")
    return [[int(x) for x in b] for b in np.array_split(np.array(t), folds)]


def trial_cv(recordings: Sequence[BiotacRecording], cfg: EvalConfig, folds: int = 3) -> dict:
    """Cross-validation over trials: each block of trials is the test set once."""
    trials = sorted({r.trial for r in recordings})
    results = []
    for block in trial_folds(trials, folds):
        test = [r for r in recordings if r.trial in block]
        train = [r for r in recordings if r.trial not in block]
        results.append(evaluate(train, test, cfg))
    out: dict = {"folds": [[int(min(b)), int(max(b))] for b in trial_folds(trials, folds)], "classifiers": {}}
    for name in cfg.classifiers:
        accs = [r["classifiers"][name]["accuracy"] for r in results]
        out["classifiers"][name] = {"accuracy": float(np.mean(accs)), "accuracy_std": float(np.std(accs)),
                                    "fold_accuracy": accs}
    return out
