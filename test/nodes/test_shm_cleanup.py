"""The suite removes the shared-memory files of Fast DDS participants that were killed (``dds_shm``, run by the
root ``conftest.py`` per module), and only theirs: a live participant's files stay."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from dds_shm import FASTDDS_TOOL, clean_zombie_shm

pytestmark = [pytest.mark.ros, pytest.mark.skipif(not FASTDDS_TOOL.is_file(), reason=f"no {FASTDDS_TOOL}")]

SHM = Path("/dev/shm")
#: A participant that publishes and subscribes on one topic (so Fast DDS opens its shared-memory port and
#: segment), says so, and waits to be killed.
PARTICIPANT = """
import sys, rclpy
from std_msgs.msg import String
rclpy.init()
node = rclpy.create_node("shm_probe")
got = []
node.create_subscription(String, "shm_probe", got.append, 10)
pub = node.create_publisher(String, "shm_probe", 10)
while not got:
    pub.publish(String(data="x"))
    rclpy.spin_once(node, timeout_sec=0.1)
print("ready", flush=True)
sys.stdin.read()
"""


#: Fast DDS's shared-memory files: ``fastrtps_*`` before Fast DDS 3 (Jazzy's), ``fastdds_*`` since (Kilted's).
PREFIXES = ("fastdds_", "fastrtps_")


def _files() -> set[str]:
    """Fast DDS's shared-memory files in ``/dev/shm``."""
    return {p.name for prefix in PREFIXES for p in SHM.glob(prefix + "*")}


def _held_by(pid: int) -> set[str]:
    """The Fast DDS shared-memory files process ``pid`` has open or mapped (``/proc``): its own, whatever other
    suites running beside this one create in ``/dev/shm`` meanwhile."""
    paths = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        try:
            paths.add(os.readlink(fd))
        except OSError:  # closed meanwhile
            pass
    for line in Path(f"/proc/{pid}/maps").read_text().splitlines():
        fields = line.split(maxsplit=5)
        if len(fields) == 6:
            paths.add(fields[5])
    names = {Path(p).name for p in paths if p.startswith(str(SHM) + "/") and not p.endswith(" (deleted)")}
    return {n for n in names if n.startswith(PREFIXES)}


def _participant() -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, "-c", PARTICIPANT], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            text=True, env=dict(os.environ))
    assert proc.stdout.readline().strip() == "ready", "the participant did not start"
    return proc


@pytest.mark.skipif(not SHM.is_dir(), reason="no /dev/shm")
def test_a_killed_participants_files_are_removed_and_a_live_ones_stay():
    before = _files()
    live = _participant()
    try:
        dead = _participant()
        # each participant's own new files (another suite beside this one may create and remove files meanwhile);
        # a port one of them opened to send to the other is held by both and belongs to neither alone
        held_live, held_dead = _held_by(live.pid), _held_by(dead.pid)
        live_files = held_live - held_dead - before
        dead_files = held_dead - held_live - before
        assert live_files and dead_files, "the participants opened no shared memory"
        os.kill(dead.pid, signal.SIGKILL)
        dead.wait(timeout=10)
        assert dead_files <= _files(), "a killed participant's files went away by themselves"
        clean_zombie_shm()
        assert not dead_files & _files(), f"left behind: {sorted(dead_files & _files())}"
        assert live_files <= _files(), f"removed while in use: {sorted(live_files - _files())}"
    finally:
        live.stdin.close()
        live.wait(timeout=10)
