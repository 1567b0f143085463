"""``tactile urdf ROBOT``: the robot description's cell and site frames as URDF (docs/view.md).

Standalone (default): the root, the body parts' links at their rest pose,
every cell and site as a link on a fixed joint.  ``--xacro``: a macro
(``<robot>_tactile``, parameter ``prefix``) of the cell and site frames on
the robot's own links, to include in its URDF so that robot_state_publisher
publishes them.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("urdf", help="write the cells' frames as URDF or a xacro macro",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("robot", help="robot name (shadow_hand, nao) or YAML path")
    p.add_argument("--xacro", action="store_true", help="a xacro macro of the cell and site frames only")
    p.add_argument("--no-sites", action="store_true", help="leave out the sensing sites (BioTac electrodes)")
    p.add_argument("-o", "--output", default=None, help="file to write (default: stdout)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..core.robot import load_robot
    from ..core.urdf import urdf_text

    text = urdf_text(load_robot(args.robot), xacro=args.xacro, sites=not args.no_sites)
    if args.output:
        Path(args.output).write_text(text)
        print(f"tactile urdf: wrote {args.output}", file=sys.stderr)
    else:
        sys.stdout.write(text)
    return 0
