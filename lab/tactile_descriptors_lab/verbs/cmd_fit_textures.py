"""``tactile fit-textures DATA_DIR -o DIR``: fit the simulator's texture models to real BioTac recordings.

Writes one small JSON file per material (AR model of PAC, electrode and PDC
statistics; see :mod:`tactile_descriptors_ros.sim.textures`) into ``-o DIR``,
by default ``texture_models`` in the current directory: never into the
installed package (regenerating the shipped models is an explicit
``-o tactile_descriptors_ros/sim/models`` in a checkout).  Only the fitted
parameters are written, never the data.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

__all__ = ["register", "run", "DEFAULT_OUTPUT"]

#: Output folder when ``-o`` is not given (relative to the current directory).
DEFAULT_OUTPUT = Path("texture_models")


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("fit-textures", help="fit simulator texture models to BioTac recordings",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("data_dir", type=Path, help="folder holding raw_data/mat<M>/mat<M>_<N>_bio.csv")
    p.add_argument("-o", "--output", type=Path, default=None,
                   help=f"output folder (default: ./{DEFAULT_OUTPUT})")
    p.add_argument("--trials", default=None, help="trials to use, e.g. 1-30 (default: all found)")
    p.add_argument("--pac-order", type=int, default=12, help="AR order of the PAC model (default 12)")
    p.add_argument("--segment-s", type=float, default=2.0, help="statistics over segments of this length (default 2 s)")
    p.add_argument("--json", action="store_true", help="print one JSON summary on stdout")
    p.set_defaults(func=run)


def _parse_trials(text: str | None) -> list[int] | None:
    if not text:
        return None
    out: list[int] = []
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        out += list(range(int(lo), int(hi or lo) + 1))
    return out


def run(args: argparse.Namespace) -> int:
    from tactile_descriptors_lab.textures.fitting import fit_materials
    from tactile_descriptors_ros.sim.textures import save_material

    out = args.output or DEFAULT_OUTPUT
    out.mkdir(parents=True, exist_ok=True)
    models = fit_materials(args.data_dir, trials=_parse_trials(args.trials), progress=not args.json,
                           pac_order=args.pac_order, segment_s=args.segment_s)
    written = []
    for m in models:
        path = out / f"{m.name}.json"
        save_material(m, path)
        written.append({"material": m.name, "path": str(path), "bytes": path.stat().st_size,
                        "pac_std_counts": round(m.vibration.variance ** 0.5, 2)})
    if args.json:
        print(json.dumps({"output": str(out), "materials": written}))
    else:
        for w in written:
            print(f"{w['material']:<22} {w['bytes']:>6} B  PAC std {w['pac_std_counts']:.1f} counts  -> {w['path']}")
    return 0
