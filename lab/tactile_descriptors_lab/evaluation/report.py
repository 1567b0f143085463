"""``tactile report``: every experiment of lab/docs/results.md, its tables and plots, in one run.

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

from tactile_descriptors_lab.datasets.biotac_slide import BiotacRecording, load_recordings
from tactile_descriptors_lab.evaluation.across_datasets import (
    FLOOR_MODE,
    FULL_DATASETS,
    QUICK_DATASETS,
    DatasetPlan,
    default_at_least_floor,
    evaluate_datasets,
)
from tactile_descriptors_lab.evaluation.bank import BANK_VERSION, DEFAULT_MODE
from tactile_descriptors_lab.evaluation.classifiers import C_GRID_TEXT
from tactile_descriptors_lab.evaluation.convolutions import (
    FULL_CONVOLUTIONS,
    QUICK_CONVOLUTIONS,
    ConvolutionPlan,
    evaluate_convolutions,
)
from tactile_descriptors_lab.evaluation.experiments import (
    DEFAULT_BLOCK_S,
    EvalConfig,
    evaluate,
    evaluate_many,
    trial_cv,
)
from tactile_descriptors_lab.evaluation.sampling import format_trials, is_length_range
from tactile_descriptors_ros.core.learning import RECOMMENDED_PA_AVERAGE, RECOMMENDED_PA_UPDATE
from tactile_descriptors_ros.errors import ConfigError

__all__ = ["ReportPlan", "FULL_PLAN", "QUICK_PLAN", "SECTIONS", "LENGTH_SECTIONS", "FEATURE_DEFINITION",
           "section_provenance", "build_report", "render_markdown", "README_BEGIN", "README_END",
           "what_to_expect", "update_readme"]

#: Sections of results.json, in report order.
SECTIONS: tuple[str, ...] = ("headline", "sweep", "length", "length_cv", "short", "ablation", "trial_cv",
                             "datasets", "convolutions")

#: The sections ``tactile report --only length`` recomputes (the rest is kept from results.json).
LENGTH_SECTIONS: tuple[str, ...] = ("length", "length_cv", "short")

#: How this release computes the feature groups, as a section's provenance records it: a section of
#: results.json measured with another definition is rendered with a warning naming its date and definition.
FEATURE_DEFINITION: str = (f"feature bank v{BANK_VERSION}: bands and band powers from one FFT per channel "
                           "over the window's last fast-length samples (core/features.py)")


def section_provenance(date: str | None = None) -> dict:
    """What a section recomputed now records: the UTC date and :data:`FEATURE_DEFINITION`."""
    import datetime

    day = date or datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d")
    return {"date": day, "features": FEATURE_DEFINITION}


class ReportPlan:
    """What the report runs (the full plan, or a quick one for tests).

    The last headline mode is the recommended one (its confusion matrix is plotted).

    Attributes mirror the report's sections: headline modes and windows,
    the window-length sweep, the ablation window and modes, CV repeats for
    the headline and for the sweeps, the number of trial-CV folds, and the
    touch-length section: its variants ``(label, mode, block_s)`` (the first
    is the default, also scored by trial CV and on short windows;
    ``block_s`` None = one descriptor of the whole window; C chosen by
    ``length_repeats`` repeats of the 5-fold CV), the test windows of a model trained on
    ``ablation_window`` windows (a range such as ``"1-6"`` draws random
    lengths), the test windows of its trial CV, and the short windows
    scored with train and test of the same length (the training length
    itself is read from the touch-length table: the same model) with
    ``short_train_per_trial`` training windows per trial (None: the
    evaluation's default, :func:`~.windows.default_train_windows`).
    ``trial_cv_modes`` are scored by trial cross-validation at the ablation
    window (default: the ablation modes); the full plan adds ``plain`` (mean,
    sd, min, max of every channel), the floor the shipped groups must clear.
    ``datasets`` plans the table across data sets, ``convolutions`` the
    section on the ``rocket`` group (1 s SVM, 2 s online).
    """

    def __init__(self, *, headline_modes: Sequence[str], headline_windows: Sequence[str],
                 sweep_modes: Sequence[str], sweep_windows: Sequence[str],
                 length_variants: Sequence[tuple[str, str, float | None]],
                 length_tests: Sequence[str], length_cv_tests: Sequence[str], short_windows: Sequence[str],
                 ablation_modes: Sequence[str], ablation_window: str, headline_repeats: int,
                 sweep_repeats: int, cv_folds: int, train_per_trial: int, test_per_trial: int,
                 pa_orders: int, length_repeats: int = 1, short_train_per_trial: int | None = None,
                 trial_cv_modes: Sequence[str] | None = None, datasets: DatasetPlan = FULL_DATASETS,
                 convolutions: ConvolutionPlan = FULL_CONVOLUTIONS) -> None:
        self.headline_modes = tuple(headline_modes)
        self.headline_windows = tuple(headline_windows)
        self.sweep_modes = tuple(sweep_modes)
        self.sweep_windows = tuple(sweep_windows)
        self.length_variants = tuple(tuple(v) for v in length_variants)
        self.length_tests = tuple(length_tests)
        self.length_cv_tests = tuple(length_cv_tests)
        self.short_windows = tuple(short_windows)
        self.length_repeats = length_repeats
        self.short_train_per_trial = short_train_per_trial
        self.ablation_modes = tuple(ablation_modes)
        self.ablation_window = ablation_window
        self.trial_cv_modes = tuple(self.ablation_modes if trial_cv_modes is None else trial_cv_modes)
        self.headline_repeats = headline_repeats
        self.sweep_repeats = sweep_repeats
        self.cv_folds = cv_folds
        self.train_per_trial = train_per_trial
        self.test_per_trial = test_per_trial
        self.pa_orders = pa_orders
        self.datasets = datasets
        self.convolutions = convolutions


FULL_PLAN = ReportPlan(
    headline_modes=("paper", "combined"),
    headline_windows=("2", "whole"),
    sweep_modes=("paper", "combined"),
    sweep_windows=("0.25", "0.5", "1", "2", "4", "whole"),
    length_variants=((DEFAULT_MODE, DEFAULT_MODE, DEFAULT_BLOCK_S),
                     (f"{DEFAULT_MODE}, whole-window descriptor", DEFAULT_MODE, None),
                     ("paper", "paper", DEFAULT_BLOCK_S)),
    length_tests=("1", "2", "4", "whole", "1-6"),
    length_cv_tests=("2", "1-6"), short_windows=("0.5", "1"), length_repeats=1,
    ablation_modes=("paper", "combined"), ablation_window="2", trial_cv_modes=("paper", "combined", "plain"),
    headline_repeats=10, sweep_repeats=2, cv_folds=3, train_per_trial=8, test_per_trial=2, pa_orders=5)

QUICK_PLAN = ReportPlan(
    headline_modes=("paper", "combined"), headline_windows=("1", "whole"),
    sweep_modes=("paper",), sweep_windows=("0.5", "whole"),
    length_variants=((DEFAULT_MODE, DEFAULT_MODE, DEFAULT_BLOCK_S), ("window", DEFAULT_MODE, None)),
    length_tests=("1", "0.5-2"), length_cv_tests=("1", "0.5-2"),
    short_windows=("0.5",), short_train_per_trial=1,
    ablation_modes=("paper",), ablation_window="1", trial_cv_modes=("paper", "plain"),
    headline_repeats=1, sweep_repeats=1, cv_folds=2, train_per_trial=1, test_per_trial=1, pa_orders=1,
    datasets=QUICK_DATASETS, convolutions=QUICK_CONVOLUTIONS)


def _pct(x: float) -> str:
    return f"{100 * x:.1f}"


def _wlabel(w: str, common_s: float) -> str:
    if w == "whole":
        return f"whole ({common_s:.2f} s)"
    if is_length_range(w):
        lo, hi = (float(x) for x in w.split("-"))
        return f"random {lo:g}-{hi:g} s"
    return f"{float(w):g} s"


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


#: What each online update is called in the report's text: its name, and what it is.
ONLINE_UPDATE_NAMES = {"arow": ("AROW", " (second-order, one shared covariance)"),
                       "max_loss": ("PA-I, Crammer et al.'s max-loss update", ""),
                       "prediction": ("PA-I, the paper's prediction-based update", " (eq. 30-32)")}


def online_learner_name(update: str = RECOMMENDED_PA_UPDATE, average: bool = RECOMMENDED_PA_AVERAGE,
                        short: bool = False) -> str:
    """The online learner a result's ``pa_update`` / ``pa_average`` configure, as the report names it
    (``short``: its name without the explanation in brackets)."""
    name, what = ONLINE_UPDATE_NAMES[update]
    return name + ("" if short else what) + (", averaged weights" if average else "")


def _online_of(serial: dict, short: bool = False) -> str:
    """The online learner of the headline results (the shipped one unless a plan said otherwise)."""
    for r in serial.get("headline", {}).values():
        cfg = r.get("config", {})
        if "pa_update" in cfg:
            return online_learner_name(cfg["pa_update"], bool(cfg.get("pa_average")), short)
    return online_learner_name(short=short)


def _keyed(d: dict) -> dict:
    """results.json's ``"a | b"`` keys of one section as tuples."""
    return {tuple(k.split(" | ")): v for k, v in d.items()}


def build_report(data_dir: str | Path, out_dir: str | Path, *, plan: ReportPlan = FULL_PLAN,
                 materials: Sequence[int] | None = None, trials: Sequence[int] | None = None,
                 jobs: int = 2, cache_dir: str | None = "build/cache", progress: bool = True,
                 only: Sequence[str] | None = None) -> dict:
    """Run the experiments and write ``results.md``, ``results.json`` and ``figures/*.png``.

    Parameters
    ----------
    only : sequence of str, optional
        Recompute only these sections (:data:`SECTIONS`); the others are
        read from the existing ``<out>/results.json`` and ``results.md`` is
        rendered again from the merged results.  ``None`` runs everything.

    Returns
    -------
    dict
        Everything measured (also written to ``<out>/results.json``).
    """
    import matplotlib
    matplotlib.use("Agg")
    from tqdm import tqdm

    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    fig_dir = out_dir / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    wanted = tuple(SECTIONS if only is None else only)
    unknown = sorted(set(wanted) - set(SECTIONS))
    if unknown:
        raise ConfigError(f"unknown report section(s) {unknown}; choose from {', '.join(SECTIONS)}", key="only")
    previous: dict = {}
    if only is not None:
        path = out_dir / "results.json"
        if not path.is_file():
            raise ConfigError(f"{path}: no earlier report to complete; run the full report first", key="only")
        previous = json.loads(path.read_text())
    recs = load_recordings(data_dir, trials=trials, materials=materials)
    train, test, tr_trials, te_trials = _split(recs)
    dev = [r for r in recs if r.trial in set(tr_trials) | set(te_trials)]
    base = EvalConfig(seed=0, train_per_trial=plan.train_per_trial, test_per_trial=plan.test_per_trial,
                      jobs=jobs, cache_dir=cache_dir, progress=progress, pa_orders=plan.pa_orders,
                      cv_repeats=plan.sweep_repeats)
    # (section, key, config, kind): kind "split" = one evaluation; "many" = one training scored on several
    # test windows (key[1] lists them); "cv" / "cv_many" the same by trial cross-validation
    todo: list[tuple[str, tuple, EvalConfig, str]] = []
    for m in plan.headline_modes:
        for w in plan.headline_windows:
            todo.append(("headline", (m, w), replace(base, mode=m, window=w, classifiers=("svm", "pa", "gmm"),
                                                     cv_repeats=plan.headline_repeats), "split"))
    for m in plan.sweep_modes:
        for w in plan.sweep_windows:
            todo.append(("sweep", (m, w), replace(base, mode=m, window=w, classifiers=("svm", "pa")), "split"))
    train_w = plan.ablation_window
    for label, m, block in plan.length_variants:
        todo.append(("length", (label, plan.length_tests),
                     replace(base, mode=m, window=train_w, block_s=block, classifiers=("svm", "pa"),
                             cv_repeats=plan.length_repeats), "many"))
    if plan.length_variants:
        label, m, block = plan.length_variants[0]
        first = replace(base, mode=m, block_s=block, classifiers=("svm", "pa"), cv_repeats=plan.length_repeats)
        todo.append(("length_cv", (label, plan.length_cv_tests), replace(first, window=train_w), "cv_many"))
        for w in plan.short_windows:
            if w != train_w:  # the training length's row is the touch-length table's (same model)
                todo.append(("short", (label, w), replace(first, window=w, train_per_trial=plan.short_train_per_trial),
                             "split"))
    abl = replace(base, window=plan.ablation_window, classifiers=("svm", "pa"))
    ablations = [("full descriptor", {})] + [(f"without {q}", {"drop": (q,)}) for q in ("A", "M", "C", "L", "N")] + [
        ("with the contact gate (F_t on tared PDC)", {"gate": True}), ("scaling: none", {"scaling": "none"}),
        ("scaling: standardise only", {"scaling": "standardize"}),
        ("one training window per trial", {"train_per_trial": 1}),
        *[(f"online: {online_learner_name(u, av)}", {"pa_update": u, "pa_average": av})
          for u, av in (("prediction", False), ("max_loss", False), ("max_loss", True))]]
    # combined = per_channel + bands + levels + baseline: leave groups out
    ablations_groups = [("without the baseline statistics (multiband_levels)", {"mode": "multiband_levels"}),
                        ("without baseline and levels (multiband)", {"mode": "multiband"}),
                        ("per-channel descriptor only (per_channel)", {"mode": "per_channel"}),
                        ("+ successive pieces: mean and sd over 4 x 0.5 s (combined_subwindows, one descriptor "
                         "per window)", {"mode": "combined_subwindows", "block_s": None})]
    for m in plan.ablation_modes:
        for name, kw in ablations:
            only_pa = {"classifiers": ("pa",)} if name.startswith("online:") else {}  # the SVM is unchanged
            todo.append(("ablation", (m, name), replace(abl, mode=m, **kw, **only_pa), "split"))
    if "combined" in plan.ablation_modes:
        for name, kw in ablations_groups:
            todo.append(("ablation", ("combined", name), replace(abl, **kw), "split"))
    todo.append(("ablation", ("baseline", "related-work baseline features"), replace(abl, mode="baseline"),
                 "split"))
    for m in plan.trial_cv_modes:
        todo.append(("trial_cv", (m, plan.ablation_window), replace(abl, mode=m), "cv"))
    todo.append(("datasets", ("every layout",), abl, "datasets"))
    todo.append(("convolutions", ("1 s SVM and 2 s online",), base, "convolutions"))
    todo = [t for t in todo if t[0] in wanted]

    results: dict = {sec: {} for sec in wanted}
    bar = tqdm(todo, desc="report", unit="run", disable=not progress)
    for section, key, cfg, kind in bar:
        bar.set_postfix_str(f"{section} {key[0]}")
        cfg = replace(cfg, progress=False)
        if kind == "split":
            results[section][key] = evaluate(train, test, cfg)
        elif kind == "cv":
            results[section][key] = trial_cv(dev, cfg, plan.cv_folds)
        elif kind == "datasets":
            import tempfile

            with tempfile.TemporaryDirectory(prefix="tactile_report_datasets_") as tmp:
                rows = evaluate_datasets(dev, tmp, cfg, plan.datasets,
                                         progress=lambda text: bar.set_postfix_str(f"datasets {text}"))
            for name, row in rows.items():
                results[section][(name,)] = row
        elif kind == "convolutions":
            rows = evaluate_convolutions(train, test, dev, cfg, plan.convolutions,
                                         progress=lambda text: bar.set_postfix_str(f"convolutions {text}"))
            for name, row in rows.items():
                results[section][(name,)] = row
        elif kind == "many":
            for w, res in evaluate_many(train, test, cfg, key[1]).items():
                results[section][(key[0], w)] = res
        else:
            cv = trial_cv(dev, cfg, plan.cv_folds, test_windows=key[1])
            for w, res in cv["by_test_window"].items():
                results[section][(key[0], w)] = res
    bar.close()
    runtime_s = time.perf_counter() - t_start

    serial = {sec: dict(previous.get(sec, {})) for sec in SECTIONS}
    for sec in wanted:
        serial[sec] = {" | ".join(k): v for k, v in results[sec].items()}
    serial = json.loads(json.dumps(serial, default=_json_default))  # plain JSON types, as read back
    serial["plan"] = {**previous.get("plan", {}), **_plan_record(plan, wanted)}
    serial["runtime_s"] = runtime_s
    if only is not None and "runtime_s" in previous:  # the last full run's, plus a section it did not hold
        serial["runtime_s"] = previous["runtime_s"] + (runtime_s if any(not previous.get(s) for s in wanted) else 0.0)
    serial["section_runtime_s"] = {**previous.get("section_runtime_s", {}),
                                   **{sec: runtime_s for sec in wanted}} if only is not None else {}
    serial["provenance"] = {**previous.get("provenance", {}), **{sec: section_provenance() for sec in wanted}}
    serial["split"] = {"train_trials": tr_trials, "test_trials": te_trials,
                       "trials": sorted({r.trial for r in recs}), "materials": len({r.material for r in recs})}

    # every figure from the merged results: a section kept from results.json is drawn with today's labels
    figs = _figures(serial, plan, fig_dir, tr_trials, te_trials)
    md = render_markdown(serial, figs={k: v.relative_to(out_dir).as_posix() for k, v in figs.items()})
    (out_dir / "results.md").write_text(md)
    (out_dir / "results.json").write_text(json.dumps(serial, indent=1))
    return serial


def _plan_record(plan: ReportPlan, sections: Sequence[str]) -> dict:
    """What the report's text needs to know of the plan (kept in results.json)."""
    rec = {"train_per_trial": plan.train_per_trial, "test_per_trial": plan.test_per_trial,
           "headline_repeats": plan.headline_repeats, "sweep_repeats": plan.sweep_repeats,
           "pa_orders": plan.pa_orders, "cv_folds": plan.cv_folds, "ablation_window": plan.ablation_window}
    if any(s in LENGTH_SECTIONS for s in sections):
        rec.update(length_train=plan.ablation_window, length_tests=list(plan.length_tests),
                   length_cv_tests=list(plan.length_cv_tests), short_windows=list(plan.short_windows),
                   length_repeats=plan.length_repeats)
    if "datasets" in sections:
        rec.update(datasets_window=plan.datasets.window, datasets_folds=plan.datasets.folds)
    if "convolutions" in sections:
        rec.update(convolutions_folds=plan.convolutions.folds)
    return rec


#: Figure files of the report, by name.
FIGURES = {"accuracy_vs_window": "accuracy_vs_window.png", "time_vs_window": "time_vs_window.png",
           "length_robustness": "length_robustness.png", "pa_curves": "pa_curves.png",
           "confusion": "confusion_svm.png"}


def _frames_s(res: dict) -> float:
    return res["test_window_frames"] / 100.0


def _figures(serial: dict, plan: ReportPlan, fig_dir: Path, tr: list[int], te: list[int]) -> dict[str, Path]:
    """Draw the figures of every section ``serial`` holds; return every figure the report links to."""
    import matplotlib.pyplot as plt

    sweep, length, headline = _keyed(serial["sweep"]), _keyed(serial["length"]), _keyed(serial["headline"])
    if sweep:
        modes = list(dict.fromkeys(m for m, _ in sweep))
        fig, ax = plt.subplots(figsize=(6.4, 4.0))
        for m in modes:
            rows = [r for (mm, _), r in sweep.items() if mm == m]
            xs = [_frames_s(r) for r in rows]
            ax.plot(xs, [100 * r["classifiers"]["svm"]["accuracy"] for r in rows], "o-", label=f"SVM, {m}")
            ax.plot(xs, [100 * r["classifiers"]["pa"]["accuracy"] for r in rows], "s--", label=f"online, {m}",
                    alpha=0.7)
        ax.set_xlabel("window length (s)")
        ax.set_ylabel("test accuracy (%)")
        ax.set_title(f"Accuracy against window length (train trials {format_trials(tr)}, test {format_trials(te)})", fontsize=9)
        _save_figure(fig, fig_dir / FIGURES["accuracy_vs_window"], ax=ax, legend_size=7)

        fig, ax = plt.subplots(figsize=(6.4, 4.0))
        for m in modes:
            rows = [r for (mm, _), r in sweep.items() if mm == m]
            ax.plot([_frames_s(r) for r in rows], [1e3 * r["descriptor_s_per_window"] for r in rows], "o-",
                    label=f"descriptor, {m}")
        ax.set_xlabel("window length (s)")
        ax.set_ylabel("descriptor time per window (ms)")
        _save_figure(fig, fig_dir / FIGURES["time_vs_window"], ax=ax, legend_size=7)

    if length:
        fig, ax = plt.subplots(figsize=(6.4, 4.0))
        for m in dict.fromkeys(m for m, _ in length):
            rows = [(w, r) for (mm, w), r in length.items() if mm == m and not is_length_range(w)]
            line = ax.plot([_frames_s(r) for _, r in rows],
                           [100 * r["classifiers"]["svm"]["accuracy"] for _, r in rows], "o-", label=f"SVM, {m}")
            for w, r in ((w, r) for (mm, w), r in length.items() if mm == m and is_length_range(w)):
                ax.axhline(100 * r["classifiers"]["svm"]["accuracy"], ls=":", color=line[0].get_color(),
                           label=f"SVM, {m}, test {_wlabel(w, 0)}")
        train_s = serial["plan"].get("length_train", plan.ablation_window)
        ax.set_xlabel(f"test window length (s); trained on {train_s} s windows")
        ax.set_ylabel("test accuracy (%)")
        _save_figure(fig, fig_dir / FIGURES["length_robustness"], ax=ax, legend_size=7)

    if headline:
        common_s = next(iter(headline.values()))["common_length_s"]
        fig, ax = plt.subplots(figsize=(6.4, 4.0))
        for (m, w), res in headline.items():
            c = res["classifiers"]["pa"]["curve"]
            acc, sd = np.array(c["accuracy"]) * 100, np.array(c["accuracy_std"]) * 100
            ax.plot(c["n_per_class"], acc, label=f"{m}, {_wlabel(w, common_s)}")
            ax.fill_between(c["n_per_class"], acc - sd, acc + sd, alpha=0.15)
        ax.set_xlabel("training trials per class seen (online)")
        ax.set_ylabel("test accuracy (%)")
        ax.set_title(f"Online learning curves: {_online_of(serial)}", fontsize=9)
        _save_figure(fig, fig_dir / FIGURES["pa_curves"], ax=ax, legend_size=6)

        best_key = list(headline)[-len(plan.headline_windows)]  # the recommended mode comes last
        res = headline[best_key]
        cm = np.array(res["classifiers"]["svm"]["confusion"])
        fig, ax = plt.subplots(figsize=(6.4, 5.6))
        ax.imshow(cm, cmap="Blues")
        ax.set_xticks(range(len(res["classes"])), [f"{c}" for c in res["classes"]], fontsize=6)
        ax.set_yticks(range(len(res["classes"])),
                      [f"{c} {n}" for c, n in zip(res["classes"], res["class_names"])], fontsize=6)
        for i in range(cm.shape[0]):
            for j in range(cm.shape[1]):
                if cm[i, j]:
                    ax.text(j, i, str(cm[i, j]), ha="center", va="center", fontsize=5,
                            color="white" if cm[i, j] > cm.max() / 2 else "black")
        ax.set_xlabel("predicted")
        ax.set_title(f"SVM confusion, {best_key[0]}, {_wlabel(best_key[1], common_s)}", fontsize=9)
        _save_figure(fig, fig_dir / FIGURES["confusion"])
    return {k: fig_dir / f for k, f in FIGURES.items() if (fig_dir / f).is_file()}


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


def _mean_sd(c: dict | None) -> str:
    """An accuracy with its spread, ``mean +- sd`` in %, from ``accuracy`` and ``accuracy_std`` (``-`` for None)."""
    return f"{_pct(c['accuracy'])} +- {_pct(c['accuracy_std'])}" if c else "-"


def _cv_cell(r: dict, name: str) -> str:
    return _mean_sd(r["classifiers"].get(name))


def _provenance(serial: dict, section: str) -> dict | None:
    return serial.get("provenance", {}).get(section)


def _is_current(serial: dict, section: str) -> bool:
    prov = _provenance(serial, section)
    return prov is not None and prov.get("features") == FEATURE_DEFINITION


def _provenance_lines(serial: dict, section: str) -> list[str]:
    """The line under a section's heading: when it was measured and with which feature definition.

    A section measured with another definition than this release's says so
    in bold, so that its figures are never read as the current descriptor's.
    """
    prov = _provenance(serial, section)
    redo = f"`tactile report --data DIR --out docs --only {section}`"
    if prov is None:
        return [f"**Not regenerated with this release's features**: when and with which feature definition "
                f"this section was measured is not recorded. Regenerate it with {redo}.", ""]
    if prov.get("features") != FEATURE_DEFINITION:
        return [f"**Not regenerated with this release's features**: measured {prov['date']} with "
                f"{prov['features']}; this release computes {FEATURE_DEFINITION}, so these figures describe "
                f"the earlier definition. Regenerate with {redo}.", ""]
    return [f"*Measured {prov['date']} with {prov['features']}.*", ""]


def render_markdown(serial: dict, figs: dict[str, str]) -> str:
    """``results.md`` from the results (the content of ``results.json``) and the figures' relative paths.

    Sections missing from ``serial`` are left out, so a partial run still renders.
    """
    plan = serial["plan"]
    split = serial["split"]
    tr, te = split["train_trials"], split["test_trials"]
    n_mat = split["materials"]
    first = next((next(iter(serial[sec].values())) for sec in SECTIONS if serial.get(sec)), None)
    common_s = first["common_length_s"] if first else float("nan")
    L: list[str] = []
    a = L.append
    a("# Results on real BioTac recordings")
    a("")
    a("Generated by `tactile report --data DIR --out docs` (`make report`); do not edit by hand. "
      f"Runtime of the full run: {serial['runtime_s'] / 60:.1f} min on {platform.machine()} "
      "(descriptor banks are cached in build/cache; a second run only repeats the learning). "
      "`tactile report --data DIR --out docs --only length` recomputes the touch-length sections alone "
      "and renders this page again. How the protocols work and why: [evaluation.md](evaluation.md).")
    a("")
    a(f"Data: {n_mat} materials, trials {format_trials(split['trials'])} of the BioTac "
      "sliding recordings (one finger, PAC 2.2 kHz, 19 electrodes 100 Hz). Development split: train "
      f"trials {format_trials(tr)}, test trials {format_trials(te)}. Every trial is cropped to the "
      f"common length ({common_s:.2f} s) so that duration cannot give the class away; windows are drawn at "
      f"seeded random positions inside the crop ({plan['train_per_trial']} per training trial, "
      f"{plan['test_per_trial']} per test trial; a whole-trial window is the crop itself). "
      f"SVM: linear, C chosen over {C_GRID_TEXT} by 5-fold CV (folds keep a trial's windows together) repeated "
      f"{plan['headline_repeats']} times for the headline table and {plan['sweep_repeats']} times for sweeps and "
      "ablations, refit on all training windows; scaling log1p(Activity) + standardisation fitted on the "
      f"training set. Online: the core's OnlineClassifier (running scaling) with the classifier node's "
      f"default update, {_online_of(serial)}, one pass over the training windows in trial order (the paper's "
      "PA-I and Crammer et al.'s max-loss PA-I are ablation rows), curve averaged over "
      f"{plan['pa_orders']} presentation orders. GMM: spherical, k = {n_mat}, k-means init with 20 restarts, "
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
    if serial.get("headline"):
        a("## Headline (development split)")
        a("")
        for line in _provenance_lines(serial, "headline"):
            a(line)
        a("| mode | window | values | SVM acc % | SVM C | SVM CV acc % | online acc % (all train trials) | "
          "GMM NMI | GMM acc % |")
        a("|---|---|---|---|---|---|---|---|---|")
        for (m, w), r in _keyed(serial["headline"]).items():
            c = r["classifiers"]
            a(f"| {m} | {_wlabel(w, common_s)} | {r['n_features']} | {_pct(c['svm']['accuracy'])} | "
              f"{c['svm']['best_c']:g} | {_pct(c['svm']['cv_accuracy'])} | {_pct(c['pa']['accuracy'])} | "
              f"{c['gmm']['nmi']:.3f} | {_pct(c['gmm']['accuracy'])} |")
        a("")
        a(f"![online learning curves]({figs.get('pa_curves')})  ![SVM confusion]({figs.get('confusion')})")
        a("")
    if serial.get("sweep"):
        a("## Accuracy against window length")
        a("")
        for line in _provenance_lines(serial, "sweep"):
            a(line)
        a("Train and test on windows of the same length (development split). Times: descriptor = median "
          "compute time of the mode's features per window (core `cell_features` + reductions, plus band "
          "filtering for multiband); SVM update = one refit on all training windows with the chosen C; "
          "predictions are single windows; online update = one scaling + one update step.")
        a("")
        a("| mode | window | SVM acc % | online acc % | descriptor ms/window | SVM refit s | SVM predict ms | "
          "online update us | online predict us |")
        a("|---|---|---|---|---|---|---|---|---|")
        for (m, w), r in _keyed(serial["sweep"]).items():
            s_, p = r["classifiers"]["svm"], r["classifiers"]["pa"]
            a(f"| {m} | {_wlabel(w, common_s)} | {_pct(s_['accuracy'])} | {_pct(p['accuracy'])} | "
              f"{1e3 * r['descriptor_s_per_window']:.2f} | {s_['fit_s']:.2f} | {1e3 * s_['predict_s']:.2f} | "
              f"{1e6 * p['update_s']:.0f} | {1e6 * p['predict_s']:.0f} |")
        a("")
        a(f"![accuracy vs window]({figs.get('accuracy_vs_window')})  ![time vs window]({figs.get('time_vs_window')})")
        a("")
    if serial.get("length"):
        _length_markdown(serial, figs, common_s, a)
    if serial.get("ablation"):
        a(f"## Ablations ({plan['ablation_window']} s windows, development split)")
        a("")
        for line in _provenance_lines(serial, "ablation"):
            a(line)
        a("Concatenated vs pooled body parts is moot here: the data has one finger, so both layouts give the "
          "same vector. The `online:` rows change only the online learner (its SVM is the full descriptor's).")
        a("")
        a("| mode | variant | values | SVM acc % | online acc % |")
        a("|---|---|---|---|---|")
        for (m, name), r in _keyed(serial["ablation"]).items():
            svm = _pct(r["classifiers"]["svm"]["accuracy"]) if "svm" in r["classifiers"] else "(unchanged)"
            a(f"| {m} | {name} | {r['n_features']} | {svm} | {_pct(r['classifiers']['pa']['accuracy'])} |")
        a("")
    if serial.get("trial_cv"):
        a(f"## Cross-validation over trials ({plan['ablation_window']} s windows)")
        a("")
        for line in _provenance_lines(serial, "trial_cv"):
            a(line)
        a(f"Trials {format_trials(sorted(set(tr) | set(te)))} in {plan['cv_folds']} contiguous blocks; each block "
          "is the test set once, the model is trained on the others. `plain` (mean, sd, min and max of every "
          "channel) is the floor: the shipped groups (`combined`) must score at least as much with the same "
          "classifier.")
        a("")
        a("| mode | folds | SVM acc % (mean +- sd) | online acc % (mean +- sd) |")
        a("|---|---|---|---|")
        for (m, _w), r in _keyed(serial["trial_cv"]).items():
            folds = ", ".join(f"{a_}-{b}" for a_, b in r["folds"])
            a(f"| {m} | {folds} | {_cv_cell(r, 'svm')} | {_cv_cell(r, 'pa')} |")
        a("")
    if serial.get("datasets"):
        _datasets_markdown(serial, a)
    if serial.get("convolutions"):
        _convolutions_markdown(serial, a)
    return "\n".join(L) + "\n"


def _selected_cell(sel: dict | None, name: str, mode: str) -> str:
    """A selection's accuracy by trial CV and how many folds chose the default mode (``-`` when not run)."""
    if sel is None or name not in sel["classifiers"]:
        return "-"
    c = sel["classifiers"][name]
    return f"{_cv_cell(sel, name)} (default in {sum(m == mode for m in c['chosen'])} of {len(c['chosen'])})"


def _datasets_markdown(serial: dict, a) -> None:
    """The table of :mod:`.across_datasets`: every layout, the default descriptor against plain statistics."""
    plan = serial["plan"]
    a("## Across data sets: the default descriptor against plain statistics")
    a("")
    for line in _provenance_lines(serial, "datasets"):
        a(line)
    a("Each data set is written in its lab's layout (built from the data at hand, "
      "`tactile_descriptors_lab/datasets/layouts.py`) and read back through its mapping, as `tactile evaluate "
      f"--mapping` reads it; then cross-validation over {plan.get('datasets_folds', plan['cv_folds'])} contiguous "
      "blocks of trials (the Penn layout's blocks are its sessions), each the test set once. `plain` (mean, sd, "
      "min and max of every channel) against the default mode, less the groups the cell type cannot feed (what "
      "`tactile evaluate` runs without `--mode`), with the same classifier, windows and seeds. Where the default "
      "falls below `plain`, `tactile evaluate --select plain,<default>` chooses between them inside the training "
      "trials; *selected* is that choice, made in each fold without its test block (the count: folds in which "
      "it chose the default).")
    a("")
    a("| data set | classes | trials | window | default mode | SVM %: plain | SVM %: default | SVM %: selected "
      "| online %: plain | online %: default | online %: selected | default >= plain (SVM, online) |")
    a("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, r in serial["datasets"].items():
        floor, mine = r["cv"][FLOOR_MODE], r["cv"][r["mode"]]
        mode = f"`{r['mode']}`" + (f" (without {', '.join(r['left_out'])})" if r["left_out"] else "")
        verdict = ", ".join("yes" if default_at_least_floor(r, c) else "**no**" for c in ("svm", "pa"))
        sel = r.get("selected")
        a(f"| {name}: {r['about']} | {r['classes']} | {r['trials']} | {r['window']} s | {mode} | "
          f"{_cv_cell(floor, 'svm')} | {_cv_cell(mine, 'svm')} | {_selected_cell(sel, 'svm', r['mode'])} | "
          f"{_cv_cell(floor, 'pa')} | {_cv_cell(mine, 'pa')} | {_selected_cell(sel, 'pa', r['mode'])} | {verdict} |")
    a("")


def _convolutions_markdown(serial: dict, a) -> None:
    """The section of :mod:`.convolutions`: the ``rocket`` group beside the shipped ones, 1 s SVM and 2 s online,
    each candidate on the development split and by trial CV, and the choice made inside the training trials."""
    plan = serial["plan"]
    split = serial["split"]
    rows = serial["convolutions"]
    a("## With the convolutions: 1 s windows (SVM) and 2 s windows (online)")
    a("")
    for line in _provenance_lines(serial, "convolutions"):
        a(line)
    first = next(iter(rows.values()))
    transform = first["transform"]
    a("The `rocket` group (random convolutions of PAC and of the slow channels, their biases from "
      f"`config/rocket/{transform['file']}`, {transform['description']}) joined to the shipped groups is "
      f"`combined_rocket`. Each candidate is scored on the development split (train {format_trials(split['train_trials'])}, test "
      f"{format_trials(split['test_trials'])}) and by cross-validation over "
      f"{plan.get('convolutions_folds', plan['cv_folds'])} contiguous blocks of trials; a fold that tests trials "
      "the transform was fitted on has seen their signals, never their labels. *Chosen* is what a selection "
      "inside the training trials picks (`tactile evaluate --select`, with `--select-blocks` online; "
      f"{len(first['selection']['folds'])} inner blocks of the training trials, ties to the candidate listed "
      "first); it then scores the test split once, "
      "the *dev split* figure of its row. The other rows choose nothing: they show what the choice leaves.")
    a("")
    a("| window, learner | candidate | values | dev split % | trial CV % (mean +- sd; folds) | inner % (selection) |")
    a("|---|---|---|---|---|---|")
    for r in rows.values():
        sel = r["selection"]
        if r["classifier"] == "svm":
            c_grid = ", ".join(f"{c:g}" for c in r["c_grid"])
            learner = (f"{r['window']} s, linear SVM ({r['train_per_trial']} training windows a trial; C over "
                       f"{c_grid} by {r['cv_folds']}-fold x {r['cv_repeats']} CV)")
        else:
            orders = next(iter(r["candidates"].values()))["split"].get("orders")
            learner = (f"{r['window']} s, {_online_of(serial, short=True)}, one pass ({r['train_per_trial']} "
                       f"training windows a trial; mean +- sd over {orders} orders on the dev split)")
        for label, c in r["candidates"].items():
            s = c["split"]
            dev = _mean_sd(s) if "accuracy_std" in s else _pct(s["accuracy"])
            folds = ", ".join(f"{_pct(x)}" for x in c["cv"]["fold_accuracy"])
            name = f"`{label}`" + (" **(chosen)**" if label == sel["chosen_label"] else "")
            a(f"| {learner} | {name} | {s['n_features']} | {dev} | {_mean_sd(c['cv'])} ({folds}) | "
              f"{_mean_sd(sel['inner'].get(label))} |")
            learner = ""  # named on its first row
    a("")
    for r in rows.values():
        sel = r["selection"]
        best = max(r["candidates"].items(), key=lambda kv: kv[1]["split"]["accuracy"])
        a(f"- **{r['window']} s, {'the SVM' if r['classifier'] == 'svm' else 'online'}**: the selection keeps "
          f"`{sel['chosen_label']}` and scores the test split once: {_pct(sel['test']['accuracy'])} %. "
          f"The best candidate on the dev split, known only afterwards: `{best[0]}`, "
          f"{_pct(best[1]['split']['accuracy'])} %.")
    a("")
    svm, online = rows.get("svm"), rows.get("online")
    commands = []
    if svm:
        commands.append(f"`--window {svm['window']} --train-windows {svm['train_per_trial']} --select "
                        f"{','.join(svm['candidates'])} --cv-repeats {svm['cv_repeats']} --c-grid "
                        f"{','.join(f'{c:g}' for c in svm['c_grid'])}` (SVM)")
    if online:
        modes = ",".join(dict.fromkeys(c["mode"] for c in online["candidates"].values()))
        blocks = ",".join(dict.fromkeys(f"{c['block_s'] or 0:g}" for c in online["candidates"].values()))
        commands.append(f"`--window {online['window']} --train-windows {online['train_per_trial']} --classifier pa "
                        f"--select {modes} --select-blocks {blocks}` (online)")
    a(f"Reproduce the choices with `tactile evaluate --train DATA --test DATA --train-trials "
      f"{format_trials(split['train_trials'])} --test-trials {format_trials(split['test_trials'])}` and "
      + " or ".join(commands) + "; one candidate with `--channels MODE` (and `--block 0` for the whole window), "
      "a fold of the trial CV with its trials as the test trials.")
    a("")


_QUANTITY_NAMES = {"A": "Activity", "M": "Mobility", "C": "Complexity", "L": "Pearson", "N": "Spearman",
                   "level": "mean level", "logvar": "log variance", "skew": "skewness", "kurt": "kurtosis",
                   "logbp": "log band power"}


def _family(label: str) -> str:
    """A feature's family: quantity and signal (``per_channel/A_e3`` -> ``Activity of electrodes``)."""
    group, q = label.split("/", 1)
    parts = q.split("_")
    if parts[0] in ("L", "N"):
        signal = "PAC x electrodes"
    else:
        sig = parts[1] if len(parts) > 1 else ""
        signal = "PAC" if sig == "pac" else ("electrodes" if sig == "E" or sig[:1] == "e" else sig.upper())
    if group == "bands":
        signal += " bands"
    return f"{_QUANTITY_NAMES.get(parts[0], parts[0])} of {signal}"


def _length_shift_table(length: dict, train_w: str, top: int = 10) -> list[tuple[str, dict]]:
    """Rows ``(family, {variant: mean |z shift| whole vs train length})``, largest first (first variant)."""
    variants = list(dict.fromkeys(v for v, _ in length))
    per_variant: dict[str, dict[str, float]] = {}
    for v in variants:
        whole, ref = length.get((v, "whole")), length.get((v, train_w))
        if not whole or not ref or "feature_mean_z" not in whole or "feature_mean_z" not in ref:
            continue
        shift = np.abs(np.array(whole["feature_mean_z"]) - np.array(ref["feature_mean_z"]))
        fams: dict[str, list[float]] = {}
        for lab, x in zip(whole["feature_labels"], shift):
            fams.setdefault(_family(lab), []).append(float(x))
        per_variant[v] = {f: float(np.mean(x)) for f, x in fams.items()}
        per_variant[v]["all values"] = float(np.mean(shift))
    if not per_variant:
        return []
    first = next(iter(per_variant.values()))
    order = sorted((f for f in first if f != "all values"), key=lambda f: -max(
        d.get(f, 0.0) for d in per_variant.values()))[:top] + ["all values"]
    return [(f, {v: d.get(f) for v, d in per_variant.items()}) for f in order]


def _length_markdown(serial: dict, figs: dict[str, str], common_s: float, a) -> None:
    """The touch-length sections: train on one length, test on others and on random lengths; short windows."""
    plan = serial["plan"]
    train_w = plan.get("length_train", plan["ablation_window"])
    length = _keyed(serial["length"])
    minutes = serial.get("section_runtime_s", {}).get("length")
    a("## Robustness to touch length")
    a("")
    for line in _provenance_lines(serial, "length"):
        a(line)
    a(f"A model trained on {_wlabel(train_w, common_s)} windows (what `tactile evaluate --window {train_w}` "
      "trains) is scored on test windows of other lengths; *random a-b s* draws every test window's length "
      "uniformly from a, a + 0.5 s, ..., b (a length past the crop is the crop) and its position at random, "
      "as a robot's touches last what they last. "
      + (f"SVM C chosen by 5-fold CV repeated {plan['length_repeats']} time(s). " if plan.get("length_repeats") else "")
      + "Regenerate these sections alone with "
      "`tactile report --data DIR --out docs --only length`"
      + (f" ({minutes / 60:.1f} min in this run)." if minutes else ".")
      + " Why accuracy used to fall with the length and what changed: [evaluation.md](evaluation.md).")
    a("")
    a("| mode | train window | test window | SVM acc % | online acc % | SVM points vs same length |")
    a("|---|---|---|---|---|---|")
    for (m, w), r in length.items():
        ref = length.get((m, train_w))
        diff = (f"{100 * (r['classifiers']['svm']['accuracy'] - ref['classifiers']['svm']['accuracy']):+.1f}"
                if ref else "-")
        a(f"| {m} | {_wlabel(train_w, common_s)} | {_wlabel(w, common_s)} | "
          f"{_pct(r['classifiers']['svm']['accuracy'])} | {_pct(r['classifiers']['pa']['accuracy'])} | {diff} |")
    a("")
    shift_rows = _length_shift_table(length, train_w)
    if shift_rows:
        labels = list(shift_rows[0][1])
        a(f"Which quantities move with the length: mean over a family's values of |mean on whole-trial test "
          f"windows - mean on {_wlabel(train_w, common_s)} test windows|, in units of the training set's "
          "standard deviation (after the learners' scaling); the same test trials, so only the length differs; "
          "the families that move most:")
        a("")
        a("| quantity | " + " | ".join(labels) + " |")
        a("|---|" + "---|" * len(labels))
        for fam, vals in shift_rows:
            a(f"| {fam} | " + " | ".join("-" if v is None else f"{v:.2f}" for v in vals.values()) + " |")
        a("")
    if serial.get("length_cv"):
        cv = _keyed(serial["length_cv"])
        first = next(iter(cv.values()))
        folds = ", ".join(f"{a_}-{b}" for a_, b in first["folds"])
        if _provenance(serial, "length_cv") != _provenance(serial, "length"):
            for line in _provenance_lines(serial, "length_cv"):
                a(line)
        a(f"By trial cross-validation (blocks {folds}; each fold's model trained once on "
          f"{_wlabel(train_w, common_s)} windows and scored on every test window):")
        a("")
        a("| mode | train window | test window | SVM acc % (mean +- sd) | online acc % (mean +- sd) |")
        a("|---|---|---|---|---|")
        for (m, w), r in cv.items():
            a(f"| {m} | {_wlabel(train_w, common_s)} | {_wlabel(w, common_s)} | {_cv_cell(r, 'svm')} | "
              f"{_cv_cell(r, 'pa')} |")
        a("")
    if figs.get("length_robustness"):
        a(f"![touch length]({figs['length_robustness']})")
        a("")
    if serial.get("short"):
        short = _keyed(serial["short"])
        label = next(iter(short))[0]
        # the training length's row is the touch-length table's model, when both were measured alike
        same = _provenance(serial, "short") == _provenance(serial, "length")
        if (label, train_w) in length and same:
            short[(label, train_w)] = length[(label, train_w)]
        short = dict(sorted(short.items(), key=lambda kv: float(kv[0][1])))
        a("## Short windows (default mode)")
        a("")
        for line in _provenance_lines(serial, "short"):
            a(line)
        a("Train and test on windows of the same length (development split" + (
            f"; the {_wlabel(train_w, common_s)} row is the touch-length table's model)." if same and
            (label, train_w) in length else "; the touch-length table, measured separately, has the "
            f"{_wlabel(train_w, common_s)} model).") + " `tactile evaluate` draws at least 8 training windows per "
          "trial, and 16 s of windows per trial at shorter lengths (`--train-windows`).")
        a("")
        a("| mode | window | values | training windows per trial | SVM acc % | SVM C | online acc % |")
        a("|---|---|---|---|---|---|---|")
        for (m, w), r in short.items():
            c = r["classifiers"]
            per_trial = r.get("train_windows_per_trial") or r["config"]["train_per_trial"]
            a(f"| {m} | {_wlabel(w, common_s)} | {r['n_features']} | {per_trial} | {_pct(c['svm']['accuracy'])} | "
              f"{c['svm']['best_c']:g} | {_pct(c['pa']['accuracy'])} |")
        a("")


#: Markers of the README's generated "What to expect" accuracy lines.
README_BEGIN = "<!-- what-to-expect: written by `tactile report --readme README.md` from lab/docs/results.json -->"
README_END = "<!-- /what-to-expect -->"


def what_to_expect(serial: dict) -> str:
    """The README's accuracy and report-runtime lines, every figure read from ``serial`` (results.json).

    Raises
    ------
    ConfigError
        When results.json lacks a result the lines quote.
    """
    def get(section: str, key: str) -> dict:
        try:
            return serial[section][key]
        except KeyError:
            raise ConfigError(f"results.json has no {section!r} result {key!r}; run the report", key=section) from None

    split = serial["split"]
    head = get("length", f"{DEFAULT_MODE} | 2")
    paper2, paper_whole = get("length", "paper | 2"), get("length", "paper | whole")
    cv = get("length_cv", f"{DEFAULT_MODE} | 2")
    cv_mixed = get("length_cv", f"{DEFAULT_MODE} | 1-6")
    mixed = get("length", f"{DEFAULT_MODE} | 1-6")
    short = {w: get("short", f"{DEFAULT_MODE} | {w}") for w in ("0.5", "1")}
    length_min = serial.get("section_runtime_s", {}).get("length")
    headline_min = serial.get("section_runtime_s", {}).get("headline")
    datasets_min = serial.get("section_runtime_s", {}).get("datasets")
    convolutions_min = serial.get("section_runtime_s", {}).get("convolutions")

    def svm(r: dict) -> str:
        return f"{_pct(r['classifiers']['svm']['accuracy'])} %"

    def cv_svm(r: dict) -> str:
        return f"{_mean_sd(r['classifiers']['svm'])} %"

    def when(*sections: str) -> str:
        """`` (measured <date> with ...)`` for figures of sections measured with another feature definition."""
        old = [(sec, _provenance(serial, sec)) for sec in sections if not _is_current(serial, sec)]
        if not old:
            return ""
        dates = sorted({(p or {}).get("date", "on a date not recorded") for _, p in old})
        return (f" (measured {', '.join(dates)} with an earlier feature definition than this release's: "
                "see `lab/docs/results.md`)")

    lines = [
        f"- **Accuracy on real BioTac data** ({split['materials']} materials, one finger, train trials "
        f"{format_trials(split['train_trials'])}, test {format_trials(split['test_trials'])}; "
        f"`lab/docs/results.md`): the default `{DEFAULT_MODE}` descriptor ({head['n_features']} values, averaged "
        f"over 1 s blocks) gets {svm(head)} (linear SVM) and {_pct(head['classifiers']['pa']['accuracy'])} % "
        f"(online, {_online_of(serial, short=True)}, one pass) with 2 s windows, {cv_svm(cv)} by cross-validation "
        "over trials; the "
        f"paper's 8-value descriptor, averaged over the same blocks, gets {svm(paper2)} at 2 s and "
        f"{svm(paper_whole)} on whole {paper_whole['common_length_s']:.0f} s trials (`--block 0` describes a "
        "window as one eq. 17 descriptor)" + when("length", "length_cv") + ".",
        f"- **Touch length**: trained on 2 s windows and tested on touches of random length 1-6 s, "
        f"{svm(mixed)} ({cv_svm(cv_mixed)} by trial cross-validation)" + when("length", "length_cv")
        + f"; trained and tested on short windows, {svm(short['0.5'])} at 0.5 s and {svm(short['1'])} at 1 s"
        + when("short") + ".",
        f"- `make report` regenerates the real-data report in about {serial['runtime_s'] / 60:.0f} minutes on 2 "
        "cores" + "".join(f"; `make report-{name}` {what} in about {minutes / 60:.0f} minutes"
                          for name, what, minutes in (("headline", "its headline table", headline_min),
                                                      ("length", "its touch-length sections", length_min),
                                                      ("datasets", "its table across data sets", datasets_min),
                                                      ("convolutions", "its section on the convolution group",
                                                       convolutions_min))
                          if minutes) + ".",
    ]
    if serial.get("datasets"):
        rows = serial["datasets"]

        def pair(r: dict, name: str) -> str:
            acc = {m: _pct(r["cv"][m]["classifiers"][name]["accuracy"]) for m in (r["mode"], FLOOR_MODE)}
            return f"{acc[r['mode']]} against {acc[FLOOR_MODE]} %"

        lines.insert(2, "- **Other labs' layouts** (read through mappings; `lab/docs/results.md`): by cross-validation "
                     "over trials, the default descriptor against plain per-channel statistics, linear SVM, on "
                     + "; ".join(f"the {name} {pair(r, 'svm')}" for name, r in rows.items())
                     + when("datasets") + ".")
    if serial.get("convolutions"):
        conv = serial["convolutions"]

        def chosen(setting: str) -> str:
            r = conv[setting]
            sel = r["selection"]
            return (f"{r['window']} s {'SVM' if r['classifier'] == 'svm' else 'online'} "
                    f"{_pct(sel['test']['accuracy'])} % (`{sel['chosen_label']}`)")

        lines.insert(2, "- **With the convolution group** (`rocket`, not in the shipped configurations; "
                     "`lab/docs/results.md`): chosen inside the training trials and scored once on the test "
                     "trials, " + " and ".join(chosen(k) for k in conv) + when("convolutions") + ".")
    return "\n".join([README_BEGIN, *lines, README_END])


def update_readme(readme: str | Path, serial: dict) -> None:
    """Replace the generated block of ``readme`` (between :data:`README_BEGIN` and :data:`README_END`).

    Raises
    ------
    ConfigError
        When the file lacks the markers.
    """
    path = Path(readme)
    text = path.read_text()
    a, b = text.find(README_BEGIN), text.find(README_END)
    if a < 0 or b < a:
        raise ConfigError(f"{path}: no '{README_BEGIN}' ... '{README_END}' block to update", key="readme")
    path.write_text(text[:a] + what_to_expect(serial) + text[b + len(README_END):])
