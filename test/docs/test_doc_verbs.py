"""Every ``tactile <verb>`` the README and docs/ name in code is a verb of the ``tactile`` command."""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
#: ``tactile <verb>`` inside inline code or a code block.
VERB = re.compile(r"(?:^|`|\$ |\n)\s*tactile ([a-z][a-z_-]*)")


def _verbs() -> set[str]:
    import argparse

    from tactile_descriptors_ros.tools.cli import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return set(sub.choices)


def test_every_tactile_verb_the_docs_name_exists():
    verbs = _verbs()
    unknown = []
    for page in PAGES:
        text = page.read_text()
        code = "\n".join(re.findall(r"`([^`\n]+)`", text) + re.findall(r"```[a-z]*\n(.*?)```", text, re.S))
        for m in VERB.finditer(code):
            if m.group(1) not in verbs:
                unknown.append(f"{page.relative_to(REPO)}: tactile {m.group(1)}")
    assert not unknown, f"verbs of tactile: {sorted(verbs)}\n" + "\n".join(sorted(set(unknown)))
