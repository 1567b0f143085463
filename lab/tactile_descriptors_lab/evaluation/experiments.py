"""Evaluation protocols on the BioTac sliding recordings: one split, sweeps, ablations, trial CV.

Every protocol crops all trials to the common length (see
:mod:`.windows`), draws seeded random windows, computes (or reads from the
cache) the feature bank (:mod:`.features`), selects a descriptor mode and
runs the learners of :mod:`.classifiers`.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
from sklearn.metrics import confusion_matrix, normalized_mutual_info_score

from tactile_descriptors_lab.datasets.recording import BiotacRecording
from tactile_descriptors_lab.evaluation.bank import (
    DEFAULT_MODE,
    FeatureBank,
    compute_bank,
    mode_groups,
    recordings_robot,
    select_features,
)
from tactile_descriptors_lab.evaluation.classifiers import C_GRID, C_GRID_TEXT, CV_REPEATS, fit_svm, gmm_nmi, pa_curve
from tactile_descriptors_lab.evaluation.rocket_fit import transform_in_use
from tactile_descriptors_lab.evaluation.sampling import (
    DEFAULT_BLOCK_HOP_S,
    DEFAULT_BLOCK_S,
    WINDOW_PLACEMENTS,
    Window,
    block_windows,
    common_length_frames,
    default_train_windows,
    draw_contact_windows,
    draw_mixed_windows,
    draw_windows,
    window_lengths,
)
from tactile_descriptors_ros.core.blocks import block_mean
from tactile_descriptors_ros.core.learning import RECOMMENDED_PA_AVERAGE, RECOMMENDED_PA_UPDATE
from tactile_descriptors_ros.core.robot import load_robot
from tactile_descriptors_ros.errors import ConfigError

__all__ = ["EvalConfig", "CLASSIFIERS", "DEFAULT_BLOCK_S", "DEFAULT_BLOCK_HOP_S", "evaluate", "evaluate_many",
           "trial_folds", "trial_cv", "descriptor_seconds", "draw_spec_windows", "describe_windows",
           "select_mode", "selection_candidates", "evaluate_selected", "selected_trial_cv", "SELECTION_FOLDS"]


#: Learners of ``tactile evaluate --classifier``.
CLASSIFIERS: tuple[str, ...] = ("svm", "pa", "gmm")


@dataclass(frozen=True)
class EvalConfig:
    """Parameters of one evaluation (train windows -> model -> test windows).

    Attributes
    ----------
    window : str
        Training window: seconds (``"2"``), ``"whole"`` (the common length)
        or a range of lengths (``"1-6"``, see :func:`~.windows.window_lengths`).
    test_window : str or None
        Test window (defaults to ``window``): the length-robustness protocol
        trains on one length and tests on others, or on random lengths
        (``"1-6"``).
    mode : str
        Descriptor mode (:data:`~.features.DESCRIPTOR_MODES`, or ``averaged``);
        default :data:`~.features.DEFAULT_MODE`.
    classifiers : tuple of str
    seed : int
        Window positions and CV shuffles.
    train_per_trial, test_per_trial : int
        Random windows per trial (one when the window is the whole trial).
        ``train_per_trial`` None: :func:`~.windows.default_train_windows` of
        the training window (8 at 2 s and longer, 16 at 1 s, 32 at 0.5 s).
    scaling : str
        ``none``, ``standardize`` or ``log_standardize``.
    gate : bool
        Contact gate on (eq. 16).  Off by default here: every recorded trial
        is a slide in contact, and the gate, fed by PDC that the recording
        setup tared and clipped at 0, misfires on soft materials (35 of 120
        windows of material 16 read < 0.02 N); a gated window becomes zeros
        and costs accuracy (lab/docs/results.md, ablation "with contact gate").
    drop : tuple of str
        Quantities left out (ablation).
    cv_folds, cv_repeats : int
        SVM C selection (5 x 10 in the paper; 5 x :data:`~.classifiers.CV_REPEATS` by default).
    pa_max, pa_orders : int
        PA curve length (training trials per class) and presentation orders.
    pa_update, pa_average
        Online learner (:class:`~..core.learning.PassiveAggressive`): default
        the classifier node's, AROW without averaging
        (:data:`~..core.learning.RECOMMENDED_PA_UPDATE`); ``"prediction"``
        and ``False`` are the paper's eq. 30-32.
    windows : {"random", "contact"}
        Window placement: seeded random positions in the common-length crop,
        or random positions wholly in contact (:func:`~.windows.draw_contact_windows`).
    block_s, block_hop_s : float or None
        Block averaging (:func:`describe_windows`): a window's descriptor is
        the mean of the descriptors of its ``block_s`` blocks, at most
        ``block_hop_s`` apart.  ``None``: one descriptor of the whole window.
    rocket_file : str or None
        The ``rocket`` group's transforms from this file (written by
        ``tactile fit-rocket``) instead of the config directory's
        (:func:`~.rocket_fit.transform_in_use`); None: the config directory's.
    jobs : int
    cache_dir : str or None
    progress : bool
    """

    window: str = "2"
    test_window: str | None = None
    mode: str = DEFAULT_MODE
    classifiers: tuple[str, ...] = ("svm",)
    seed: int = 0
    train_per_trial: int | None = None
    test_per_trial: int = 2
    scaling: str = "log_standardize"
    gate: bool = False
    drop: tuple[str, ...] = ()
    cv_folds: int = 5
    cv_repeats: int = CV_REPEATS
    pa_max: int = 30
    pa_orders: int = 5
    pa_update: str = RECOMMENDED_PA_UPDATE
    pa_average: bool = RECOMMENDED_PA_AVERAGE
    windows: str = "random"
    block_s: float | None = DEFAULT_BLOCK_S
    block_hop_s: float | None = DEFAULT_BLOCK_HOP_S
    rocket_file: str | None = None
    jobs: int = 2
    cache_dir: str | None = "build/cache"
    progress: bool = False
    c_grid: tuple[float, ...] = C_GRID


def descriptor_seconds(bank, mode: str) -> float:
    """Median compute time per window of a mode's feature groups (each group timed on its own)."""
    return float(np.median(sum(bank.seconds[g.partition(":")[0]] for g in dict.fromkeys(mode_groups(mode)))))


def draw_spec_windows(recordings: Sequence[BiotacRecording], window: str, rate_hz: float, common: int,
                      per_trial: int, seed: int) -> tuple[list[Window], tuple[int, ...]]:
    """Windows of a window specification (one length, ``whole`` or a range) and the lengths it allows."""
    lengths = window_lengths(window, rate_hz, common)
    if len(lengths) == 1:
        return draw_windows(recordings, lengths[0], common, per_trial, seed), lengths
    return draw_mixed_windows(recordings, lengths, common, per_trial, seed), lengths


def _draw(recordings: Sequence[BiotacRecording], spec: str, rate_hz: float, common: int, per_trial: int,
          seed: int, cfg: EvalConfig, without: list[str], split: str) -> tuple[list[Window], tuple[int, ...]]:
    """Windows of one split by ``cfg.windows`` placement; trials without a contact window go to ``without``."""
    if cfg.windows == "random":
        return draw_spec_windows(recordings, spec, rate_hz, common, per_trial, seed)
    if cfg.windows != "contact":
        raise ConfigError(f"windows must be one of {', '.join(WINDOW_PLACEMENTS)}, got {cfg.windows!r}",
                          key="windows")
    lengths = window_lengths(spec, rate_hz, common)
    if len(lengths) != 1:
        raise ConfigError(f"contact windows take one length, not the range {spec!r}", key="windows")
    robot, cell_type = recordings_robot(recordings)
    npc, ft = cell_type.force.n_per_count, robot.contact.force_threshold_n
    wins, miss = draw_contact_windows(recordings, lengths[0], per_trial, seed, npc, ft)
    without += [f"{r.class_name} trial {r.trial}" for r in miss]
    if not wins:
        raise ConfigError(f"no {split} window of {lengths[0]} frames lies wholly in contact (force >= {ft:g} N): "
                          "shorten --window, or check the tare", key="windows")
    return wins, lengths


def describe_windows(recordings: Sequence[BiotacRecording], windows: Sequence[Window], *,
                     block_frames: int | None = None, hop_frames: int | None = None, **kwargs) -> FeatureBank:
    """Feature bank of windows of one or several lengths, rows in the order of ``windows``.

    :func:`~.features.compute_bank` describes (and caches) one length at a
    time; windows of a length range are described per length and put back
    in order.  ``kwargs`` go to ``compute_bank``.

    With ``block_frames`` a window's row is the *mean over its blocks*
    (:func:`~.windows.block_windows`, ``hop_frames`` apart) of the blocks'
    rows, by the core's :func:`~..core.blocks.block_mean` (Activity averaged
    as ``log1p`` and mapped back by ``expm1``, so the log scaling of the
    learners sees the mean log Activity) -- the values the window node's
    :func:`~..core.blocks.describe_blocks` publishes for the same window; force the
    blocks' mean and the contact gate that mean against F_t; compute times
    add up.  Every quantity is then an average of statistics of
    equal-length stretches, whose expectation does not depend on how long
    the window is (see lab/docs/evaluation.md, "Touch length").
    """
    if block_frames:
        return _block_mean_bank(recordings, windows, int(block_frames), int(hop_frames or block_frames), kwargs)
    by_length: dict[int, list[int]] = {}
    for i, w in enumerate(windows):
        by_length.setdefault(w.n_frames, []).append(i)
    if len(by_length) <= 1:
        return compute_bank(recordings, windows, **kwargs)
    banks = [compute_bank(recordings, [windows[i] for i in idx], **kwargs) for idx in by_length.values()]
    back = np.argsort(np.concatenate([np.array(idx) for idx in by_length.values()]), kind="stable")

    def stacked(arrays):
        return np.concatenate(list(arrays))[back]

    first = banks[0]
    return FeatureBank(
        windows=list(windows),
        groups={g: stacked(b.groups[g] for b in banks) for g in first.groups},
        labels=first.labels,
        in_contact=stacked(b.in_contact for b in banks),
        mean_force_n=stacked(b.mean_force_n for b in banks),
        seconds={k: stacked(b.seconds[k] for b in banks) for k in first.seconds},
        unfed=first.unfed,
    )


def _block_mean_bank(recordings: Sequence[BiotacRecording], windows: Sequence[Window], block_frames: int,
                     hop_frames: int, kwargs: dict) -> FeatureBank:
    """:func:`describe_windows` with block averaging."""
    if kwargs.get("subwindows"):
        raise ConfigError("block averaging and the subwindows group do not combine: choose one", key="block")
    pieces: list[Window] = []
    owner: list[int] = []
    for i, w in enumerate(windows):
        blocks = block_windows(w, block_frames, hop_frames)
        pieces += blocks
        owner += [i] * len(blocks)
    # a block is described once however many windows share it
    unique = list(dict.fromkeys(pieces))
    row = {p: k for k, p in enumerate(unique)}
    bank = describe_windows(recordings, unique, **kwargs)
    take = np.array([row[p] for p in pieces])
    owner_a = np.array(owner)
    counts = np.bincount(owner_a, minlength=len(windows)).astype(np.float64)

    def mean_rows(values: np.ndarray) -> np.ndarray:
        out = np.zeros((len(windows),) + values.shape[1:])
        np.add.at(out, owner_a, values[take])
        return out / counts.reshape((-1,) + (1,) * (values.ndim - 1))

    # the core's block mean (Activity in log), as the window node averages its blocks
    ends = np.cumsum(counts.astype(np.int64))[:-1]  # a window's blocks are consecutive in ``pieces``
    groups = {g: np.stack([block_mean(rows, bank.labels[g]) for rows in np.split(values[take], ends)])
              for g, values in bank.groups.items()}
    threshold = kwargs.get("force_threshold_n")
    if threshold is None:
        threshold = load_robot("shadow_hand").contact.force_threshold_n
    force = mean_rows(bank.mean_force_n)
    seconds = {}
    for k, v in bank.seconds.items():
        total = np.zeros(len(windows))
        np.add.at(total, owner_a, v[take])
        seconds[k] = total
    return FeatureBank(windows=list(windows), groups=groups, labels=bank.labels,
                       in_contact=force >= float(threshold), mean_force_n=force, seconds=seconds,
                       unfed=bank.unfed)


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
    spec = cfg.test_window or cfg.window
    return evaluate_many(train, test, cfg, [spec])[spec]


def evaluate_many(train: Sequence[BiotacRecording], test: Sequence[BiotacRecording], cfg: EvalConfig,
                  test_windows: Sequence[str]) -> dict[str, dict]:
    """Train once on ``cfg.window``, score on the test windows of every specification in ``test_windows``.

    Each specification's result is exactly what :func:`evaluate` returns
    with ``test_window`` set to it (the same test windows, the same model:
    the learners never look at the test set while training), at the cost of
    one training.

    Returns
    -------
    dict of str to dict
        :func:`evaluate`'s result per test window specification.
    """
    if cfg.rocket_file is None:
        return _evaluate_many(train, test, cfg, test_windows)
    _, cell_type = recordings_robot(list(train) + list(test))
    with transform_in_use(cfg.rocket_file, cell_type):
        return _evaluate_many(train, test, cfg, test_windows)


def _evaluate_many(train: Sequence[BiotacRecording], test: Sequence[BiotacRecording], cfg: EvalConfig,
                   test_windows: Sequence[str]) -> dict[str, dict]:
    classifiers = _check_classifiers(cfg.classifiers)
    specs = list(dict.fromkeys(test_windows))
    if not train or not test:
        raise ConfigError("train and test sets must both hold recordings")
    if not specs:
        raise ConfigError("no test window to score", key="test_window")
    # The same file in both splits is a leak; the same (material, trial) numbers in two different
    # folders are two different recordings (a separate test set may number its trials from 1 again).
    overlap = {str(Path(r.path).resolve()) for r in train} & {str(Path(r.path).resolve()) for r in test}
    if overlap:
        raise ConfigError(f"train and test share {len(overlap)} recordings (e.g. {sorted(overlap)[0]}): "
                          "use disjoint trial ranges")
    common = common_length_frames(list(train) + list(test))
    rate = float(np.median([r.frame_rate_hz for r in list(train) + list(test)]))
    rate = 100.0 if abs(rate - 100.0) < 1.0 else rate
    without: list[str] = []
    per_trial = cfg.train_per_trial or default_train_windows(window_lengths(cfg.window, rate, common), rate)
    w_train, l_train = _draw(train, cfg.window, rate, common, per_trial, cfg.seed, cfg, without, "training")
    # Each split's windows are looked up in that split's recordings only: (material, trial) names a
    # recording uniquely inside one folder, not across two.
    sub = "subwindows" in mode_groups(cfg.mode)
    robot, cell_type = recordings_robot(list(train) + list(test))
    bank_kw = {"cache_dir": cfg.cache_dir, "jobs": cfg.jobs, "progress": cfg.progress, "subwindows": sub,
               "cell_type": cell_type, "force_threshold_n": robot.contact.force_threshold_n}
    if cfg.block_s:
        bank_kw["block_frames"] = int(round(cfg.block_s * rate))
        bank_kw["hop_frames"] = int(round((cfg.block_hop_s or cfg.block_s) * rate))
    b_train = describe_windows(train, w_train, desc="train descriptors", **bank_kw)
    X_tr, labels = select_features(b_train, cfg.mode, gate=cfg.gate, drop=cfg.drop)
    y_tr = b_train.y
    parts = []
    for spec in specs:
        w_test, l_test = _draw(test, spec, rate, common, cfg.test_per_trial, cfg.seed + 1, cfg, without, "test")
        b_test = describe_windows(test, w_test, desc="test descriptors", **bank_kw)
        X_te, _ = select_features(b_test, cfg.mode, gate=cfg.gate, drop=cfg.drop)
        parts.append((spec, l_test, b_test, X_te))
    X_all = np.concatenate([p[3] for p in parts])
    y_all = np.concatenate([p[2].y for p in parts])
    where = np.repeat(np.arange(len(parts)), [len(p[3]) for p in parts])
    classes = np.unique(np.concatenate([y_tr, y_all]))
    names = {r.material: r.class_name for r in list(train) + list(test)}
    missing = sorted(set(y_all) - set(y_tr))
    if missing:
        raise ConfigError(f"test materials {missing} have no training trials")
    svm = pa = gmm = None
    if "svm" in classifiers:
        svm = fit_svm(X_tr, y_tr, b_train.groups_id, labels, scaling=cfg.scaling, folds=cfg.cv_folds,
                      repeats=cfg.cv_repeats, seed=cfg.seed, jobs=cfg.jobs, progress=cfg.progress,
                      c_grid=cfg.c_grid)
        svm_pred = svm.predict(X_all)
    if "pa" in classifiers:
        pa = pa_curve(X_tr, y_tr, b_train.trials, X_all, y_all, labels, n_max=cfg.pa_max, orders=cfg.pa_orders,
                      seed=cfg.seed, scaling=cfg.scaling, update=cfg.pa_update, average=cfg.pa_average)
    if "gmm" in classifiers:
        gmm = gmm_nmi(X_tr, y_tr, X_all, y_all, labels, scaling=cfg.scaling, seed=cfg.seed)

    results = {}
    for k, (spec, l_test, b_test, X_te) in enumerate(parts):
        sel = where == k
        y_te = y_all[sel]
        out: dict = {
            "config": {**{key: (list(v) if isinstance(v, tuple) else v) for key, v in asdict(cfg).items()
                          if key not in ("progress", "jobs", "cache_dir")},
                       "test_window": None if spec == cfg.window and cfg.test_window is None else spec},
            "common_length_frames": common,
            "common_length_s": common / rate,
            # one length: its frame count; a range: the list of lengths windows were drawn from
            "train_window_frames": l_train[0] if len(l_train) == 1 else list(l_train),
            "test_window_frames": l_test[0] if len(l_test) == 1 else list(l_test),
            "train_windows_per_trial": int(per_trial),
            "n_train": int(len(y_tr)),
            "n_test": int(len(y_te)),
            "n_features": int(X_tr.shape[1]),
            "train_trials": sorted({r.trial for r in train}),
            "test_trials": sorted({r.trial for r in test}),
            "classes": [int(c) for c in classes],
            "class_names": [names[int(c)] for c in classes],
            "trials_without_contact_window": sorted(set(without)),
            "in_contact_fraction": float(np.mean(np.concatenate([b_train.in_contact, b_test.in_contact]))),
            "descriptor_s_per_window": descriptor_seconds(b_test, cfg.mode),
            "classifiers": {},
        }
        if svm is not None:
            pred = svm_pred[sel]
            per_pred = []
            for x in X_te[: min(50, len(X_te))]:
                t0 = time.perf_counter()
                svm.model.predict(x[None, :])
                per_pred.append(time.perf_counter() - t0)
            # where the test windows sit in the training scaling: a quantity whose mean moves with the
            # window length shows up here (the report's touch-length diagnosis)
            scaled = svm.model[:-1].transform(X_te) if len(svm.model.steps) > 1 else X_te
            out["feature_labels"] = list(labels)
            out["feature_mean_z"] = np.mean(scaled, axis=0).tolist()
            out["classifiers"]["svm"] = {
                "accuracy": float(np.mean(pred == y_te)),
                "confusion": confusion_matrix(y_te, pred, labels=classes).tolist(),
                "best_c": svm.best_c, "cv_accuracy": svm.cv_accuracy, "cv_scores": svm.cv_scores,
                "c_grid": list(cfg.c_grid), "c_grid_text": C_GRID_TEXT if tuple(cfg.c_grid) == C_GRID else
                ", ".join(f"{c:g}" for c in cfg.c_grid),
                "cv": f"{cfg.cv_folds}-fold x {cfg.cv_repeats} repeats",
                "fit_s": svm.fit_s, "select_s": svm.select_s,
                "update_s": svm.fit_s, "predict_s": float(np.median(per_pred)),
            }
        if pa is not None:
            hits = pa.hits[:, :, sel]  # (orders, rounds, test windows)
            acc = hits.mean(axis=2)
            out["classifiers"]["pa"] = {
                "accuracy": float(acc.mean(axis=0)[-1]),
                "confusion": confusion_matrix(y_te, pa.final_predictions[sel], labels=classes).tolist(),
                "curve": {"n_per_class": pa.n_per_class.tolist(), "accuracy": acc.mean(axis=0).tolist(),
                          "accuracy_std": acc.std(axis=0).tolist(), "orders": pa.orders},
                "update_s": pa.update_s, "predict_s": pa.predict_s,
            }
        if gmm is not None:
            clusters, gpred = gmm.clusters[sel], gmm.predictions[sel]
            out["classifiers"]["gmm"] = {
                "accuracy": float(np.mean(gpred == y_te)),
                "nmi": float(normalized_mutual_info_score(y_te, clusters, average_method="arithmetic")),
                "nmi_train": gmm.nmi_train,
                "confusion": confusion_matrix(y_te, gpred, labels=classes).tolist(),
                "fit_s": gmm.fit_s,
            }
        results[spec] = out
    return results


def trial_folds(trials: Sequence[int], folds: int) -> list[list[int]]:
    """Contiguous blocks of trial numbers (1-10, 11-20, 21-30 for 30 trials and 3 folds)."""
    t = sorted(set(trials))
    if folds < 2 or folds > len(t):
        raise ConfigError(f"trial CV needs 2..{len(t)} folds, got {folds}")
    return [[int(x) for x in b] for b in np.array_split(np.array(t), folds)]


def _trial_splits(recordings: Sequence[BiotacRecording], folds: int
                  ) -> tuple[list[list[int]], list[tuple[list[BiotacRecording], list[BiotacRecording]]]]:
    """The blocks of :func:`trial_folds` over the recordings' trials and, for each, its ``(training, test)``
    recordings: the block tested, the other blocks trained on."""
    blocks = trial_folds(sorted({r.trial for r in recordings}), folds)
    return blocks, [([r for r in recordings if r.trial not in b], [r for r in recordings if r.trial in b])
                    for b in blocks]


def _block_ranges(blocks: Sequence[Sequence[int]]) -> list[list[int]]:
    """Each block of trials as ``[first, last]``."""
    return [[int(min(b)), int(max(b))] for b in blocks]


def _fold_summary(accs: Sequence[float]) -> dict:
    """Accuracy over folds: ``accuracy`` (mean), ``accuracy_std`` and ``fold_accuracy``."""
    return {"accuracy": float(np.mean(accs)), "accuracy_std": float(np.std(accs)),
            "fold_accuracy": [float(a) for a in accs]}


def trial_cv(recordings: Sequence[BiotacRecording], cfg: EvalConfig, folds: int = 3,
             test_windows: Sequence[str] | None = None) -> dict:
    """Cross-validation over trials: each block of trials is the test set once.

    With ``test_windows`` each fold's model is trained once and scored on
    every test window specification (:func:`evaluate_many`), and the result
    holds one summary per specification under ``by_test_window``.
    """
    blocks, splits = _trial_splits(recordings, folds)
    specs = list(test_windows) if test_windows else [cfg.test_window or cfg.window]
    per_fold = [evaluate_many(train, test, cfg, specs) for train, test in splits]

    def summary(spec: str) -> dict:
        return {"folds": _block_ranges(blocks),
                "classifiers": {name: _fold_summary([r[spec]["classifiers"][name]["accuracy"] for r in per_fold])
                                for name in cfg.classifiers}}

    if test_windows:
        return {"folds": _block_ranges(blocks),
                "by_test_window": {spec: summary(spec) for spec in specs}}
    return summary(specs[0])


#: Folds of the selection's cross-validation inside the training trials (contiguous blocks of trials).
SELECTION_FOLDS: int = 3


def _block_label(block_s: float | None) -> str:
    return f"{block_s:g} s blocks" if block_s else "whole window"


def selection_candidates(cfg: EvalConfig, modes: Sequence[str], blocks: Sequence[float] | None,
                          block_hop_s: float, rockets: Sequence[str] | None = None
                          ) -> tuple[dict[str, EvalConfig], dict[str, str]]:
    """The configurations a selection compares, by label, and the pairs it cannot run, with why.

    Without ``blocks`` a candidate is a mode with ``cfg``'s blocks (its label
    is the mode's name).  With ``blocks`` it is every (mode, block length)
    pair; a block of 0 is one descriptor per window; a block's hop is
    ``block_hop_s`` or the block, whichever is shorter.  The ``subwindows``
    group describes a window's pieces itself, so it pairs with the whole
    window only.  With ``rockets`` (transform files) every candidate whose
    mode holds the ``rocket`` group is tried with each file in turn (label
    ``<label>, transform <file>``); the other modes once.
    """
    runs, skipped = _mode_block_candidates(cfg, modes, blocks, block_hop_s)
    if not rockets:
        return runs, skipped
    if not any("rocket" in mode_groups(run.mode) for run in runs.values()):
        raise ConfigError("transform files choose among the rocket group's transforms: no candidate mode holds "
                          "the group (e.g. rocket, combined_rocket)", key="select_rocket")
    out: dict[str, EvalConfig] = {}
    for label, run in runs.items():
        if "rocket" not in mode_groups(run.mode):
            out[label] = run
            continue
        for path in dict.fromkeys(rockets):
            out[f"{label}, transform {path}"] = replace(run, rocket_file=str(path))
    return out, skipped


def _mode_block_candidates(cfg: EvalConfig, modes: Sequence[str], blocks: Sequence[float] | None,
                           block_hop_s: float) -> tuple[dict[str, EvalConfig], dict[str, str]]:
    """:func:`selection_candidates` without the transform files."""
    for mode in modes:
        mode_groups(mode)  # unknown modes are refused before any work
    if blocks is None:
        if cfg.block_s and any("subwindows" in mode_groups(m) for m in modes):
            raise ConfigError("block averaging and the subwindows group do not combine: select with whole windows "
                              "(block 0), or among blocks including 0 (--select-blocks)", key="block")
        return {m: replace(cfg, mode=m) for m in dict.fromkeys(modes)}, {}
    if any(not np.isfinite(b) or b < 0 for b in blocks) or not block_hop_s > 0:
        raise ConfigError(f"selection blocks must be >= 0 s (0 = whole window) with a hop > 0, got "
                          f"{list(blocks)} / {block_hop_s:g}", key="select_blocks")
    runs: dict[str, EvalConfig] = {}
    skipped: dict[str, str] = {}
    for mode in dict.fromkeys(modes):
        for b in dict.fromkeys(float(b) for b in blocks):
            label = f"{mode}, {_block_label(b)}"
            if b and "subwindows" in mode_groups(mode):
                skipped[label] = "the subwindows group describes the window's pieces itself: whole window only"
                continue
            runs[label] = replace(cfg, mode=mode, block_s=b or None, block_hop_s=min(block_hop_s, b) if b else None)
    if not runs:
        raise ConfigError("no candidate the selection can run: " + "; ".join(f"{k} ({v})" for k, v in skipped.items()),
                          key="select_blocks")
    return runs, skipped


def select_mode(train: Sequence[BiotacRecording], cfg: EvalConfig, candidates: Sequence[str],
                folds: int = SELECTION_FOLDS, blocks: Sequence[float] | None = None,
                block_hop_s: float = DEFAULT_BLOCK_HOP_S, rockets: Sequence[str] | None = None) -> dict:
    """Choose a descriptor mode (and block length) by cross-validation by trial *inside the training trials only*.

    The training trials are cut into ``folds`` contiguous blocks
    (:func:`trial_folds`); each candidate is trained on the other blocks and
    scored on each block in turn, with ``cfg``'s first classifier and window
    (windows drawn as :func:`evaluate` draws them).  The candidate with the
    best mean accuracy is chosen; ties go to the one listed first (list the
    cheaper ones first).  No test trial is read: the test split is scored
    once, afterwards, with the chosen mode (:func:`evaluate_selected`).

    With ``blocks`` (seconds, 0 = one descriptor per window) every mode is
    tried with every block length, modes first in the order listed: how a
    window is averaged is chosen by the same inner cross-validation, never
    by the test split.

    With ``rockets`` (files written by ``tactile fit-rocket``, e.g. of two
    sizes) the modes holding the ``rocket`` group are also tried with each
    transform: the transform's size is chosen the same way.  The files should
    be fitted on the training trials only; inside the selection a file fitted
    on all of them has seen the inner test block's signals (its biases are
    quantiles of them, never of labels), and every file alike.

    Returns
    -------
    dict
        ``chosen`` (the mode), ``block_s`` (its block length, None = the
        whole window), ``rocket_file`` (None = the config directory's),
        ``chosen_label``, ``candidates`` (per label: ``mode``, ``block_s``,
        ``rocket_file``, ``accuracy``, ``accuracy_std``, ``fold_accuracy``),
        ``skipped`` (labels a mode cannot pair with, and why), ``folds`` and
        ``classifier``.
    """
    return _select(train, cfg, candidates, folds, blocks, block_hop_s, rockets)[0]


def _select(train: Sequence[BiotacRecording], cfg: EvalConfig, candidates: Sequence[str], folds: int,
            blocks: Sequence[float] | None, block_hop_s: float, rockets: Sequence[str] | None
            ) -> tuple[dict, EvalConfig]:
    """:func:`select_mode`'s result, and the chosen candidate's configuration (``cfg`` with its mode, blocks
    and transform)."""
    if not candidates:
        raise ConfigError("no candidate mode to select from", key="select")
    runs, skipped = selection_candidates(cfg, candidates, blocks, block_hop_s, rockets)
    name = cfg.classifiers[0]
    fold_trials, splits = _trial_splits(train, folds)
    scores: dict[str, dict] = {}
    for label, run_cfg in runs.items():
        accs = [evaluate(inner_train, inner_test, replace(run_cfg, classifiers=(name,), test_window=None)
                         )["classifiers"][name]["accuracy"] for inner_train, inner_test in splits]
        scores[label] = {"mode": run_cfg.mode, "block_s": run_cfg.block_s, "rocket_file": run_cfg.rocket_file,
                         **_fold_summary(accs)}
    best = max(v["accuracy"] for v in scores.values())
    chosen = next(k for k, v in scores.items() if v["accuracy"] >= best - 1e-12)
    pick = runs[chosen]
    return ({"chosen": pick.mode, "block_s": pick.block_s, "block_hop_s": pick.block_hop_s,
             "rocket_file": pick.rocket_file, "chosen_label": chosen, "candidates": scores, "skipped": skipped,
             "classifier": name, "folds": _block_ranges(fold_trials)}, pick)


def evaluate_selected(train: Sequence[BiotacRecording], test: Sequence[BiotacRecording], cfg: EvalConfig,
                      candidates: Sequence[str], folds: int = SELECTION_FOLDS, blocks: Sequence[float] | None = None,
                      block_hop_s: float = DEFAULT_BLOCK_HOP_S, rockets: Sequence[str] | None = None) -> dict:
    """:func:`select_mode` on the training trials, then :func:`evaluate` once with the chosen mode, blocks and
    transform.

    Returns
    -------
    dict
        :func:`evaluate`'s result with the selection under ``selection``.
    """
    selection, chosen = _select(train, cfg, candidates, folds, blocks, block_hop_s, rockets)
    out = evaluate(train, test, chosen)
    out["selection"] = selection
    return out


def selected_trial_cv(recordings: Sequence[BiotacRecording], cfg: EvalConfig, candidates: Sequence[str],
                      folds: int = 3) -> dict:
    """Cross-validation over trials of a selection: what ``tactile evaluate --select`` scores on unseen trials.

    Each block of trials (:func:`trial_folds`) is the test set once; for each
    classifier of ``cfg`` the mode is chosen among ``candidates`` inside the
    other blocks alone (:func:`evaluate_selected`, by that classifier's
    accuracy), then the block is scored once with the choice.

    Returns
    -------
    dict
        ``folds``, ``candidates`` and per classifier ``accuracy``,
        ``accuracy_std``, ``fold_accuracy`` and ``chosen`` (the mode chosen in each fold).
    """
    blocks, splits = _trial_splits(recordings, folds)
    out: dict = {"folds": _block_ranges(blocks), "candidates": list(candidates), "classifiers": {}}
    for name in cfg.classifiers:
        runs = [evaluate_selected(train, test, replace(cfg, classifiers=(name,)), candidates) for train, test in splits]
        out["classifiers"][name] = {**_fold_summary([r["classifiers"][name]["accuracy"] for r in runs]),
                                    "chosen": [r["selection"]["chosen"] for r in runs]}
    return out
