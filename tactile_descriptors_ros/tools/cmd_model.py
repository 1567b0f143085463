"""``tactile model check|recover MODEL``: inspect or recover a classifier's model file and its journal.

``check`` loads the model file and replays its journal without writing
anything: it prints the classes, the version, the journal's entries, and
the first damaged line if there is one (exit code 1 then).

``recover`` is for a journal damaged in the middle (a zeroed region or a
garbled line followed by later entries: what no crash leaves, and what the
classifier node refuses to start on).  It keeps the model file and every
journal entry before the damaged line, writes them as the new model file,
and renames the journal ``<model>.journal.damaged`` for inspection (nothing
is deleted).  It takes the model's lock, so it refuses while a node holds
the file.  See docs/nodes.md.
"""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("model", help="check or recover a classifier model file and its journal",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("action", choices=("check", "recover"), help="check: read only; recover: keep what is intact")
    p.add_argument("model", type=Path, help="the model file (its journal is <model>.journal)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..core.model_store import check_model, journal_path, recover_model
    from ..errors import ModelError

    if not args.model.is_file():
        raise ModelError(f"{args.model}: no such model file")
    if args.action == "check":
        model, report = check_model(args.model)
    else:
        report = recover_model(args.model)
        model, _ = check_model(args.model)
    journal = journal_path(args.model)
    print(f"{args.model}: {len(model.classes)} classes, version {model.version}, {model.pa.updates} updates")
    kept = f"kept {report.entries} entr{'y' if report.entries == 1 else 'ies'}"
    if report.damaged_line is None:
        print(f"{journal}: {kept}, no damage" if report.entries or args.action == "check" else f"{journal}: none")
        return 0
    print(f"{journal}: {kept}; damaged at line {report.damaged_line}: {report.damage}")
    if args.action == "recover":
        print(f"wrote {args.model} with them; the damaged journal is {journal.name}.damaged beside it")
        return 0
    print(f"to keep them: tactile model recover {args.model}")
    return 1
