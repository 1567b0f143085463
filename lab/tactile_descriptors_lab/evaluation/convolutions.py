"""How far the convolution features take recognition: 1 s windows with the SVM, 2 s windows online.

The report's other sections score the shipped groups.  This one scores the
``rocket`` group (random convolutions with the biases of
``config/rocket/<cell type>.json``) joined to them, where the shipped groups
stop short of the data:

* **1 s windows, linear SVM**: every mode of :attr:`ConvolutionPlan.svm_modes`
  (``plain``, ``combined``, ``combined_rocket``) on the development split and
  by cross-validation over blocks of trials, and the choice among them made
  inside the training trials (``tactile evaluate --select``, :func:`~.experiments.select_mode`), which
  scores the test split once;
* **2 s windows, the online learner** (the classifier node's default, one
  pass): every mode of :attr:`ConvolutionPlan.online_modes` with each block
  length of :attr:`ConvolutionPlan.online_blocks` (1 s blocks, and one
  descriptor per window), the same way, and the choice among the pairs
  (``--select ... --select-blocks 1,0``).

The test split never takes part in a choice.  The candidates not chosen are
scored beside the choice, on the same windows, to show what the selection
leaves on the table; they choose nothing.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

from tactile_descriptors_lab.datasets.recording import BiotacRecording
from tactile_descriptors_lab.evaluation.bank import recordings_cell_type
from tactile_descriptors_lab.evaluation.experiments import (
    DEFAULT_BLOCK_HOP_S,
    EvalConfig,
    evaluate,
    select_mode,
    selection_candidates,
    trial_cv,
)
from tactile_descriptors_ros.core.groups import rocket_parameters_path

__all__ = ["ConvolutionPlan", "FULL_CONVOLUTIONS", "QUICK_CONVOLUTIONS", "evaluate_convolutions",
           "transform_description"]


@dataclass(frozen=True)
class ConvolutionPlan:
    """What :func:`evaluate_convolutions` runs.

    Attributes
    ----------
    svm_window : str
        The SVM's window (train and test), seconds.
    svm_train_per_trial : int
        Training windows drawn per trial for the SVM.
    svm_modes : tuple of str
        Modes scored with the SVM, and the candidates of its selection (ties
        go to the one listed first).
    svm_c_grid : tuple of float
        The SVM's C candidates (chosen by 5-fold CV on the training windows).
    svm_cv_repeats : int
        Repeats of that 5-fold CV.
    online_window : str
        The online learner's window, seconds.
    online_train_per_trial : int
        Training windows per trial for the online learner (one pass).
    online_modes : tuple of str
        Modes scored online, and the candidates of its selection.
    online_blocks : tuple of float
        Block lengths crossed with ``online_modes`` (seconds; 0 = one
        descriptor per window).
    folds : int
        Blocks of trials of the cross-validation beside the development split.
    """

    svm_window: str = "1"
    svm_train_per_trial: int = 16
    svm_modes: tuple[str, ...] = ("plain", "combined", "combined_rocket")
    svm_c_grid: tuple[float, ...] = (3.0 ** -4, 0.0625, 0.25, 1.0)
    svm_cv_repeats: int = 1
    online_window: str = "2"
    online_train_per_trial: int = 8
    online_modes: tuple[str, ...] = ("combined", "combined_rocket")
    online_blocks: tuple[float, ...] = (1.0, 0.0)
    folds: int = 3


#: The report's plan: the windows, draws and candidates ``lab/docs/evaluation.md`` describes.
FULL_CONVOLUTIONS = ConvolutionPlan()

#: A plan for tests and smoke runs (three materials, a dozen trials).
QUICK_CONVOLUTIONS = ConvolutionPlan(svm_train_per_trial=2, svm_modes=("plain", "combined_rocket"),
                                     svm_c_grid=(0.0625, 1.0), online_train_per_trial=2,
                                     online_modes=("combined_rocket",), folds=2)


def transform_description(recordings: Sequence[BiotacRecording]) -> dict:
    """The transform file of the recordings' cell type: its ``file`` name and the ``description`` it holds
    (``tactile fit-rocket`` records the recordings, classes, trials and seed it was fitted on)."""
    path = rocket_parameters_path(recordings_cell_type(recordings))
    return {"file": path.name, "description": json.loads(path.read_text()).get("description", "no description")}


def _split_row(res: dict, name: str) -> dict:
    """What the report keeps of one :func:`~.experiments.evaluate` result: the accuracy, its spread over
    presentation orders (online) and the C chosen (SVM)."""
    c = res["classifiers"][name]
    row = {"accuracy": c["accuracy"], "n_features": res["n_features"], "n_train": res["n_train"],
           "n_test": res["n_test"]}
    if "curve" in c:
        row["accuracy_std"] = c["curve"]["accuracy_std"][-1]
        row["orders"] = c["curve"]["orders"]
    if "best_c" in c:
        row["best_c"] = c["best_c"]
    return row


def _setting(train: Sequence[BiotacRecording], test: Sequence[BiotacRecording],
             dev: Sequence[BiotacRecording], cfg: EvalConfig, modes: Sequence[str],
             blocks: Sequence[float] | None, folds: int, progress: Callable[[str], None]) -> dict:
    """One classifier's candidates, each on the development split and by trial CV, and the choice among them
    made inside the training trials, scored once on the test split."""
    name = cfg.classifiers[0]
    runs, skipped = selection_candidates(cfg, modes, blocks, DEFAULT_BLOCK_HOP_S)
    out: dict = {"classifier": name, "window": cfg.window, "train_per_trial": cfg.train_per_trial,
                 "candidates": {}, "skipped": skipped}
    if name == "svm":
        out.update(c_grid=list(cfg.c_grid), cv_folds=cfg.cv_folds, cv_repeats=cfg.cv_repeats)
    for label, run in runs.items():
        progress(f"{name} {label}")
        cv = trial_cv(dev, run, folds)
        out["candidates"][label] = {"mode": run.mode, "block_s": run.block_s,
                                    "split": _split_row(evaluate(train, test, run), name),
                                    "cv": {"folds": cv["folds"], **cv["classifiers"][name]}}
    progress(f"{name} selection")
    sel = select_mode(train, cfg, modes, blocks=blocks, block_hop_s=DEFAULT_BLOCK_HOP_S)
    # the choice is one of the candidates above, with the same configuration, windows and seeds: its score on the
    # test split is that candidate's development-split row (what evaluate_selected would compute once more)
    out["selection"] = {"chosen_label": sel["chosen_label"], "folds": sel["folds"],
                        "inner": {k: {"accuracy": v["accuracy"], "accuracy_std": v["accuracy_std"],
                                      "fold_accuracy": v["fold_accuracy"]} for k, v in sel["candidates"].items()},
                        "test": out["candidates"][sel["chosen_label"]]["split"]}
    return out


def evaluate_convolutions(train: Sequence[BiotacRecording], test: Sequence[BiotacRecording],
                          dev: Sequence[BiotacRecording], base: EvalConfig,
                          plan: ConvolutionPlan = FULL_CONVOLUTIONS,
                          progress: Callable[[str], None] | None = None) -> dict[str, dict]:
    """Score the convolution group beside the shipped ones at 1 s (SVM) and 2 s (online).

    Parameters
    ----------
    train, test : sequence of BiotacRecording
        The development split (training and test trials).
    dev : sequence of BiotacRecording
        The trials of the cross-validation (its blocks are contiguous runs of trials).
    base : EvalConfig
        Seeds, test windows per trial, presentation orders, jobs and cache;
        windows, draws, modes and classifiers come from ``plan``.
    plan : ConvolutionPlan
    progress : callable, optional
        Called with a short text before each run.

    Returns
    -------
    dict
        ``{"svm": ..., "online": ...}``: per setting ``classifier``, ``window``,
        ``train_per_trial``, ``candidates`` (per label: ``mode``, ``block_s``,
        ``split`` = the development split's ``accuracy`` and, online, its
        ``accuracy_std`` over orders; ``cv`` = the trial CV's ``accuracy``,
        ``accuracy_std``, ``fold_accuracy`` and ``folds``), ``skipped`` and
        ``selection`` (``chosen_label``, the ``inner`` accuracies it chose by
        and the ``test`` split's score of the choice), and ``transform``
        (:func:`transform_description`).
    """
    say = progress or (lambda _text: None)
    svm = replace(base, window=plan.svm_window, train_per_trial=plan.svm_train_per_trial, classifiers=("svm",),
                  c_grid=tuple(plan.svm_c_grid), cv_repeats=plan.svm_cv_repeats, test_window=None)
    online = replace(base, window=plan.online_window, train_per_trial=plan.online_train_per_trial,
                     classifiers=("pa",), test_window=None)
    about = {"transform": transform_description(train)}
    return {"svm": {**_setting(train, test, dev, svm, plan.svm_modes, None, plan.folds, say), **about},
            "online": {**_setting(train, test, dev, online, plan.online_modes, plan.online_blocks, plan.folds, say),
                       **about}}
