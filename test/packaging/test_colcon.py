"""The README's colcon instructions build both packages, and ``ros2 launch`` runs them from install/.

A workspace with this checkout in ``src/`` (its tracked files), colcon from
PyPI (``colcon-common-extensions``), the README's own ``colcon build`` line,
then ``ros2 launch`` with the workspace's ``install/setup.bash`` sourced: the
package and its executables must come from ``install/``, not from the venv.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from ros_cli import start_at_a_terminal

pytestmark = [pytest.mark.ros, pytest.mark.ros2cli, pytest.mark.slow, pytest.mark.timeout(1800)]

BIN = Path(sys.prefix) / "bin"
#: the graph's namespace: no other graph on the machine publishes there
NAMESPACE = f"colcon_test_{os.getpid()}"
#: bounds that stop a hung step on a loaded 2-core machine; they measure nothing
BUILD_S = 900.0
LAUNCH_S = 240.0


def _readme_colcon_line(repo_dir: Path) -> str:
    lines = [line.split("#")[0].strip() for line in (repo_dir / "README.md").read_text().splitlines()
             if line.startswith("colcon build")]
    assert len(lines) == 1, lines
    return lines[0]


def _copy_checkout(repo_dir: Path, dest: Path) -> None:
    files = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=repo_dir,
                           capture_output=True, check=True).stdout.decode().split("\0")
    for name in filter(None, files):
        src = repo_dir / name
        if src.is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / name)



def test_colcon_workspace_builds_two_packages_and_launches_from_install(repo_dir, tmp_path):
    if shutil.which("colcon", path=str(BIN)) is None:
        pytest.fail("colcon is not installed in the venv (requirements/test.txt)")
    ws = tmp_path / "ws"
    _copy_checkout(repo_dir, ws / "src" / "tactile_descriptors_ros")
    env = dict(os.environ, ROS_HOME=str(tmp_path / "ros_home"), PYTHONUNBUFFERED="1")
    env["PATH"] = f"{BIN}{os.pathsep}{env['PATH']}"
    build = subprocess.run(["bash", "-e", "-c", _readme_colcon_line(repo_dir)], cwd=ws, env=env,
                           capture_output=True, text=True, timeout=BUILD_S)
    assert build.returncode == 0, build.stdout[-4000:] + build.stderr[-4000:]
    assert "Summary: 2 packages finished" in build.stdout, build.stdout[-3000:]
    # the robot's build holds no lab code (the lab is a pip package beside it, lab/)
    installed = [p.relative_to(ws / "install") for p in (ws / "install").rglob("*.py")]
    assert installed and not [p for p in installed if "tactile_descriptors_lab" in str(p)]

    sourced = f"source {ws}/install/setup.bash && "
    prefixes = subprocess.run(
        ["bash", "-c", sourced + "ros2 pkg prefix tactile_descriptors_ros && ros2 pkg prefix tactile_descriptors_msgs"
         " && python -c 'import tactile_descriptors_msgs.msg as m; print(m.__file__)'"],
        cwd=ws, env=env, capture_output=True, text=True, timeout=120)
    assert prefixes.returncode == 0, prefixes.stderr
    pkg, msgs, msg_module = prefixes.stdout.split()
    assert Path(pkg) == ws / "install" / "tactile_descriptors_ros"
    assert Path(msgs) == ws / "install" / "tactile_descriptors_msgs"
    assert Path(msg_module).is_relative_to(ws / "install")

    log = tmp_path / "launch.log"
    launch = start_at_a_terminal(["bash", "-c", sourced + "exec ros2 launch tactile_descriptors_ros nao.launch.py "
                                  f"sim:=demo_nao namespace:={NAMESPACE}"], log, cwd=ws, env=env)
    lib = ws / "install" / "tactile_descriptors_ros" / "lib" / "tactile_descriptors_ros"
    try:
        echo = subprocess.run(["bash", "-c", sourced + "ros2 topic echo --once --no-daemon --no-arr "
                               f"/{NAMESPACE}/tactile/descriptor tactile_descriptors_msgs/msg/Descriptor"],
                              cwd=ws, env=env, capture_output=True, text=True, timeout=LAUNCH_S)
        assert echo.returncode == 0 and "robot: nao" in echo.stdout, echo.stdout[-2000:] + log.read_text()[-3000:]
        nodes = [p.cmdline() for p in _children(launch.pid) if "--ros-args" in p.cmdline()]
    finally:
        os.killpg(launch.pid, signal.SIGINT)
        try:
            launch.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(launch.pid, signal.SIGKILL)
            launch.wait()
    # every node ran from the workspace's install/, none from the venv
    assert len(nodes) == 5, nodes
    scripts = [Path(next(a for a in cmd if "/lib/" in a)) for cmd in nodes]
    assert all(p.parent == lib for p in scripts), scripts
    assert {p.name for p in scripts} == {"skin_driver", "tf_publisher", "window_node", "contact_node",
                                         "classifier_node"}


def _children(pid: int) -> list:
    import psutil

    return psutil.Process(pid).children(recursive=True)
