"""The robot installs and runs without the lab: no lab module in it, no lab dependency, one-line advice."""

from __future__ import annotations

import importlib.metadata
import subprocess
import sys
import textwrap
import zipfile

import pytest

#: Distributions only the lab needs (evaluation, benches, reports, HDF5 import).
LAB_ONLY = ("scikit-learn", "matplotlib", "threadpoolctl", "psutil", "h5py")
#: What is blocked when the robot is imported "with the lab absent": the lab and its stack.
LAB_MODULES = ("tactile_descriptors_lab", "sklearn", "matplotlib", "threadpoolctl", "psutil", "h5py")


def _name(requirement: str) -> str:
    """The distribution name of a requirement string such as ``h5py; extra == "hdf5"``."""
    head = requirement.split(";")[0]
    for stop in "<>=!~[ ":
        head = head.split(stop)[0]
    return head.strip().lower()


def test_robot_requires_nothing_of_the_lab():
    requires = {_name(r) for r in importlib.metadata.requires("tactile_descriptors_ros") or []}
    assert not requires & set(LAB_ONLY), f"the robot install pulls {requires & set(LAB_ONLY)}"
    assert {"numpy", "scipy", "pyyaml", "rosbags", "python-can", "pyserial"} <= requires


def test_package_xml_names_none_of_the_lab_stack(repo_dir):
    import xml.etree.ElementTree as ET

    root = ET.parse(repo_dir / "package.xml").getroot()
    deps = {e.text for e in root if e.tag.endswith("depend")}
    assert not deps & {"python3-sklearn", "python3-matplotlib", "python3-threadpoolctl", "python3-psutil",
                       "python3-h5py"}


# Every robot module, and the tactile CLI with every verb, imported with the lab and its stack blocked;
# a lab verb then says in one line how to install the lab and exits with 2.
_ROBOT_WITHOUT_LAB = textwrap.dedent("""
    import contextlib, importlib, importlib.abc, io, pkgutil, sys
    BLOCKED = {blocked!r}
    class Block(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in BLOCKED:
                raise ImportError(f"robot code imported {{name}}")
            return None
    sys.meta_path.insert(0, Block())
    import importlib.metadata as md
    _eps = md.entry_points
    md.entry_points = lambda **kw: [e for e in _eps(**kw) if not e.value.startswith("tactile_descriptors_lab")]
    import tactile_descriptors_ros as pkg
    for info in pkgutil.walk_packages(pkg.__path__, "tactile_descriptors_ros."):
        importlib.import_module(info.name)
    from tactile_descriptors_ros.tools.cli import main
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = main(["evaluate", "--train", "x"])
    print(code)
    print(err.getvalue().strip())
""")


@pytest.mark.ros
def test_robot_imports_and_runs_with_the_lab_absent():
    code = _ROBOT_WITHOUT_LAB.format(blocked=LAB_MODULES)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=180)
    assert out.returncode == 0, out.stderr[-3000:]
    status, advice = out.stdout.strip().splitlines()[-2:]
    assert status == "2"
    assert advice.startswith("tactile evaluate: part of the lab package tactile_descriptors_lab")
    assert "pip install ./lab" in advice


@pytest.mark.slow
def test_a_robot_wheel_holds_no_lab_module(repo_dir, tmp_path):
    """``pip install .`` of the robot: a non-editable build holds every robot module and no lab code."""
    out = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                          "-w", str(tmp_path), str(repo_dir)], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    (wheel,) = tmp_path.glob("tactile_descriptors_ros-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    modules = {n for n in names if n.endswith(".py")}
    assert not [n for n in names if n.startswith("tactile_descriptors_lab")]
    for lab_room in ("evaluation/", "datasets/", "perf/", "bench/", "codecs/fuzz.py", "bags/importer.py",
                     "bags/live_replay.py", "sim/validation.py", "tools/cmd_evaluate.py", "tools/cmd_bench.py"):
        assert not [n for n in modules if f"tactile_descriptors_ros/{lab_room}" in n], lab_room
    source = {str(p.relative_to(repo_dir)) for p in (repo_dir / "tactile_descriptors_ros").rglob("*.py")}
    assert source <= modules
