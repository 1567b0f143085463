"""The linter and the layer contracts, as `make test` runs them: clean, or the test names what broke."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

BIN = Path(sys.executable).parent


def test_ruff_finds_nothing(repo_dir):
    out = subprocess.run([str(BIN / "ruff"), "check", "--no-cache", "--output-format", "concise", "."],
                         cwd=repo_dir, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout[-4000:] + out.stderr[-2000:]


@pytest.mark.skipif(importlib.util.find_spec("tactile_descriptors_lab") is None,
                    reason="the contracts span both packages; the lab is not installed")
def test_layer_contracts_hold(repo_dir):
    """The robot never imports the lab; each package's layers import downwards only (`.importlinter`)."""
    out = subprocess.run([str(BIN / "lint-imports"), "--no-cache"], cwd=repo_dir, capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stdout[-6000:] + out.stderr[-2000:]
    assert "0 broken" in out.stdout


def test_a_broken_contract_is_reported(repo_dir, tmp_path):
    """The checker can fail: a robot module importing the lab breaks the first contract."""
    if importlib.util.find_spec("tactile_descriptors_lab") is None:
        pytest.skip("the contracts span both packages; the lab is not installed")
    pkg = tmp_path / "tactile_descriptors_ros"
    (pkg / "core").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "core" / "__init__.py").write_text("import tactile_descriptors_lab\n")
    lab = tmp_path / "tactile_descriptors_lab"
    lab.mkdir()
    (lab / "__init__.py").write_text("")
    # the repository's own first contract, on a robot package whose core imports the lab
    sections = (repo_dir / ".importlinter").read_text().split("\n\n")
    config = tmp_path / ".importlinter"
    config.write_text("\n\n".join(s for s in sections if s.startswith(
        ("[importlinter]", "[importlinter:contract:robot-never-imports-lab]"))))
    out = subprocess.run([str(BIN / "lint-imports"), "--no-cache", str(config)], cwd=tmp_path,
                         capture_output=True, text=True, timeout=300,
                         env={"PATH": str(BIN), "PYTHONPATH": str(tmp_path)})
    assert out.returncode != 0
    assert "The robot package never imports the lab BROKEN" in out.stdout
