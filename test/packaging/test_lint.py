"""The linter and the layer contracts, as `make test` runs them: clean, or the test names what broke."""

from __future__ import annotations

import ast
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


def test_no_private_name_crosses_a_module(repo_dir):
    """A ``_name`` is its module's own: no module of either package imports or reads another's."""
    crossing = []
    for root in ("tactile_descriptors_ros", "lab/tactile_descriptors_lab"):
        for path in sorted((repo_dir / root).rglob("*.py")):
            tree = ast.parse(path.read_text())
            ours: set[str] = set()
            for node in ast.walk(tree):
                if isinstance(node, ast.ImportFrom) and (node.level or (node.module or "").startswith(
                        ("tactile_descriptors_ros", "tactile_descriptors_lab"))):
                    for alias in node.names:
                        if alias.name.startswith("_") and not alias.name.startswith("__"):
                            crossing.append(f"{path.relative_to(repo_dir)}:{node.lineno} imports {alias.name}")
                        ours.add(alias.asname or alias.name)
            for node in ast.walk(tree):
                if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in ours
                        and node.attr.startswith("_") and not node.attr.startswith("__")):
                    crossing.append(f"{path.relative_to(repo_dir)}:{node.lineno} reads {node.value.id}.{node.attr}")
    assert not crossing, crossing
