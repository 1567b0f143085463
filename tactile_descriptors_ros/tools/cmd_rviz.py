"""``tactile rviz ROBOT``: an rviz2 configuration of the robot's skin (docs/view.md).

TF, and per body part the contact node's markers and tactile image, with
rviz2's default QoS and the robot's root as the fixed frame.  The package
ships them for its robots (``share/tactile_descriptors_ros/config/rviz/``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("rviz", help="write an rviz2 configuration of the robot's skin",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("robot", help="robot name (shadow_hand, nao) or YAML path")
    p.add_argument("-o", "--output", default=None, help="file to write (default: stdout)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..core.robot import load_robot
    from ..view.rviz import rviz_text

    text = rviz_text(load_robot(args.robot))
    if args.output:
        Path(args.output).write_text(text)
        print(f"tactile rviz: wrote {args.output}", file=sys.stderr)
    else:
        sys.stdout.write(text)
    return 0
