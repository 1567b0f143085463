"""``tactile report``: regenerate docs/results.md and docs/figures/*.png from the real recordings."""

from __future__ import annotations

import argparse
import json

__all__ = ["register", "run"]


def register(subparsers) -> None:
    """Add the ``report`` subcommand."""
    p = subparsers.add_parser(
        "report", help="run every evaluation on recorded BioTac trials and write results.md with plots",
        description="Runs the headline, window-length sweep, exploration-time, ablation and trial-CV "
        "experiments (see docs/evaluation.md) and writes <out>/results.md, <out>/results.json and "
        "<out>/figures/*.png.")
    p.add_argument("--data", required=True, help="folder of the recordings (holding raw_data/)")
    p.add_argument("--out", default="docs", help="output folder (default docs)")
    p.add_argument("--materials", default=None, help="material range (default: all)")
    p.add_argument("--trials", default=None, help="trial range (default: all)")
    p.add_argument("--quick", action="store_true", help="a small plan (for tests and smoke runs)")
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--cache", default="build/cache", help="descriptor cache folder ('' = off)")
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Build the report."""
    from ..evaluation.report import FULL_PLAN, QUICK_PLAN, build_report
    from ..evaluation.windows import parse_trials

    res = build_report(args.data, args.out, plan=QUICK_PLAN if args.quick else FULL_PLAN,
                       materials=parse_trials(args.materials) if args.materials else None,
                       trials=parse_trials(args.trials) if args.trials else None,
                       jobs=args.jobs, cache_dir=args.cache or None, progress=True)
    if args.json:
        print(json.dumps({"results_md": f"{args.out}/results.md", "runtime_s": res["runtime_s"],
                          "headline": {k: {c: v["accuracy"] for c, v in r["classifiers"].items()}
                                       for k, r in res["headline"].items()}}))
    else:
        print(f"wrote {args.out}/results.md in {res['runtime_s']:.0f} s")
    return 0
