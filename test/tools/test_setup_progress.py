"""`make setup` says what it is doing: every step is announced, with its expected time, in order."""

from __future__ import annotations

import re
import shutil
import subprocess

import pytest


@pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")
def test_make_setup_announces_every_step(repo_dir, tmp_path):
    # a dry run of every step (-B), for a venv that does not exist yet: nothing is executed
    out = subprocess.run(["make", "-n", "-B", "setup", f"VENV={tmp_path / 'venv'}"], cwd=repo_dir,
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    steps = re.findall(r"setup (\d)/(\d): ([^\"']*)", out.stdout)
    assert [int(k) for k, _, _ in steps] == list(range(1, len(steps) + 1)) and len(steps) >= 5
    assert all(int(n) == len(steps) for _, n, _ in steps)
    assert any("descriptor kernel" in what for _, _, what in steps)
    lines = out.stdout.splitlines()
    install = next(i for i, line in enumerate(lines) if "install --progress-bar off -r" in line)
    assert " -q " not in lines[install] and "Collecting" in "\n".join(lines[install:install + 3]), \
        "the long pip install must list its packages, not run quietly"
