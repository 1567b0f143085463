"""``tactile evaluate``: train on some recorded trials, score on others.

Example::

    tactile evaluate --train ../shared/data/biotac_slide_20_50 --test ../shared/data/biotac_slide_20_50 \\
        --train-trials 1-20 --test-trials 21-30 --classifier all --window 2 --json

Trials default to 1-20 for training and 21-30 for testing when both folders
are the same, and to every trial of each folder when they differ (a model
trained on one set of recordings, scored on another).
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from ..errors import ConfigError

__all__ = ["register", "run", "default_trials"]


def default_trials(train_dir: str, test_dir: str, train_text: str | None,
                   test_text: str | None) -> tuple[list[int] | None, list[int] | None]:
    """Trial lists of the two splits (``None`` = every trial of that folder).

    Unset ranges default to 1-20 / 21-30 when both splits read the same
    folder (disjoint by construction), and to every trial otherwise.
    """
    from pathlib import Path

    from ..evaluation.windows import parse_trials

    same = Path(train_dir).resolve() == Path(test_dir).resolve()
    train = parse_trials(train_text if train_text is not None else ("1-20" if same else "all"))
    test = parse_trials(test_text if test_text is not None else ("21-30" if same else "all"))
    return train, test


def register(subparsers) -> None:
    """Add the ``evaluate`` subcommand."""
    from ..core.learning import PA_UPDATES, RECOMMENDED_PA_AVERAGE, RECOMMENDED_PA_UPDATE
    from ..evaluation.features import DEFAULT_MODE, DESCRIPTOR_MODES
    from ..evaluation.modes import SCALINGS

    p = subparsers.add_parser(
        "evaluate", help="train and score the paper's classifiers on recorded BioTac trials",
        description="Crop every trial to the common length (no duration leak), draw seeded random windows, "
        "compute descriptors (cached in build/cache), train on --train trials and score on --test trials.")
    p.add_argument("--train", required=True, help="folder of training recordings (holding raw_data/)")
    p.add_argument("--test", required=True, help="folder of test recordings (may be the same folder)")
    p.add_argument("--train-trials", default=None,
                   help="trial range, e.g. 1-20, 1-5,8 or all (default: 1-20 if --train and --test are the "
                   "same folder, else all)")
    p.add_argument("--test-trials", default=None,
                   help="trial range (default: 21-30 if --train and --test are the same folder, else all)")
    p.add_argument("--materials", default=None, help="material range (default: all)")
    p.add_argument("--classifier", default="svm", choices=["svm", "pa", "gmm", "all"])
    p.add_argument("--window", default="2", help="window in seconds, or 'whole' (the common length)")
    p.add_argument("--test-window", default=None, help="test window if different (exploration-time protocol)")
    p.add_argument("--channels", "--mode", dest="channels", default=DEFAULT_MODE,
                   choices=["averaged", *DESCRIPTOR_MODES],
                   help="descriptor mode: averaged/paper = eq. 17 (8 values), per_channel (98), "
                   "multiband (per_channel + Hjorth of 6 PAC bands), multiband_levels, baseline, "
                   "combined (all of them, 261 values), combined_subwindows (+ mean and sd over 4 successive "
                   f"pieces, 493); default {DEFAULT_MODE}")
    p.add_argument("--scaling", default="log_standardize", choices=list(SCALINGS))
    p.add_argument("--gate", action=argparse.BooleanOptionalAction, default=False,
                   help="contact gate (eq. 16; off by default: recorded slides are all in contact and the "
                   "tared PDC misfires on soft materials, see docs/evaluation.md)")
    p.add_argument("--pa-update", default=RECOMMENDED_PA_UPDATE, choices=list(PA_UPDATES),
                   help="PA-I update: max_loss (default) or prediction (the paper's eq. 30-32)")
    p.add_argument("--pa-average", action=argparse.BooleanOptionalAction, default=RECOMMENDED_PA_AVERAGE,
                   help="predict with averaged PA weights (default on; --no-pa-average is the paper's PA-I)")
    p.add_argument("--drop", default="", help="quantities to leave out, e.g. L,N (ablation)")
    p.add_argument("--train-windows", type=int, default=8, help="random windows per training trial (default 8)")
    p.add_argument("--test-windows", type=int, default=2, help="random windows per test trial")
    p.add_argument("--cv-repeats", type=int, default=10, help="repeats of the 5-fold CV choosing C")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--cache", default="build/cache", help="descriptor cache folder ('' = off)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the evaluation and print accuracy and confusion matrices (or JSON)."""
    from ..evaluation.experiments import CLASSIFIERS, EvalConfig, evaluate
    from ..evaluation.windows import load_split, parse_trials

    train_trials, test_trials = default_trials(args.train, args.test, args.train_trials, args.test_trials)
    materials = parse_trials(args.materials) if args.materials else None
    if args.train_windows < 1 or args.test_windows < 1 or args.cv_repeats < 1:
        raise ConfigError("--train-windows, --test-windows and --cv-repeats must be >= 1")
    classifiers = CLASSIFIERS if args.classifier == "all" else (args.classifier,)
    drop = tuple(q.strip() for q in args.drop.split(",") if q.strip())
    train = load_split(args.train, train_trials, materials)
    test = load_split(args.test, test_trials, materials)
    cfg = EvalConfig(window=args.window, test_window=args.test_window, mode=args.channels,
                     classifiers=tuple(classifiers), seed=args.seed, train_per_trial=args.train_windows,
                     test_per_trial=args.test_windows, scaling=args.scaling, gate=args.gate, drop=drop,
                     pa_update=args.pa_update, pa_average=args.pa_average,
                     cv_repeats=args.cv_repeats, jobs=args.jobs, cache_dir=args.cache or None,
                     progress=True)
    result = evaluate(train, test, cfg)
    if args.json:
        out = dict(result)
        if args.classifier != "all":  # with all, each classifier's object carries its accuracy
            out["accuracy"] = result["classifiers"][args.classifier]["accuracy"]
        print(json.dumps(out))
        return 0
    print(f"descriptor mode {args.channels} ({result['n_features']} values), window {args.window} s "
          f"(test {args.test_window or args.window}), crop {result['common_length_s']:.2f} s; "
          f"{result['n_train']} training and {result['n_test']} test windows; contact gate "
          f"{'on' if args.gate else 'off'}")
    for name, res in result["classifiers"].items():
        line = f"{name}: accuracy {100 * res['accuracy']:.1f} %"
        if name == "svm":
            line += f" (C = {res['best_c']:g}, CV accuracy {100 * res['cv_accuracy']:.1f} %)"
        if name == "pa":
            line += (f" after {res['curve']['n_per_class'][-1]} training trials per class (online, "
                     f"{args.pa_update} update{', averaged' if args.pa_average else ''})")
        if name == "gmm":
            line += f", NMI {res['nmi']:.3f}"
        print(line)
        cm = np.array(res["confusion"])
        print("  confusion (rows: true " + " ".join(str(c) for c in result["classes"]) + "):")
        for c, row in zip(result["classes"], cm):
            print(f"  {c:>3} " + " ".join(f"{v:3d}" for v in row))
    return 0
