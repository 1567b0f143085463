"""Ctrl-C and fatal errors of a node process: rclpy's shutdown path, nothing raised into running code, and
every line under the node's own name."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.ros

HERE = Path(__file__).parent


def test_ctrl_c_inside_a_destructor_lets_it_and_the_callback_finish():
    """The SIGINT lands inside a destructor run by a callback: the destructor, the callback and ``close()`` run
    to their ends, nothing is printed as ignored, and the node exits 0."""
    out = subprocess.run([sys.executable, str(HERE / "sigint_probe.py")], capture_output=True, text=True,
                         timeout=120)
    err = out.stderr
    assert out.returncode == 0, err
    assert "KeyboardInterrupt" not in err and "Exception ignored" not in err and "Traceback" not in err, err
    assert err.splitlines()[-3:] == ["destructor finished", "callback finished", "closed"], err


def test_a_fatal_error_is_logged_under_the_remapped_node_name():
    """A driver whose constructor refuses its parameters (no robot) logs the reason as FATAL under the name it
    was started with, not a generic ``[node]``, and exits 2."""
    out = subprocess.run([sys.executable, "-m", "tactile_descriptors_ros.nodes.biotac_driver", "--ros-args",
                          "-r", "__node:=left_fingers", "-r", "__ns:=/left"], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 2, out.stderr
    fatal = [line for line in out.stderr.splitlines() if "FATAL" in line]
    assert len(fatal) == 1 and "[left.left_fingers]" in fatal[0] and "parameter 'robot' is required" in fatal[0], \
        out.stderr
