"""``tactile``: one command-line entry point with subcommands.

Each subcommand lives in its own module ``tactile_descriptors_ros.tools.cmd_<name>``
that defines ``register(subparsers) -> None``; the parser it adds sets
``func`` (called with the parsed arguments, returns an exit code).  Modules
are discovered at start, so adding a subcommand touches no other file.
Subcommands stay thin: they parse arguments and call library functions.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
from collections.abc import Sequence

from ..errors import TactileError

__all__ = ["build_parser", "main"]


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
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``tactile``; return the process exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except TactileError as exc:
        print(f"tactile {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
