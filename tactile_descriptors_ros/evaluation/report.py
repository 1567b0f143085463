"""``tactile report``: every experiment of docs/results.md, its tables and plots, in one run.

All runs use the same recordings, the crop rule of :mod:`.windows`, the
development split (train trials 1-20, test trials 21-30 unless the data
has fewer trials: then the first two thirds / last third) and
cross-validation over blocks of trials.  Descriptor banks are cached, so a
second run only repeats the learning.
"""

from __future__ import annotations

import json
import platform
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..datasets.biotac_slide import BiotacRecording, load_recordings
from ..errors import ConfigError
from .classifiers import C_GRID_TEXT
from .experiments import EvalConfig, evaluate, trial_cv
from .windows import format_trials

__all__ = ["ReportPlan", "FULL_PLAN", "QUICK_PLAN", "build_report"]


class ReportPlan:
    """What the report runs (the full plan, or a quick one for tests).

    The last headline mode is the recommended one (its confusion matrix is plotted).

    Attributes mirror the report's sections: headline modes and windows,
    the window-length sweep, the exploration-time test windows, the
    ablation window and modes, CV repeats for the headline and for the
    sweeps, and the number of trial-CV folds.
    """

    def __init__(self, *, headline_modes: Sequence[str], headline_windows: Sequence[str],
                 sweep_modes: Sequence[str], sweep_windows: Sequence[str], exploration_test: Sequence[str],
                 ablation_modes: Sequence[str], ablation_window: str, headline_repeats: int,
                 sweep_repeats: int, cv_folds: int, train_per_trial: int, test_per_trial: int,
                 pa_orders: int) -> None:
        self.headline_modes = tuple(headline_modes)
        self.headline_windows = tuple(headline_windows)
        self.sweep_modes = tuple(sweep_modes)
        self.sweep_windows = tuple(sweep_windows)
        self.exploration_test = tuple(exploration_test)
        self.ablation_modes = tuple(ablation_modes)
        self.ablation_window = ablation_window
        self.headline_repeats = headline_repeats
        self.sweep_repeats = sweep_repeats
        self.cv_folds = cv_folds
        self.train_per_trial = train_per_trial
        self.test_per_trial = test_per_trial
        self.pa_orders = pa_orders


FULL_PLAN = ReportPlan(
    headline_modes=("paper", "combined"),
    headline_windows=("2", "whole"),
    sweep_modes=("paper", "combined"),
    sweep_windows=("0.25", "0.5", "1", "2", "4", "whole"),
    exploration_test=("1", "2", "4", "whole"),
    ablation_modes=("paper", "combined"), ablation_window="2",
    headline_repeats=10, sweep_repeats=2, cv_folds=3, train_per_trial=8, test_per_trial=2, pa_orders=5)

QUICK_PLAN = ReportPlan(
    headline_modes=("paper", "combined"), headline_windows=("1", "whole"),
    sweep_modes=("paper",), sweep_windows=("0.5", "whole"), exploration_test=("0.5", "whole"),
    ablation_modes=("paper",), ablation_window="1",
    headline_repeats=1, sweep_repeats=1, cv_folds=2, train_per_trial=1, test_per_trial=1, pa_orders=1)


def _pct(x: float) -> str:
    return f"{100 * x:.1f}"


def _wlabel(w: str, common_s: float) -> str:
    return f"whole ({common_s:.2f} s)" if w == "whole" else f"{float(w):g} s"


def _split(recs: Sequence[BiotacRecording]) -> tuple[list, list, list[int], list[int]]:
    trials = sorted({r.trial for r in recs})
    if len(trials) < 3:
        raise ConfigError(f"the report needs at least 3 trials per material, found {len(trials)}")
    if trials[-1] >= 30 and 20 in trials:
        tr = [t for t in trials if t <= 20]
        te = [t for t in trials if 21 <= t <= 30]
    else:
        cut = trials[(2 * len(trials)) // 3 - 1]
        tr = [t for t in trials if t <= cut]
        te = [t for t in trials if t > cut]
    return [r for r in recs if r.trial in tr], [r for r in recs if r.trial in te], tr, te


def build_report(data_dir: str | Path, out_dir: str | Path, *, plan: ReportPlan = FULL_PLAN,
                 materials: Sequence[int] | None = None, trials: Sequence[int] | None = None,
                 jobs: int = 2, cache_dir: str | None = "build/cache", progress: bool = True) -> dict:
    """Run every experiment and write ``results.md``, ``results.json`` and ``figures/*.png``.

    Returns
    -------
    dict
        Everything measured (also written to ``<out>/results.json``).
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from tqdm import tqdm

    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    fig_dir = out_dir / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    recs = load_recordings(data_dir, trials=trials, materials=materials)
    train, test, tr_trials, te_trials = _split(recs)
    dev = [r for r in recs if r.trial in set(tr_trials) | set(te_trials)]
    base = EvalConfig(seed=0, train_per_trial=plan.train_per_trial, test_per_trial=plan.test_per_trial,
                      jobs=jobs, cache_dir=cache_dir, progress=progress, pa_orders=plan.pa_orders,
                      cv_repeats=plan.sweep_repeats)
    todo: list[tuple[str, tuple, EvalConfig, str]] = []
    for m in plan.headline_modes:
        for w in plan.headline_windows:
            todo.append(("headline", (m, w), replace(base, mode=m, window=w, classifiers=("svm", "pa", "gmm"),
                                                     cv_repeats=plan.headline_repeats), "split"))
    for m in plan.sweep_modes:
        for w in plan.sweep_windows:
            todo.append(("sweep", (m, w), replace(base, mode=m, window=w, classifiers=("svm", "pa")), "split"))
    train_w = plan.ablation_window
    for m in plan.ablation_modes:
        for w in plan.exploration_test:
            todo.append(("exploration", (m, w), replace(base, mode=m, window=train_w, test_window=w,
                                                        classifiers=("svm", "pa")), "split"))
    abl = replace(base, window=plan.ablation_window, classifiers=("svm", "pa"))
    ablations = [("full descriptor", {})] + [(f"without {q}", {"drop": (q,)}) for q in ("A", "M", "C", "L", "N")] + [
        ("with the contact gate (F_t on tared PDC)", {"gate": True}), ("scaling: none", {"scaling": "none"}),
        ("scaling: standardise only", {"scaling": "standardize"}),
        ("one training window per trial", {"train_per_trial": 1}),
        ("PA: the paper's update (prediction-based, not averaged)", {"pa_update": "prediction", "pa_average": False}),
        ("PA: max-loss update, not averaged", {"pa_average": False}),
        ("PA: prediction-based update, averaged", {"pa_update": "prediction"})]
    # combined = per_channel + bands + levels + baseline: leave groups out
    ablations_groups = [("without the baseline statistics (multiband_levels)", {"mode": "multiband_levels"}),
                        ("without baseline and levels (multiband)", {"mode": "multiband"}),
                        ("per-channel descriptor only (per_channel)", {"mode": "per_channel"}),
                        ("+ successive pieces: mean and sd over 4 x 0.5 s (combined_subwindows)",
                         {"mode": "combined_subwindows"})]
    for m in plan.ablation_modes:
        for name, kw in ablations:
            only_pa = {"classifiers": ("pa",)} if name.startswith("PA:") else {}  # the SVM is unchanged
            todo.append(("ablation", (m, name), replace(abl, mode=m, **kw, **only_pa), "split"))
    if "combined" in plan.ablation_modes:
        for name, kw in ablations_groups:
            todo.append(("ablation", ("combined", name), replace(abl, **kw), "split"))
    todo.append(("ablation", ("baseline", "related-work baseline features"), replace(abl, mode="baseline"),
                 "split"))
    for m in plan.ablation_modes:
        todo.append(("trial_cv", (m, plan.ablation_window), replace(abl, mode=m), "cv"))

    results: dict = {"headline": {}, "sweep": {}, "exploration": {}, "ablation": {}, "trial_cv": {}}
    bar = tqdm(todo, desc="report", unit="run", disable=not progress)
    for section, key, cfg, kind in bar:
        bar.set_postfix_str(f"{section} {key}")
        cfg = replace(cfg, progress=False)
        res = evaluate(train, test, cfg) if kind == "split" else trial_cv(dev, cfg, plan.cv_folds)
        results[section][key] = res
    bar.close()
    runtime_s = time.perf_counter() - t_start
    any_res = next(iter(results["headline"].values()))
    common_s = any_res["common_length_s"]

    # ---------------------------------------------------------------- figures
    figs = {}
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    for m in plan.sweep_modes:
        xs = [results["sweep"][(m, w)]["test_window_frames"] / 100.0 for w in plan.sweep_windows]
        ax.plot(xs, [100 * results["sweep"][(m, w)]["classifiers"]["svm"]["accuracy"] for w in plan.sweep_windows],
                "o-", label=f"SVM, {m}")
        ax.plot(xs, [100 * results["sweep"][(m, w)]["classifiers"]["pa"]["accuracy"] for w in plan.sweep_windows],
                "s--", label=f"PA-I, {m}", alpha=0.7)
    ax.set_xlabel("window length (s)")
    ax.set_ylabel("test accuracy (%)")
    ax.set_title("Accuracy against window length (train trials {}, test {})".format(
        format_trials(tr_trials), format_trials(te_trials)), fontsize=9)
    figs["accuracy_vs_window"] = _save_figure(fig, fig_dir / "accuracy_vs_window.png", ax=ax, legend_size=7)

    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    for m in plan.sweep_modes:
        xs = [results["sweep"][(m, w)]["test_window_frames"] / 100.0 for w in plan.sweep_windows]
        ax.plot(xs, [1e3 * results["sweep"][(m, w)]["descriptor_s_per_window"] for w in plan.sweep_windows],
                "o-", label=f"descriptor, {m}")
    ax.set_xlabel("window length (s)")
    ax.set_ylabel("descriptor time per window (ms)")
    figs["time_vs_window"] = _save_figure(fig, fig_dir / "time_vs_window.png", ax=ax, legend_size=7)

    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    for m in plan.ablation_modes:
        xs = [results["exploration"][(m, w)]["test_window_frames"] / 100.0 for w in plan.exploration_test]
        ax.plot(xs, [100 * results["exploration"][(m, w)]["classifiers"]["svm"]["accuracy"]
                     for w in plan.exploration_test], "o-", label=f"SVM, {m}")
    ax.set_xlabel(f"test window length (s); trained on {plan.ablation_window} s windows")
    ax.set_ylabel("test accuracy (%)")
    figs["exploration_time"] = _save_figure(fig, fig_dir / "exploration_time.png", ax=ax, legend_size=7)

    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    for (m, w), res in results["headline"].items():
        c = res["classifiers"]["pa"]["curve"]
        acc, sd = np.array(c["accuracy"]) * 100, np.array(c["accuracy_std"]) * 100
        ax.plot(c["n_per_class"], acc, label=f"{m}, {_wlabel(w, common_s)}")
        ax.fill_between(c["n_per_class"], acc - sd, acc + sd, alpha=0.15)
    ax.set_xlabel("training trials per class seen (online)")
    ax.set_ylabel("test accuracy (%)")
    ax.set_title("Online PA-I learning curves", fontsize=9)
    figs["pa_curves"] = _save_figure(fig, fig_dir / "pa_curves.png", ax=ax, legend_size=6)

    best_key = (plan.headline_modes[-1], plan.headline_windows[0])  # the recommended mode comes last
    res = results["headline"][best_key]
    cm = np.array(res["classifiers"]["svm"]["confusion"])
    fig, ax = plt.subplots(figsize=(6.4, 5.6))
    ax.imshow(cm, cmap="Blues")
    ax.set_xticks(range(len(res["classes"])), [f"{c}" for c in res["classes"]], fontsize=6)
    ax.set_yticks(range(len(res["classes"])), [f"{c} {n}" for c, n in zip(res["classes"], res["class_names"])],
                  fontsize=6)
    for i in range(cm.shape[0]):
        for j in range(cm.shape[1]):
            if cm[i, j]:
                ax.text(j, i, str(cm[i, j]), ha="center", va="center", fontsize=5,
                        color="white" if cm[i, j] > cm.max() / 2 else "black")
    ax.set_xlabel("predicted")
    ax.set_title(f"SVM confusion, {best_key[0]}, {_wlabel(best_key[1], common_s)}", fontsize=9)
    figs["confusion"] = _save_figure(fig, fig_dir / "confusion_svm.png")

    # ---------------------------------------------------------------- markdown
    md = _markdown(results, plan, tr_trials, te_trials, common_s, runtime_s, figs, out_dir, data_dir, recs)
    (out_dir / "results.md").write_text(md)
    serial = {sec: {" | ".join(k): v for k, v in d.items()} for sec, d in results.items()}
    serial["runtime_s"] = runtime_s
    (out_dir / "results.json").write_text(json.dumps(serial, indent=1, default=_json_default))
    return serial


def _save_figure(fig, path: Path, *, ax=None, legend_size: int | None = None) -> Path:
    """Grid and legend on ``ax`` (if given), tight layout, write ``path`` as PNG and close the figure."""
    import matplotlib.pyplot as plt

    if ax is not None:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=legend_size)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _json_default(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def _markdown(results: dict, plan: ReportPlan, tr: list[int], te: list[int], common_s: float,
              runtime_s: float, figs: dict, out_dir: Path, data_dir, recs) -> str:
    n_mat = len({r.material for r in recs})
    rel = {k: v.relative_to(out_dir).as_posix() for k, v in figs.items()}
    L: list[str] = []
    a = L.append
    a("# Results on real BioTac recordings")
    a("")
    a("Generated by `tactile report --data DIR --out docs` (`make report`); do not edit by hand. "
      f"Runtime of this run: {runtime_s / 60:.1f} min on {platform.machine()} "
      "(descriptor banks are cached in build/cache; a second run only repeats the learning). "
      "How the protocols work and why: [evaluation.md](evaluation.md).")
    a("")
    a(f"Data: {n_mat} materials, trials {format_trials(sorted({r.trial for r in recs}))} of the BioTac "
      "sliding recordings (one finger, PAC 2.2 kHz, 19 electrodes 100 Hz). Development split: train "
      f"trials {format_trials(tr)}, test trials {format_trials(te)}. Every trial is cropped to the "
      f"common length ({common_s:.2f} s) so that duration cannot give the class away; windows are drawn at "
      f"seeded random positions inside the crop ({plan.train_per_trial} per training trial, "
      f"{plan.test_per_trial} per test trial; a whole-trial window is the crop itself). "
      f"SVM: linear, C chosen over {C_GRID_TEXT} by 5-fold CV (folds keep a trial's windows together) repeated "
      f"{plan.headline_repeats} times for the headline table and {plan.sweep_repeats} times for sweeps and "
      "ablations, refit on all training windows; scaling log1p(Activity) + standardisation fitted on the "
      "training set. PA-I: the core's OnlineClassifier (running scaling), one pass over the training windows "
      "in trial order, max-loss update with averaged weights unless the ablation says otherwise (the paper's "
      "prediction-based update is an ablation row), curve averaged over "
      f"{plan.pa_orders} presentation orders. GMM: spherical, k = {n_mat}, k-means init with 20 restarts, "
      "100 EM iterations, NMI (arithmetic) on the test windows. The contact gate is off unless an ablation "
      "row says otherwise: every recorded trial is a slide in contact, and the gate, fed by PDC that the "
      "recording setup tared and clipped at 0, misfires on soft materials.")
    a("")
    a("Descriptor modes: `paper` = eq. 17, electrodes averaged (8 values); `per_channel` = the same quantities "
      "per electrode (98); `multiband` = per_channel + Hjorth A/M/C of PAC in 6 bands (116); "
      "`multiband_levels` = multiband + mean electrode/PDC/TDC/TAC levels (138); `baseline` = related-work "
      "statistics (log variance, skewness, kurtosis, log band powers of PAC and electrodes; 123); "
      "`combined` = multiband_levels + baseline (261, the default of `tactile evaluate`); "
      "`combined_subwindows` = combined + mean and standard deviation of the per_channel and band values "
      "over the window's 4 successive pieces (493).")
    a("")
    a("## Headline (development split)")
    a("")
    a("| mode | window | values | SVM acc % | SVM C | SVM CV acc % | PA-I acc % (all train trials) | "
      "GMM NMI | GMM acc % |")
    a("|---|---|---|---|---|---|---|---|---|")
    for (m, w), r in results["headline"].items():
        c = r["classifiers"]
        a(f"| {m} | {_wlabel(w, common_s)} | {r['n_features']} | {_pct(c['svm']['accuracy'])} | "
          f"{c['svm']['best_c']:g} | {_pct(c['svm']['cv_accuracy'])} | {_pct(c['pa']['accuracy'])} | "
          f"{c['gmm']['nmi']:.3f} | {_pct(c['gmm']['accuracy'])} |")
    a("")
    a(f"![PA-I learning curves]({rel['pa_curves']})  ![SVM confusion]({rel['confusion']})")
    a("")
    a("## Accuracy against window length")
    a("")
    a("Train and test on windows of the same length (development split). Times: descriptor = median compute "
      "time of the mode's features per window (core `cell_features` + reductions, plus band filtering for "
      "multiband); SVM update = one refit on all training windows with the chosen C; predictions are single "
      "windows; PA update = one scaling + PA-I step.")
    a("")
    a("| mode | window | SVM acc % | PA-I acc % | descriptor ms/window | SVM refit s | SVM predict ms | "
      "PA update us | PA predict us |")
    a("|---|---|---|---|---|---|---|---|---|")
    for (m, w), r in results["sweep"].items():
        s, p = r["classifiers"]["svm"], r["classifiers"]["pa"]
        a(f"| {m} | {_wlabel(w, common_s)} | {_pct(s['accuracy'])} | {_pct(p['accuracy'])} | "
          f"{1e3 * r['descriptor_s_per_window']:.2f} | {s['fit_s']:.2f} | {1e3 * s['predict_s']:.2f} | "
          f"{1e6 * p['update_s']:.0f} | {1e6 * p['predict_s']:.0f} |")
    a("")
    a(f"![accuracy vs window]({rel['accuracy_vs_window']})  ![time vs window]({rel['time_vs_window']})")
    a("")
    a("## Exploration-time robustness")
    a("")
    a(f"Train on {plan.ablation_window} s windows, test on windows of other lengths (random positions).")
    a("")
    a("| mode | test window | SVM acc % | PA-I acc % |")
    a("|---|---|---|---|")
    for (m, w), r in results["exploration"].items():
        a(f"| {m} | {_wlabel(w, common_s)} | {_pct(r['classifiers']['svm']['accuracy'])} | "
          f"{_pct(r['classifiers']['pa']['accuracy'])} |")
    a("")
    a(f"![exploration time]({rel['exploration_time']})")
    a("")
    a(f"## Ablations ({plan.ablation_window} s windows, development split)")
    a("")
    a("Concatenated vs pooled body parts is moot here: the data has one finger, so both layouts give the "
      "same vector. PA rows change only the online learner.")
    a("")
    a("| mode | variant | values | SVM acc % | PA-I acc % |")
    a("|---|---|---|---|---|")
    for (m, name), r in results["ablation"].items():
        svm = _pct(r["classifiers"]["svm"]["accuracy"]) if "svm" in r["classifiers"] else "(unchanged)"
        a(f"| {m} | {name} | {r['n_features']} | {svm} | {_pct(r['classifiers']['pa']['accuracy'])} |")
    a("")
    a(f"## Cross-validation over trials ({plan.ablation_window} s windows)")
    a("")
    a(f"Trials {format_trials(sorted(set(tr) | set(te)))} in {plan.cv_folds} contiguous blocks; each block is the "
      "test set once, the model is trained on the others.")
    a("")
    a("| mode | folds | SVM acc % (mean +- sd) | PA-I acc % (mean +- sd) |")
    a("|---|---|---|---|")
    for (m, w), r in results["trial_cv"].items():
        s, p = r["classifiers"]["svm"], r["classifiers"]["pa"]
        folds = ", ".join(f"{a_}-{b}" for a_, b in r["folds"])
        a(f"| {m} | {folds} | {_pct(s['accuracy'])} +- {_pct(s['accuracy_std'])} | "
          f"{_pct(p['accuracy'])} +- {_pct(p['accuracy_std'])} |")
    a("")
    return "\n".join(L) + "\n"
