"""The repository speaks of itself only: no pointers to documents, issues or people outside it."""

from __future__ import annotations

import re
import subprocess

#: A section of an outside specification, an issue number of this project's tracker, a helper by letter or number.
#: (Written in two pieces so that this file, too, does not hold the phrase it forbids.)
OUTSIDE = re.compile(r"\bSPEC" r" section\b|\b[Ii]ssue \d+|\b[Ii]ssue \d+'s|\b[Hh]elper[- ](?:[A-Z]|\d+)\b|"
                     r"\b[Hh]elper [A-Z]'s\b|\bother sessions\b")


def test_no_references_outside_the_repository(repo_dir):
    files = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard"], cwd=repo_dir,
                           capture_output=True, text=True, check=True).stdout.split()
    hits = []
    for name in files:
        path = repo_dir / name
        if name == "test/docs/test_self_contained.py" or not path.is_file() or path.suffix in {".png", ".json", ".npz"}:
            continue
        for n, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
            if OUTSIDE.search(line):
                hits.append(f"{name}:{n}: {line.strip()}")
    assert not hits, "\n".join(hits)
