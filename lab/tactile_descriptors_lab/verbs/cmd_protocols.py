"""``tactile protocols``: the paper's protocols on simulated robots, beside the paper's numbers.

Example::

    tactile protocols --out lab/docs          # lab/docs/simulated.md, .json, figures/simulated_pa_curves.png
    tactile protocols --quick --json        # a small plan, one JSON object on stdout

Every number it writes is **simulated**: see lab/docs/simulated.md.
"""

from __future__ import annotations

import argparse
import json

from tactile_descriptors_ros.errors import ConfigError

__all__ = ["register", "run"]


def register(subparsers) -> None:
    """Add the ``protocols`` subcommand."""
    p = subparsers.add_parser(
        "protocols", help="run the paper's protocols on simulated robots and write lab/docs/simulated.md",
        description="Simulates the paper's protocols (Shadow Hand finger subsets and combined motions, NAO right "
        "hand -> left hand, large objects at three weights), scores SVM, online PA-I curves and GMM-EM/NMI, "
        "and writes <out>/simulated.md, <out>/simulated.json and <out>/figures/simulated_pa_curves.png "
        "beside the paper's own numbers. Simulated, not real data.")
    p.add_argument("--out", default="lab/docs", help="output folder (default lab/docs; '' = write nothing)")
    p.add_argument("--quick", action="store_true", help="a small plan (few materials, short tests; a smoke run)")
    p.add_argument("--plan", default=None, choices=("full", "quick", "skin_groups"),
                   help="the plan: full (default), quick (= --quick) or skin_groups (the NAO protocols on the "
                   "skin cells' candidate feature groups, docs/decisions.md)")
    p.add_argument("--protocol", action="append", default=None, metavar="NAME",
                   help="run only this protocol (repeatable); default: all of the plan")
    p.add_argument("--json", action="store_true", help="print one JSON object (summary) on stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the plan, write the report, print a summary."""
    import dataclasses

    from tactile_descriptors_lab.protocols import (
        FULL_PLAN,
        QUICK_PLAN,
        SKIN_GROUPS_PLAN,
        results_table,
        run_protocols,
        write_report,
    )

    plans = {"full": FULL_PLAN, "quick": QUICK_PLAN, "skin_groups": SKIN_GROUPS_PLAN}
    if args.quick and args.plan not in (None, "quick"):
        raise ConfigError(f"--quick and --plan {args.plan} name two plans", key="plan")
    plan = plans[args.plan or ("quick" if args.quick else "full")]
    if args.protocol:
        plan = dataclasses.replace(plan, protocols=tuple(args.protocol))
    results = run_protocols(plan, progress=True)
    written = write_report(results, args.out) if args.out else {}
    modes = list(plan.modes)
    if args.json:
        summary = {
            "simulated": True, "plan": plan.name, "runtime_s": results["runtime_s"], "written": written,
            "protocols": {
                k: {tn: {m: {"svm": r["svm"]["accuracy"],
                             **({"pa_plain": r["pa"]["plain"]["final"], "pa_max_loss_avg": r["pa"]["max_loss_avg"]["final"],
                                 "nmi": r["gmm"]["nmi_test"]} if "pa" in r else {})}
                         for m, r in t["modes"].items()}
                    for tn, t in p["tests"].items()}
                for k, p in results["protocols"].items() if "error" not in p},
            "errors": {k: p["error"] for k, p in results["protocols"].items() if "error" in p},
        }
        print(json.dumps(summary))
        return 1 if summary["errors"] else 0
    print("SIMULATED, not real data")
    for row in results_table(results):
        vals = "  ".join(f"{m}={row[m]}" for m in modes)
        paper = row["paper_number"].split(" (")[0]
        print(f"{row['protocol']:<22} {row['test']:<18} {row['measure']:<26} paper={paper:<8} {vals}")
    failed = [k for k, p in results["protocols"].items() if "error" in p]
    if written:
        print(f"wrote {written['markdown']}, {written['json']} and {written['figure']} "
              f"in {results['runtime_s']:.0f} s")
    return 1 if failed else 0
