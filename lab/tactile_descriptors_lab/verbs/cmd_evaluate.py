"""``tactile evaluate``: train on some recorded trials, score on others.

Example::

    tactile evaluate --train ../shared/data/biotac_slide_20_50 --test ../shared/data/biotac_slide_20_50 \\
        --train-trials 1-20 --test-trials 21-30 --classifier all --window 2 --json

--train and --test take whatever ``tactile import`` takes (a folder or file
of tables read through ``--mapping``, Shadow or UPenn bags) and the bags it
writes.  Splits are always by trial: when both name the same source, trials
default to the first two thirds for training and the rest for testing (1-20
and 21-30 of 30), and the two ranges must not share a trial; when they
differ, every trial of each.  A range naming trials or classes the data do
not hold is an error listing what they hold.  ``--windows contact`` draws
windows wholly in contact instead of at random positions.

``--live`` checks that the robot computes the same: the trials are imported
into a bag and replayed through the window node and classifier node
processes, a teacher publishing the labels of the training trials, and the
live descriptors and predictions are compared with this evaluation's, one
window per trial (its first ``--window`` seconds).  Example::

    tactile evaluate --live --train ../shared/data/biotac_slide_20_50 --test ../shared/data/biotac_slide_20_50 --json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from tactile_descriptors_ros.errors import ConfigError
from tactile_descriptors_ros.tools.arguments import number_list

__all__ = ["register", "run", "run_live", "default_trials", "split_trials", "check_recordings", "check_pac_rate"]


def default_trials(train_dir: str, test_dir: str, train_text: str | None,
                   test_text: str | None) -> tuple[list[int] | None, list[int] | None]:
    """Trial lists of the two splits as given (``None`` = not given, or ``all``).

    Unset ranges of one source are filled in by :func:`split_trials` once
    the source's trials are known; of two sources they mean every trial.
    """
    from tactile_descriptors_lab.evaluation.sampling import parse_trials

    return (parse_trials(train_text) if train_text is not None else None,
            parse_trials(test_text) if test_text is not None else None)


def split_trials(trials: list[int], train: list[int] | None, test: list[int] | None,
                 train_given: bool, test_given: bool) -> tuple[list[int], list[int]]:
    """Disjoint train and test trials of one source.

    Unset: the first two thirds of the trials (rounded) train, the rest test;
    one range set: the other is the remaining trials.

    Raises
    ------
    ConfigError
        When the two ranges share trials, or a split is empty.
    """
    have = sorted(trials)
    if not train_given and not test_given:
        k = int(round(len(have) * 2 / 3))
        train, test = have[:k], have[k:]
    elif not test_given:
        train = have if train is None else train
        test = [t for t in have if t not in set(train)]
    elif not train_given:
        test = have if test is None else test
        train = [t for t in have if t not in set(test)]
    train = have if train is None else train
    test = have if test is None else test
    shared = sorted(set(train) & set(test))
    if shared:
        from tactile_descriptors_lab.datasets.readers import format_numbers

        raise ConfigError(f"--train-trials and --test-trials share trials {format_numbers(shared)} of one source: "
                          "splits are by trial, use disjoint ranges", key="trials")
    if not train or not test:
        raise ConfigError(f"the source holds trials {have}: too few to split into training and test trials",
                          key="trials")
    return train, test


def check_recordings(recordings, mode: str) -> None:
    """Refuse a descriptor mode whose feature groups read a channel the recordings do not hold.

    A channel is absent when the source lacks it, or when it is not at the
    rate the descriptors take (:func:`~..evaluation.features.recording_channels`:
    a BioTac's PAC must be at 2.2 kHz, so an old Shadow driver's two PAC
    samples a frame are no PAC signal).

    Raises
    ------
    ConfigError
        Naming the first recording lacking a channel, the feature group that
        reads it, and the groups the recordings can feed.
    """
    from tactile_descriptors_lab.evaluation.bank import mode_groups, recording_channels, recordings_cell_type
    from tactile_descriptors_ros.core.groups import check_present

    ct = recordings_cell_type(recordings)
    groups = [g for g in mode_groups(mode) if g != "subwindows"]
    if "subwindows" in mode_groups(mode):
        groups += ["per_channel", "bands"]  # what each piece of a window is described with
    for r in recordings:
        present, why = recording_channels(r, ct)
        check_present(ct, groups, present, where=f"{r.path} (mode {mode})", why=why, key="channels")


def resolve_mode(recordings, mode: str | None) -> str:
    """The descriptor mode: ``mode`` if given (refused by name when the recordings' cell type cannot feed
    one of its groups), else the default mode less the groups the cell type cannot feed, with a note.

    Raises
    ------
    ConfigError
        For a mode asked for with a group the cell type cannot feed (a vibration rate without a band below
        Nyquist for ``bands``), naming the group, why, and the groups it can feed.
    """
    from tactile_descriptors_lab.evaluation.bank import DEFAULT_MODE, cell_type_groups, fed_mode, recordings_cell_type

    ct = recordings_cell_type(recordings)
    kept, left, reason = fed_mode(ct, DEFAULT_MODE if mode is None else mode)
    if left and mode is not None:
        raise ConfigError(f"mode {mode!r}: {reason}; the groups it can feed: {', '.join(cell_type_groups(ct)[0])}",
                          key="channels")
    if left:
        print(f"note: descriptor mode {DEFAULT_MODE} without {', '.join(left)} ({reason}): "
              f"{kept}; --mode {DEFAULT_MODE} asks for every group", file=sys.stderr)
    return kept


def check_classes(train, test, train_source: str, test_source: str, every=None) -> None:
    """Refuse splits in which a class has training trials but no test trial, or test trials but no training.

    Raises
    ------
    ConfigError
        One line naming the source, the option (``--test-trials`` or ``--train-trials``), the class and the
        trials that class holds (in the one source read, or in the split that has it).
    """
    from tactile_descriptors_lab.datasets.readers import format_numbers

    def trials_of(recs) -> dict[str, list[int]]:
        out: dict[str, list[int]] = {}
        for r in recs:
            out.setdefault(r.class_name, []).append(r.trial)
        return out

    tr, te = trials_of(train), trials_of(test)
    held = trials_of(every) if every is not None else None
    for have, lack, source, key, side in ((tr, te, test_source, "--test-trials", "test"),
                                          (te, tr, train_source, "--train-trials", "training")):
        absent = [c for c in have if c not in lack]
        if absent:
            c = absent[0]
            holds = held[c] if held is not None else have[c]
            split = sorted({r.trial for r in (test if side == "test" else train)})
            more = f" (and {len(absent) - 1} more: {', '.join(absent[1:4])})" if len(absent) > 1 else ""
            raise ConfigError(f"class {c} has no {side} trial{more}: the {side} trials are "
                              f"{format_numbers(split)}, class {c} holds trials {format_numbers(sorted(holds))}"
                              + ("" if held is not None else " in the other split"), key=key, source=source)


def check_pac_rate(recordings) -> None:
    """The paper's descriptor reads PAC at the BioTac's rate: :func:`check_recordings` of mode ``paper``."""
    check_recordings(recordings, "paper")


def register(subparsers) -> None:
    """Add the ``evaluate`` subcommand."""
    from tactile_descriptors_lab.evaluation.bank import DEFAULT_MODE
    from tactile_descriptors_lab.evaluation.modes import CV_REPEATS, SCALINGS
    from tactile_descriptors_lab.evaluation.sampling import DEFAULT_BLOCK_HOP_S, DEFAULT_BLOCK_S
    from tactile_descriptors_ros.core.learning import (
        PA_UPDATES,
        RECOMMENDED_PA_AVERAGE,
        RECOMMENDED_PA_UPDATE,
    )

    p = subparsers.add_parser(
        "evaluate", help="train and score the paper's classifiers on recorded BioTac trials",
        description="Crop every trial to the common length (no duration leak), draw seeded random windows, "
        "compute descriptors (cached in build/cache), train on --train trials and score on --test trials.")
    p.add_argument("--train", required=True,
                   help="training recordings: a folder or file of tables, bags, or a bag from tactile import")
    p.add_argument("--test", required=True, help="test recordings (may be the same source)")
    p.add_argument("--mapping", default=None,
                   help="mapping of the tables (file or shipped name; default biotac_slide_20_50; bags need none)")
    p.add_argument("--test-mapping", default=None, help="mapping of --test if different from --mapping")
    p.add_argument("--train-trials", default=None,
                   help="trial range, e.g. 1-20, 1-5,8 or all (default: the first two thirds of the trials if "
                   "--train and --test are the same source, else all)")
    p.add_argument("--test-trials", default=None,
                   help="trial range (default: the trials not trained on if the same source, else all)")
    p.add_argument("--materials", "--classes", dest="materials", default=None,
                   help="classes by number or name, e.g. 1-20 or cork,felt (default: all)")
    p.add_argument("--windows", default="random", choices=["random", "contact"],
                   help="window placement: random positions in the common crop (default), or random positions "
                   "wholly in contact (force >= F_t in every frame)")
    p.add_argument("--classifier", default="svm", choices=["svm", "pa", "gmm", "all"])
    p.add_argument("--window", default="2",
                   help="window in seconds, 'whole' (the common length) or a range such as 1-6 (each window "
                   "draws its length from 1, 1.5, ..., 6 s)")
    p.add_argument("--test-window", default=None,
                   help="test window if different, e.g. 1-6 for touches of random length (touch-length protocol)")
    p.add_argument("--block", type=float, default=None,
                   help="describe a window by the mean over its blocks of this many seconds, at most "
                   f"--block-hop apart (default {DEFAULT_BLOCK_S:g}; keeps a model trained on one touch length "
                   "right on others, lab/docs/evaluation.md); 0 = one descriptor of the whole window; the window node "
                   "averages the same blocks (descriptor.block_s), --live on both sides")
    p.add_argument("--block-hop", type=float, default=DEFAULT_BLOCK_HOP_S,
                   help=f"largest step between blocks in seconds (default {DEFAULT_BLOCK_HOP_S:g})")
    p.add_argument("--channels", "--mode", dest="channels", default=None,
                   help="descriptor mode: averaged/paper = eq. 17 (8 values), per_channel (98), "
                   "multiband (per_channel + Hjorth of 6 PAC bands), multiband_levels, baseline, "
                   "combined (all of them, 261 values), combined_subwindows (+ mean and sd over 4 successive "
                   "pieces, 493), plain (mean, sd, min, max of every channel), rocket (random convolutions), "
                   "combined_rocket, or feature groups joined by '+' (levels, per_channel+levels, "
                   f"levels:pdc,tdc,tac); default {DEFAULT_MODE}")
    p.add_argument("--select", default=None, metavar="MODE,MODE,...",
                   help="choose the mode among these by cross-validation by trial inside the training trials "
                   "(3 blocks; ties to the first listed), then score the test once with it (replaces --channels)")
    p.add_argument("--select-blocks", type=number_list("block lengths in seconds (0 = the whole window)",
                                                       low_open=False), default=None, metavar="S,S,...",
                   help="with --select, also choose the block length among these seconds (0 = one descriptor "
                   "per window) by the same cross-validation inside the training trials (default: --block's)")
    p.add_argument("--rocket", default=None, metavar="FILE",
                   help="the rocket group's transforms from FILE (written by tactile fit-rocket, e.g. of another "
                   "size) instead of config/rocket/<cell type>.json")
    p.add_argument("--select-rocket", default=None, metavar="FILE,FILE,...",
                   help="with --select, also choose the rocket group's transforms among these files (fitted on the "
                   "training trials) for the modes that hold the group, by the same cross-validation")
    p.add_argument("--c-grid", type=number_list("C values"), default=None, metavar="C,C,...",
                   help="the SVM's candidate C values (default: the paper's 15)")
    p.add_argument("--scaling", default="log_standardize", choices=list(SCALINGS))
    p.add_argument("--gate", action=argparse.BooleanOptionalAction, default=False,
                   help="contact gate (eq. 16; off by default: recorded slides are all in contact and the "
                   "tared PDC misfires on soft materials, see lab/docs/evaluation.md)")
    p.add_argument("--pa-update", default=RECOMMENDED_PA_UPDATE, choices=list(PA_UPDATES),
                   help="online update: arow (default; second-order), max_loss, or prediction (the paper's "
                   "eq. 30-32)")
    p.add_argument("--pa-average", action=argparse.BooleanOptionalAction, default=RECOMMENDED_PA_AVERAGE,
                   help="predict with averaged weights (default off; --pa-update prediction --no-pa-average "
                   "is the paper's PA-I)")
    p.add_argument("--drop", default="", help="quantities to leave out, e.g. L,N (ablation)")
    p.add_argument("--train-windows", type=int, default=None,
                   help="random windows per training trial (default: at least 8, and 16 s of windows per trial: "
                   "8 at 2 s and longer, 16 at 1 s, 32 at 0.5 s)")
    p.add_argument("--test-windows", type=int, default=2, help="random windows per test trial")
    p.add_argument("--cv-repeats", type=int, default=CV_REPEATS,
                   help=f"repeats of the 5-fold CV choosing C (default {CV_REPEATS}; the paper's 10 chose the same C "
                        "on the shared recordings, docs/evaluation.md)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--cache", default="build/cache", help="descriptor cache folder ('' = off)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.add_argument("--live", action="store_true",
                   help="replay the trials through the live window and classifier nodes (one window per trial, "
                   "its first --window seconds) and check they give this evaluation's descriptors and predictions")
    p.add_argument("--timeout", type=float, default=120.0,
                   help="--live: longest wait for any one event of the live graph, in seconds")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the evaluation and print accuracy and confusion matrices (or JSON)."""
    if args.live:
        if args.channels is None:
            from tactile_descriptors_lab.evaluation.bank import DEFAULT_MODE

            args.channels = DEFAULT_MODE
        return run_live(args)
    from tactile_descriptors_lab.datasets.readers import LoadReport, align_classes, check_selection
    from tactile_descriptors_lab.evaluation.bank import mode_groups, recordings_cell_type
    from tactile_descriptors_lab.evaluation.experiments import CLASSIFIERS, EvalConfig, evaluate
    from tactile_descriptors_lab.evaluation.rocket_fit import transform_in_use
    from tactile_descriptors_lab.evaluation.sampling import load_split
    from tactile_descriptors_lab.verbs.cmd_import import parse_classes

    candidates = [m.strip() for m in args.select.split(",") if m.strip()] if args.select else []
    if candidates:
        args.channels = candidates[0]
    asked = args.channels is not None
    for mode in candidates or ([args.channels] if asked else []):
        mode_groups(mode)  # an unknown mode is refused before any data is read
    select_blocks = args.select_blocks
    if select_blocks is not None and not candidates:
        raise ConfigError("--select-blocks chooses among blocks with --select: give the modes too",
                          key="select-blocks")
    rockets = _rocket_files(args, candidates)
    c_grid = tuple(args.c_grid) if args.c_grid else None
    train_trials, test_trials = default_trials(args.train, args.test, args.train_trials, args.test_trials)
    materials = parse_classes(args.materials) if args.materials else None
    if (args.train_windows is not None and args.train_windows < 1) or args.test_windows < 1 or args.cv_repeats < 1:
        raise ConfigError("--train-windows, --test-windows and --cv-repeats must be >= 1")
    _block_setting(args)
    classifiers = CLASSIFIERS if args.classifier == "all" else (args.classifier,)
    drop = tuple(q.strip() for q in args.drop.split(",") if q.strip())
    test_mapping = args.test_mapping or args.mapping
    reports = [LoadReport(args.train, ""), LoadReport(args.test, "")]
    if Path(args.train).resolve() == Path(args.test).resolve() and test_mapping == args.mapping:
        both = None  # with both ranges given, only their trials are read
        if train_trials is not None and test_trials is not None:
            both = sorted(set(train_trials) | set(test_trials))
        every = load_split(args.train, both, materials, args.mapping, report=reports[0])
        reports = reports[:1]
        train_trials, test_trials = split_trials(sorted({r.trial for r in every}), train_trials, test_trials,
                                                 args.train_trials is not None, args.test_trials is not None)
        train = check_selection(every, train_trials, None, args.train)
        test = check_selection(every, test_trials, None, args.test)
    else:
        every = None
        train = load_split(args.train, train_trials, materials, args.mapping, report=reports[0])
        test = load_split(args.test, test_trials, materials, test_mapping, report=reports[1])
    train, test = align_classes(train, test)
    check_classes(train, test, args.train, args.test, every)
    # the modes are checked with the transform they will run (a cell type may have none in config/rocket)
    with transform_in_use(args.rocket or (rockets[0] if rockets else None),
                          recordings_cell_type(list(train) + list(test))):
        args.channels = resolve_mode(list(train) + list(test), args.channels)
        if not candidates:
            _check_rocket_mode(args)
        for mode in candidates or [args.channels]:
            check_recordings(list(train) + list(test), mode)
    for rep in reports:
        for line in rep.tare_lines():
            print(f"{rep.source}: {line}", file=sys.stderr)
        for line in rep.note_lines():
            print(f"{rep.source}: warning: {line}", file=sys.stderr)
    cfg = EvalConfig(window=args.window, test_window=args.test_window, mode=args.channels,
                     classifiers=tuple(classifiers), seed=args.seed, train_per_trial=args.train_windows,
                     test_per_trial=args.test_windows, scaling=args.scaling, gate=args.gate, drop=drop,
                     pa_update=args.pa_update, pa_average=args.pa_average,
                     cv_repeats=args.cv_repeats, windows=args.windows, jobs=args.jobs,
                     cache_dir=args.cache or None,
                     block_s=args.block or None, block_hop_s=args.block_hop if args.block else None,
                     rocket_file=args.rocket, progress=True, **({"c_grid": c_grid} if c_grid else {}))
    if candidates:
        from ..evaluation.experiments import evaluate_selected

        result = evaluate_selected(train, test, cfg, candidates, blocks=select_blocks, block_hop_s=args.block_hop,
                                   rockets=rockets)
        args.channels = result["selection"]["chosen"]
        args.block = result["selection"]["block_s"] or 0.0
        args.rocket = result["selection"]["rocket_file"] or args.rocket
    else:
        result = evaluate(train, test, cfg)
    if args.json:
        out = dict(result)
        if args.classifier != "all":  # with all, each classifier's object carries its accuracy
            out["accuracy"] = result["classifiers"][args.classifier]["accuracy"]
        print(json.dumps(out))
        return 0
    blocks = f"mean over {args.block:g} s blocks" if args.block else "one descriptor per window"
    if candidates:
        sel = result["selection"]
        print(f"selection by trial cross-validation inside the training trials ({sel['classifier']}, blocks "
              + ", ".join(f"{a}-{b}" for a, b in sel["folds"]) + "): "
              + "; ".join(f"{m} {100 * v['accuracy']:.1f} +- {100 * v['accuracy_std']:.1f} %"
                          for m, v in sel["candidates"].items()) + f" -> {sel['chosen_label']}")
        for label, why in sel["skipped"].items():
            print(f"  not tried: {label} ({why})")
    transform = f", rocket transform {args.rocket}" if args.rocket and "rocket" in mode_groups(args.channels) else ""
    print(f"descriptor mode {args.channels} ({result['n_features']} values, {blocks}{transform}), window {args.window} s "
          f"(test {args.test_window or args.window}), crop {result['common_length_s']:.2f} s; "
          f"{result['n_train']} training and {result['n_test']} test windows ({args.windows} positions); "
          f"contact gate {'on' if args.gate else 'off'}")
    if result["trials_without_contact_window"]:
        miss = result["trials_without_contact_window"]
        print(f"{len(miss)} trials have no window wholly in contact and give none: {', '.join(miss[:10])}"
              + (" ..." if len(miss) > 10 else ""))
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
        print("  confusion (rows: true " + " ".join(str(c) for c in result["classes"]) + "; "
              + ", ".join(f"{c} {n}" for c, n in zip(result["classes"], result["class_names"])) + "):")
        for c, row in zip(result["classes"], cm):
            print(f"  {c:>3} " + " ".join(f"{v:3d}" for v in row))
    return 0




def _rocket_files(args: argparse.Namespace, candidates: list[str]) -> list[str] | None:
    """Check ``--rocket`` and ``--select-rocket`` before any data is read; the files to select among, or None."""
    from tactile_descriptors_lab.evaluation.rocket_fit import check_transform_file

    rockets = [f.strip() for f in args.select_rocket.split(",") if f.strip()] if args.select_rocket else None
    if args.select_rocket is not None and not rockets:
        raise ConfigError("--select-rocket needs at least one transform file", key="select-rocket")
    if rockets and not candidates:
        raise ConfigError("--select-rocket chooses among transforms with --select: give the modes too",
                          key="select-rocket")
    if rockets and args.rocket:
        raise ConfigError("give the transform (--rocket) or the files to choose among (--select-rocket), not both",
                          key="rocket")
    if not candidates and args.channels is not None:
        _check_rocket_mode(args)
    for path in [args.rocket] if args.rocket else rockets or []:
        check_transform_file(path)
    return rockets


def _check_rocket_mode(args: argparse.Namespace) -> None:
    """Refuse ``--rocket`` with a mode that has no ``rocket`` group (the file would change nothing)."""
    from tactile_descriptors_lab.evaluation.bank import mode_groups

    if args.rocket and "rocket" not in mode_groups(args.channels):
        raise ConfigError(f"--rocket gives the rocket group's transforms, and mode {args.channels} has no rocket "
                          "group", key="rocket")


def _block_setting(args: argparse.Namespace) -> None:
    """Resolve ``--block`` (default :data:`~..evaluation.windows.DEFAULT_BLOCK_S`) and check it with ``--block-hop``."""
    if args.block is None:
        from tactile_descriptors_lab.evaluation.sampling import DEFAULT_BLOCK_S

        args.block = DEFAULT_BLOCK_S
    if args.block < 0 or not args.block_hop > 0 or (args.block and args.block_hop > args.block):
        raise ConfigError(f"--block {args.block:g} / --block-hop {args.block_hop:g}: need a block >= 0 "
                          "(0 = off) and a hop > 0 no longer than the block", key="block")


def run_live(args: argparse.Namespace) -> int:
    """``--live``: offline and live on the same windows; exit 1 unless descriptors and predictions agree."""
    import tempfile

    from tactile_descriptors_lab.datasets.importer import ImportOptions, import_recordings
    from tactile_descriptors_lab.evaluation.live_check import (
        check_segmentable,
        compare,
        offline_replay,
        plan_steps,
    )
    from tactile_descriptors_lab.evaluation.live_replay import run_live_replay
    from tactile_descriptors_lab.evaluation.sampling import common_length_frames, load_split, window_frames
    from tactile_descriptors_lab.verbs.cmd_import import parse_classes

    if Path(args.train).resolve() != Path(args.test).resolve() or (args.test_mapping or args.mapping) != args.mapping:
        raise ConfigError("--live replays one source: give the same source to --train and --test", key="test")
    refusals = {"test-window": args.test_window not in (None, args.window), "gate": args.gate, "drop": args.drop,
                "windows": args.windows != "random", "select": args.select, "select-blocks": args.select_blocks,
                "rocket": args.rocket, "select-rocket": args.select_rocket}
    bad = [k for k, v in refusals.items() if v]
    if bad:
        raise ConfigError(f"--live scores one window per trial (its first --window seconds) with the nodes' "
                          f"descriptor, the contact gate off: leave out --{bad[0]}", key=bad[0])
    from tactile_descriptors_lab.evaluation.bank import DESCRIPTOR_MODES, mode_groups

    groups = list(mode_groups(args.channels))
    if "subwindows" in groups:
        live_modes = [m for m, g in DESCRIPTOR_MODES.items() if "subwindows" not in g]
        raise ConfigError(f"the window node does not compute the subwindows group of mode {args.channels!r}; "
                          f"--live takes {', '.join(['averaged', *live_modes])}", key="channels")
    train_trials, test_trials = default_trials(args.train, args.test, args.train_trials, args.test_trials)
    materials = parse_classes(args.materials) if args.materials else None
    both = None if train_trials is None or test_trials is None else sorted(set(train_trials) | set(test_trials))
    every = load_split(args.train, both, materials, args.mapping)
    from tactile_descriptors_lab.datasets.recording import BiotacRecording

    if not all(isinstance(r, BiotacRecording) for r in every):
        raise ConfigError("--live replays BioTac recordings through the window node; these hold cell type "
                          f"{getattr(every[0], 'cell_type', '?')!r}: leave out --live", key="live")
    train_trials, test_trials = split_trials(sorted({r.trial for r in every}), train_trials, test_trials,
                                             args.train_trials is not None, args.test_trials is not None)
    chosen = set(train_trials) | set(test_trials)
    recs = [r for r in every if r.trial in chosen]
    common = common_length_frames(recs)
    n_frames = window_frames(args.window, 100.0, common)
    steps = plan_steps(recs, train_trials, test_trials)
    check_segmentable(recs, steps, n_frames)
    _block_setting(args)  # the window node averages the same blocks (descriptor.block_s / block_hop_s)
    offline = offline_replay(recs, steps, n_frames, args.channels, pa_update=args.pa_update,
                             pa_average=args.pa_average, scaling=args.scaling, cache_dir=args.cache or None,
                             jobs=args.jobs, block_s=args.block, block_hop_s=args.block_hop)
    with tempfile.TemporaryDirectory(prefix="tactile_evaluate_live_") as tmp:
        bag = Path(tmp) / "bag"
        report = import_recordings(recs, bag, options=ImportOptions(max_frames=n_frames, order="trial"))
        if [(t.material, t.trial) for t in report.trials] != [(s.material, s.trial) for s in steps]:
            raise ConfigError("the bag's trial order differs from the replay plan")
        run = run_live_replay(
            bag, [t.start_ns for t in report.trials], [s.train for s in steps], [s.class_name for s in steps],
            [t.end_ns for t in report.trials],
            window_parameters={"descriptor.groups": groups, "descriptor.block_s": float(args.block),
                               "descriptor.block_hop_s": float(args.block_hop)},
            classifier_parameters={"pa_update": args.pa_update, "pa_average": bool(args.pa_average),
                                   "log_activity": args.scaling == "log_standardize",
                                   "standardize": args.scaling != "none"},
            timeout_s=args.timeout)
    out = compare(offline, run.values, run.labels, run.predictions)
    out.update({"mode": args.channels, "window_frames": n_frames, "window_s": n_frames / 100.0,
                "block_s": float(args.block), "block_hop_s": float(args.block_hop),
                "train_trials": sorted(train_trials), "test_trials": sorted(test_trials),
                "classes": sorted({s.class_name for s in steps}), "labels_taught": run.labels_taught,
                "n_features": len(run.labels), "window_node_faults": run.window_node_faults,
                "live_wall_s": round(run.wall_s, 1), "pa_update": args.pa_update,
                "pa_average": bool(args.pa_average), "scaling": args.scaling})
    ok = out["descriptors_match"] and out["predictions_match"]
    if args.json:
        print(json.dumps(out))
        return 0 if ok else 1
    print(f"live replay: {out['windows']} windows ({out['train_windows']} taught, {out['test_windows']} scored) of "
          f"{out['window_s']:.2f} s through window_node and classifier_node, descriptor mode {args.channels} "
          f"({out['n_features']} values), {out['live_wall_s']:.0f} s")
    print(f"live accuracy {100 * out['live_accuracy']:.2f} %, offline {100 * out['offline_accuracy']:.2f} %; "
          f"predictions agree on {100 * out['prediction_agreement']:.1f} % of windows; largest relative "
          f"descriptor difference {out['max_relative_descriptor_difference']:.2e}")
    for m in out["mismatched_windows"]:
        print(f"  mismatch: material {m['material']} trial {m['trial']}: live {m['live']}, offline {m['offline']}, "
              f"relative difference {m['max_relative_difference']:.2e}")
    print("live = offline" if ok else "live differs from offline")
    return 0 if ok else 1
