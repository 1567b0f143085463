"""``tactile report``: regenerate lab/docs/results.md and lab/docs/figures/*.png from the real recordings."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from tactile_descriptors_ros.errors import ConfigError

__all__ = ["register", "run"]


def register(subparsers) -> None:
    """Add the ``report`` subcommand."""
    p = subparsers.add_parser(
        "report", help="run every evaluation on recorded BioTac trials and write results.md with plots",
        description="Runs the headline, window-length sweep, exploration-time, ablation and trial-CV "
        "experiments (see lab/docs/evaluation.md) and writes <out>/results.md, <out>/results.json and "
        "<out>/figures/*.png.")
    p.add_argument("--data", required=True, help="folder of the recordings (holding raw_data/)")
    p.add_argument("--out", default="lab/docs", help="output folder (default lab/docs)")
    p.add_argument("--materials", default=None, help="material range (default: all)")
    p.add_argument("--trials", default=None, help="trial range (default: all)")
    p.add_argument("--quick", action="store_true", help="a small plan (for tests and smoke runs)")
    p.add_argument("--only", default=None,
                   help="recompute only these sections (comma-separated, or 'length' for the touch-length "
                   "sections), keep the others from <out>/results.json and render results.md again")
    p.add_argument("--readme", default=None,
                   help="also rewrite the generated 'What to expect' block of this README from the results")
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--cache", default="build/cache", help="descriptor cache folder ('' = off)")
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Build the report."""
    from tactile_descriptors_lab.evaluation.report import (
        FULL_PLAN,
        LENGTH_SECTIONS,
        QUICK_PLAN,
        README_BEGIN,
        README_END,
        build_report,
        update_readme,
    )
    from tactile_descriptors_lab.evaluation.sampling import parse_trials

    if args.readme:  # a README without the block fails now, not after the run
        text = Path(args.readme).read_text() if Path(args.readme).is_file() else ""
        if README_BEGIN not in text or README_END not in text:
            raise ConfigError(f"{args.readme}: no generated 'What to expect' block ({README_BEGIN} ... "
                              f"{README_END})", key="readme")
    only = None
    if args.only is not None:
        only = []
        for name in (n.strip() for n in args.only.split(",") if n.strip()):
            only += list(LENGTH_SECTIONS) if name == "length" else [name]
    res = build_report(args.data, args.out, plan=QUICK_PLAN if args.quick else FULL_PLAN,
                       materials=parse_trials(args.materials) if args.materials else None,
                       trials=parse_trials(args.trials) if args.trials else None,
                       jobs=args.jobs, cache_dir=args.cache or None, progress=True, only=only)
    if args.readme:
        update_readme(args.readme, res)
    if args.json:
        print(json.dumps({"results_md": f"{args.out}/results.md", "runtime_s": res["runtime_s"],
                          **{sec: {k: {c: v["accuracy"] for c, v in r["classifiers"].items()}
                                   for k, r in res[sec].items()}
                             for sec in ("headline", "length", "length_cv", "short") if res.get(sec)}}))
    else:
        took = res["section_runtime_s"].get(only[0]) if only else res["runtime_s"]
        print(f"wrote {args.out}/results.md in {took:.0f} s")
    return 0
