"""After make setup the venv is a ROS 2 prefix: this package is in its ament index, as ros2 launch/run need."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

PKG = "tactile_descriptors_ros"
NODES = ("biotac_driver", "classifier_node", "contact_node", "skin_driver", "tf_publisher", "window_node")
PREFIX = Path(sys.prefix)


def _clean_env(**extra: str) -> dict[str, str]:
    """The test's environment without the venv on PATH or AMENT_PREFIX_PATH (a fresh terminal)."""
    env = {k: v for k, v in os.environ.items() if k not in ("AMENT_PREFIX_PATH", "VIRTUAL_ENV")}
    env["PATH"] = os.pathsep.join(p for p in env.get("PATH", "").split(os.pathsep)
                                  if Path(p).resolve() != (PREFIX / "bin").resolve())
    env.update(extra)
    return env


def test_package_in_ament_index_of_venv(repo_dir):
    from ament_index_python.packages import get_package_prefix, get_package_share_directory

    assert Path(get_package_prefix(PKG)).resolve() == PREFIX.resolve()
    share = Path(get_package_share_directory(PKG))
    assert (share / "package.xml").read_text() == (repo_dir / "package.xml").read_text()
    assert {p.name for p in (share / "launch").glob("*.launch.py")} == {"shadow_hand.launch.py", "nao.launch.py"}
    assert (share / "config" / "shadow_hand.yaml").is_file() and (share / "config" / "scenes").is_dir()
    # the Fast DDS profile the launch files give the nodes (launching.processes.dds_environment)
    assert (share / "config" / "fastdds.xml").read_text() == (repo_dir / "config" / "fastdds.xml").read_text()
    # where the README's rviz2 command finds the shipped configurations
    for robot in ("shadow_hand", "nao"):
        assert (share / "config" / "rviz" / f"{robot}.rviz").read_text() == \
            (repo_dir / "config" / "rviz" / f"{robot}.rviz").read_text()


def test_executables_in_lib_pkg():
    lib = PREFIX / "lib" / PKG
    for exe in NODES:
        path = lib / exe
        assert path.is_file() and os.access(path, os.X_OK), f"{path} missing or not executable"


def test_setup_script_sets_prefix_and_localhost_discovery():
    script = PREFIX / "setup.bash"
    assert script.is_file(), "make setup writes .venv/setup.bash"
    env = _clean_env()
    env.pop("ROS_AUTOMATIC_DISCOVERY_RANGE", None)
    out = subprocess.run(
        ["bash", "-c", f"source {script} && source {script} && "
         "echo $AMENT_PREFIX_PATH && echo $ROS_AUTOMATIC_DISCOVERY_RANGE && command -v tactile && "
         "python -c 'import sys; print(sys.prefix)'"],
        env=env, capture_output=True, text=True, timeout=60, check=True).stdout.split()
    ament, discovery, tactile, python_prefix = out
    assert ament.split(os.pathsep) == [str(PREFIX)]  # sourcing twice adds it once
    assert discovery == "LOCALHOST"
    assert Path(tactile).parent.resolve() == (PREFIX / "bin").resolve()
    assert Path(python_prefix).resolve() == PREFIX.resolve()


@pytest.mark.ros2cli
def test_ros2_pkg_finds_package_after_sourcing_setup():
    script = PREFIX / "setup.bash"
    out = subprocess.run(["bash", "-c", f"source {script} && ros2 pkg prefix {PKG} && ros2 pkg executables {PKG}"],
                         env=_clean_env(), capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.split("\n")
    assert Path(lines[0]).resolve() == PREFIX.resolve()
    listed = {line.split()[1] for line in lines[1:] if line.strip()}
    assert set(NODES) <= listed
