"""``tactile fuzz``: fuzz the wire-format codecs with random faults and known truth.

Thin over :func:`tactile_descriptors_lab.fuzz.fuzz_codec`.  Exit code 0
when every check passed, 1 when a violation was found.
"""

from __future__ import annotations

import argparse
import json
import sys

__all__ = ["register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``fuzz`` subcommand."""
    from tactile_descriptors_lab.fuzz import FUZZERS

    p = subparsers.add_parser(
        "fuzz", help="fuzz the wire-format codecs (BioTac SPI, bridge serial, skin CAN/serial)",
        description="Feed each codec random faults (bit flips, truncations, garbage, duplicates, "
        "drops, reordering, foreign and malformed frames, error words) built from known truth; "
        "check that nothing crashes, every error is counted and no value lands in the wrong "
        "channel, cell or finger.")
    p.add_argument("--codec", default="all", choices=["all", *FUZZERS],
                   help="codec to fuzz (default: all)")
    p.add_argument("--inputs", type=int, default=100_000, metavar="N",
                   help="random inputs per codec (default: 100000; `make fuzz` runs 1000000)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the fuzzers; return 0 if all passed, 1 otherwise."""
    from tqdm import tqdm

    from tactile_descriptors_lab.fuzz import FUZZERS, fuzz_codec
    from tactile_descriptors_ros.errors import ConfigError

    if args.inputs < 0:
        raise ConfigError("must be >= 0", key="--inputs")
    names = list(FUZZERS) if args.codec == "all" else [args.codec]
    reports = []
    for name in names:
        with tqdm(total=args.inputs, desc=name, unit="input", file=sys.stderr,
                  disable=args.json and not sys.stderr.isatty()) as bar:
            reports.append(fuzz_codec(name, args.inputs, seed=args.seed, progress=bar.update))
    ok = all(r.ok for r in reports)
    if args.json:
        print(json.dumps({"ok": ok, "seed": args.seed, "codecs": [r.as_dict() for r in reports]}))
    else:
        for r in reports:
            status = "ok" if r.ok else f"{r.violations} VIOLATIONS"
            print(f"{r.codec:14s} {r.inputs:>9d} inputs  {r.seconds:8.1f} s  "
                  f"{r.inputs_per_s:>9.0f} inputs/s  {status}")
            for ex in r.examples:
                print(f"    {ex}")
    return 0 if ok else 1
