"""Run the simulated graph (``tactile launch ROBOT --sim SCENE``) for the view tests, stopped with Ctrl-C."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
from pathlib import Path


@contextlib.contextmanager
def launched(robot: str, scene: str, log: Path, *extra: str):
    """The graph as a process group (its output in ``log``); SIGINT, then SIGKILL after 30 s, on exit."""
    cmd = [sys.executable, "-m", "tactile_descriptors_ros.tools.cli", "launch", robot, "--sim", scene, *extra]
    with open(log, "w") as fh:
        proc = subprocess.Popen(cmd, stdout=fh, stderr=subprocess.STDOUT, start_new_session=True,
                                env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        yield proc
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGINT)
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
