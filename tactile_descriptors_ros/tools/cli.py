"""``tactile``: one command-line entry point with subcommands.

Each robot subcommand lives in its own module ``tactile_descriptors_ros.tools.cmd_<name>``
that defines ``register(subparsers) -> None``; the parser it adds sets
``func`` (called with the parsed arguments, returns an exit code).  Modules
are discovered at start, so adding a subcommand touches no other file.
Subcommands stay thin: they parse arguments and call library functions.

Other packages add subcommands through the entry-point group
:data:`VERBS_GROUP` (name: the verb, value: its ``register`` function), as
the lab package ``tactile_descriptors_lab`` does for ``evaluate``,
``report``, ``bench``, ``import``, ``fuzz``, ``protocols`` and
``fit-textures``.  Without the lab, those verbs say in one line how to
install it and exit with status 2.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.metadata
import pkgutil
import sys
from collections.abc import Sequence

from ..errors import TactileError

__all__ = ["build_parser", "main", "VERBS_GROUP", "LAB_VERBS", "LAB_INSTALL"]

#: Entry-point group through which other packages add ``tactile`` subcommands.
VERBS_GROUP = "tactile_descriptors_ros.verbs"
#: The verbs of the lab package, named even when it is not installed.
LAB_VERBS = ("bench", "evaluate", "fit-rocket", "fit-textures", "fuzz", "import", "protocols", "report")
#: How to install the lab package.
LAB_INSTALL = "pip install ./lab (from the repository; make setup does it)"


def build_parser() -> argparse.ArgumentParser:
    """Build the ``tactile`` parser from every ``cmd_*`` module of this package."""
    parser = argparse.ArgumentParser(
        prog="tactile",
        description="Robust tactile descriptors for ROS 2: launch, evaluate, bench, "
        "record, replay, echo, import and more.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    package = importlib.import_module(__package__)
    for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda m: m.name):
        if info.name.startswith("cmd_"):
            module = importlib.import_module(f"{__package__}.{info.name}")
            module.register(sub)
    plugged = set()
    for ep in sorted(importlib.metadata.entry_points(group=VERBS_GROUP), key=lambda e: e.name):
        if ep.name in sub.choices:
            continue  # a verb of this package cannot be replaced by a plug-in
        ep.load()(sub)
        plugged.add(ep.name)
    for verb in LAB_VERBS:
        if verb not in plugged and verb not in sub.choices:
            _register_missing_lab_verb(sub, verb)
    return parser


def _register_missing_lab_verb(sub: argparse._SubParsersAction, verb: str) -> None:
    p = sub.add_parser(verb, help=f"(lab package not installed: {LAB_INSTALL})", add_help=False)
    p.set_defaults(func=lambda _args, verb=verb: _lab_missing(verb), lab_missing=True)


def _lab_missing(verb: str) -> int:
    print(f"tactile {verb}: part of the lab package tactile_descriptors_lab, which is not installed: "
          f"{LAB_INSTALL}", file=sys.stderr)
    return 2


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``tactile``; return the process exit code."""
    parser = build_parser()
    args, unknown = parser.parse_known_args(argv)
    if unknown and not getattr(args, "lab_missing", False):
        parser.error(f"unrecognized arguments: {' '.join(unknown)}")
    try:
        return int(args.func(args) or 0)
    except TactileError as exc:
        print(f"tactile {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
