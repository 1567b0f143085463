"""The robot installs without the evaluation stack: it is the ``eval`` extra, and nothing the robot runs imports it."""

from __future__ import annotations

import importlib.metadata
import subprocess
import sys
import textwrap

import pytest

#: Distributions of the ``eval`` extra (evaluation, report, bench, simulated protocols).
EVAL_ONLY = ("scikit-learn", "matplotlib", "tqdm", "threadpoolctl")
#: Their import names.
EVAL_MODULES = ("sklearn", "matplotlib", "tqdm", "threadpoolctl")


def _name(requirement: str) -> str:
    """The distribution name of a requirement string such as ``tqdm; extra == "eval"``."""
    head = requirement.split(";")[0]
    for stop in "<>=!~[ ":
        head = head.split(stop)[0]
    return head.strip().lower()


def test_eval_dependencies_are_an_extra():
    requires = importlib.metadata.requires("tactile_descriptors_ros") or []
    unconditional = {_name(r) for r in requires if ";" not in r}
    in_eval = {_name(r) for r in requires if 'extra == "eval"' in r}
    assert not unconditional & set(EVAL_ONLY), f"robot install pulls {unconditional & set(EVAL_ONLY)}"
    assert set(EVAL_ONLY) <= in_eval
    assert {"numpy", "scipy", "pyyaml", "rosbags"} <= unconditional


def test_package_xml_runtime_depends_exclude_eval(repo_dir):
    import xml.etree.ElementTree as ET

    root = ET.parse(repo_dir / "package.xml").getroot()
    exec_deps = {e.text for e in root if e.tag in ("exec_depend", "depend")}
    test_deps = {e.text for e in root if e.tag == "test_depend"}
    eval_keys = {"python3-sklearn", "python3-matplotlib", "python3-tqdm"}
    assert not exec_deps & eval_keys
    assert eval_keys <= test_deps


# What runs on the robot: the nodes, drivers, transports, codecs, bags, launch glue, the simulator
# behind the simulated transport, and the tactile CLI's parser (all subcommands are registered).
_ROBOT_IMPORTS = textwrap.dedent("""
    import importlib, importlib.abc, pkgutil, sys
    BLOCKED = {blocked!r}
    class Block(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in BLOCKED:
                raise ImportError(f"robot code imported {{name}}")
            return None
    sys.meta_path.insert(0, Block())
    import tactile_descriptors_ros as pkg
    for sub in ("core", "codecs", "transports", "nodes", "bags", "launching", "sim"):
        mod = importlib.import_module(f"tactile_descriptors_ros.{{sub}}")
        for info in pkgutil.iter_modules(mod.__path__):
            importlib.import_module(f"tactile_descriptors_ros.{{sub}}.{{info.name}}")
    from tactile_descriptors_ros.tools.cli import build_parser
    build_parser()
    print("ok")
""")


@pytest.mark.ros
def test_robot_modules_import_without_eval_stack():
    code = _ROBOT_IMPORTS.format(blocked=EVAL_MODULES)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.strip().endswith("ok")
