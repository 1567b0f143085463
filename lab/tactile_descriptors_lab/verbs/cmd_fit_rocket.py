"""``tactile fit-rocket DATA --trials 1-20 -o FILE``: fit the ``rocket`` feature group on training recordings.

Draws the training windows ``tactile evaluate`` draws (1 s blocks, seeded
random positions in the common-length crop), fits MiniRocket's dilations,
channel combinations and biases for the vibration signal and for the slow
channels (:mod:`tactile_descriptors_lab.evaluation.rocket_fit`) and writes
them as JSON.  The window node reads ``config/rocket/<cell type>.json``;
the shipped ``config/rocket/biotac.json`` was written by::

    tactile fit-rocket ../shared/data/biotac_slide_20_50 --trials 1-20 -o config/rocket/biotac.json

Fit on training trials only: the biases are quantiles of training signals,
and an evaluation whose test trials fed them has seen its test data.

``--vibration-features``, ``--slow-features`` and ``--vibration-max-dilation``
size the transforms (the shipped file: 420, 840 and 12); a larger transform
costs the window node in proportion.  To evaluate one without touching the
shipped file, write it anywhere and give it to ``tactile evaluate --rocket``
(or several to ``--select-rocket``, which chooses inside the training trials).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from tactile_descriptors_ros.tools.arguments import positive_int

__all__ = ["register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("fit-rocket", help="fit the rocket feature group's transforms on training recordings",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("data", help="recordings (any source tactile import reads)")
    p.add_argument("--mapping", default=None, help="mapping of a table source (see docs/import.md)")
    p.add_argument("--trials", default=None, help="training trials, e.g. 1-20 (default: all)")
    p.add_argument("-o", "--output", type=Path, required=True, help="the JSON file to write")
    p.add_argument("--seed", type=int, default=0, help="window positions and random choices (default 0)")
    p.add_argument("--vibration-features", type=positive_int, default=None,
                   help="features of the vibration transform, at least 84 (default 420)")
    p.add_argument("--slow-features", type=positive_int, default=None,
                   help="features of the slow channels' transform, at least 84 (default 840)")
    p.add_argument("--vibration-max-dilation", type=positive_int, default=None,
                   help="largest dilation of the vibration transform, in samples (default 12)")
    p.add_argument("--json", action="store_true", help="print one JSON summary on stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from tactile_descriptors_lab.evaluation.rocket_fit import (
        SLOW_FEATURES,
        VIBRATION_FEATURES,
        VIBRATION_MAX_DILATION,
        fit_rocket,
        write_rocket,
    )
    from tactile_descriptors_lab.evaluation.sampling import format_trials, load_split, parse_trials

    trials = parse_trials(args.trials)
    recs = load_split(args.data, trials, mapping=args.mapping)
    defaults = {"vibration_features": VIBRATION_FEATURES, "slow_features": SLOW_FEATURES,
                "vibration_max_dilation": VIBRATION_MAX_DILATION}
    sizes = {k: getattr(args, k) or v for k, v in defaults.items()}  # an option given is at least 1
    params = fit_rocket(recs, seed=args.seed, **sizes)
    used = sorted({r.trial for r in recs})
    desc = (f"fitted by tactile fit-rocket on {len(recs)} recordings ({len({r.material for r in recs})} classes, "
            f"trials {format_trials(used)}), seed {args.seed}")
    if sizes != defaults:
        desc += ", " + ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in sizes.items())
    path = write_rocket(args.output, params, desc)
    summary = {"output": str(path), "recordings": len(recs), "trials": format_trials(used),
               "features": {k: v.n_features for k, v in params.items()},
               "dilations": {k: v.dilations.tolist() for k, v in params.items()}}
    print(json.dumps(summary) if args.json else
          f"wrote {path}: " + ", ".join(f"{k} {v.n_features} features (dilations {v.dilations.tolist()})"
                                       for k, v in params.items()))
    return 0
