"""``tactile import SOURCE -o BAG``: turn BioTac recordings into a replayable bag.

SOURCE is a folder or file of tables (CSV, NPZ, HDF5) described by a mapping
file (``--mapping``; default the shipped ``biotac_slide_20_50`` layout
``raw_data/mat<M>/mat<M>_<N>_bio.csv``), or ROS 1/ROS 2 bags of Shadow Robot
``sr_robot_msgs/BiotacAll`` or UPenn ``biotac_sensors/BioTacHand``.  Each
trial becomes BioTacFrameBatch messages (10 frames = 100 ms a message, full-rate PAC with per-sample
offsets, CSV time stamps), followed by a release gap of no-contact frames and
a Label with the class name taken from the data, so ``tactile replay`` drives
the live window and classifier nodes exactly as a robot would.  Untared
pressure is tared per trial (and said so); every import prints how many
frames and trials pass the contact gate (force from PDC >= F_t).
See lab/docs/import.md.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

__all__ = ["register", "run", "parse_classes"]


def parse_classes(text: str) -> list[str]:
    """``"1-3,cork"`` -> ``["1", "2", "3", "cork"]``: numbers and ranges of numbers, or class names."""
    from tactile_descriptors_lab.datasets.importer import parse_index_ranges

    out: list[str] = []
    for part in (p.strip() for p in text.split(",")):
        if not part:
            continue
        if part.replace("-", "").isdigit():
            out.extend(str(i) for i in parse_index_ranges(part))
        else:
            out.append(part)
    return out


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("import", help="convert BioTac recordings (tables or bags) into a bag",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("data_dir", type=Path, metavar="SOURCE",
                   help="folder or file of tables, or bags (a .bag file, a rosbag2 folder, or a folder of them)")
    p.add_argument("-o", "--output", type=Path, required=True, help="bag directory to create")
    p.add_argument("--mapping", default=None,
                   help="mapping file or shipped mapping name (default: biotac_slide_20_50 for tables; "
                   "bags need none)")
    p.add_argument("--class", dest="class_name", default=None, help="class of every trial (overrides the mapping)")
    p.add_argument("--tare", choices=("auto", "per_trial", "none"), default=None,
                   help="tare PDC and electrodes per trial: auto (when the resting level is far from zero; "
                   "the mapping's default), per_trial, none")
    p.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap", help="bag storage (default mcap)")
    p.add_argument("--trials", default=None, help="trials, e.g. 1-30 or 1,3,5 (default: all found)")
    p.add_argument("--materials", "--classes", dest="materials", default=None,
                   help="classes by number or name, e.g. 1-20, 2,12 or cork,felt (default: all found)")
    p.add_argument("--robot", default="shadow_hand", help="robot description (scales, sensor name, F_t)")
    p.add_argument("--body-part", default="index", help="body part carrying the BioTac (default index)")
    p.add_argument("--frames-per-batch", type=int, default=10, help="frames per message (default 10 = 100 ms)")
    p.add_argument("--release-s", type=float, default=1.0, help="gap between trials in seconds (default 1)")
    p.add_argument("--no-release-fill", action="store_true",
                   help="leave the gap silent instead of filling it with no-contact frames")
    p.add_argument("--label-delay-s", type=float, default=0.5,
                   help="label time after a trial's end, inside the gap (default 0.5)")
    p.add_argument("--order", choices=("trial", "material"), default="trial",
                   help="trial: trial 1 of every material, then trial 2 ... (default); material: grouped")
    p.add_argument("--max-frames", type=int, default=None, help="crop every trial to this many frames")
    p.add_argument("--biotac-topic", default=None, help="topic of the frame batches (default /tactile/<body part>/frames)")
    p.add_argument("--label-topic", default=None, help="topic of the labels (default /tactile/label)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from tactile_descriptors_lab.datasets.importer import (
        DEFAULT_BIOTAC_TOPIC,
        DEFAULT_LABEL_TOPIC,
        ImportOptions,
        import_source,
        parse_index_ranges,
    )

    options = ImportOptions(
        robot=args.robot, body_part=args.body_part, frames_per_batch=args.frames_per_batch,
        release_s=args.release_s, release_fill=not args.no_release_fill, label_delay_s=args.label_delay_s,
        order=args.order, max_frames=args.max_frames,
        biotac_topic=args.biotac_topic or DEFAULT_BIOTAC_TOPIC, label_topic=args.label_topic or DEFAULT_LABEL_TOPIC,
    )
    trials = parse_index_ranges(args.trials) if args.trials else None
    classes = parse_classes(args.materials) if args.materials else None

    def progress(recs):
        from tqdm import tqdm

        return tqdm(recs, desc="import", unit="trial", file=sys.stderr, disable=None)

    report = import_source(args.data_dir, args.output, mapping=args.mapping, trials=trials, classes=classes,
                           class_name=args.class_name, tare=args.tare, options=options, storage=args.storage,
                           progress=progress)
    if args.json:
        print(json.dumps(report.to_dict()))
        return 0
    print(f"wrote {args.output} ({args.storage}): {len(report.trials)} trials, {report.batches} BioTacFrameBatch "
          f"on {options.biotac_topic.format(body_part=options.body_part)} "
          f"({report.frames} recorded + {report.release_frames} release frames), "
          f"{report.labels} Label on {options.label_topic}")
    names = sorted({(t.material, t.material_name) for t in report.trials})
    print(f"classes ({len(names)}, from the data; mapping {report.mapping}): "
          + ", ".join(f"{m} {n}" for m, n in names))
    for line in report.tare_notes:
        print(line)
    for line in report.notes:
        print(f"warning: {line}", file=sys.stderr)
    print(f"contact gate (force = PDC x {report.force_n_per_count:g} N/count >= {report.force_threshold_n:g} N): "
          f"{report.frames_in_contact}/{report.frames} frames ({100 * report.contact_fraction:.1f} %), "
          f"{report.trials_passing_gate}/{len(report.trials)} trials by mean force")
    weak = [t for t in report.trials if t.contact_fraction < 0.5]
    for t in weak[:10]:
        print(f"  low contact: mat{t.material} ({t.material_name}) trial {t.trial}: "
              f"{100 * t.contact_fraction:.0f} % of frames, mean {t.mean_force_n:.2f} N")
    if len(weak) > 10:
        print(f"  ... and {len(weak) - 10} more trials under 50 % contact")
    return 0
