"""Ctrl-C and fatal errors of a node process: rclpy's shutdown path, nothing raised into running code, and
every line under the node's own name."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from stacks import native_stacks

from tactile_descriptors_ros.nodes.common import EXECUTOR_ENV, EXECUTORS

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


SLOW_IMPORT = """
import importlib, sys, time
from tactile_descriptors_ros.nodes import entry

real_import = importlib.import_module


def slow_import(name):
    # a busy machine: the node's module is still importing when Ctrl-C comes
    importlib.import_module = real_import
    print("importing", flush=True)
    deadline = time.monotonic() + 60.0
    while not entry._interrupted.is_set() and time.monotonic() < deadline:
        time.sleep(0.01)
    module = real_import(name)
    module.main = lambda: sys.exit("main ran after Ctrl-C")
    return module


importlib.import_module = slow_import
sys.exit(entry.window_node())
"""


def _signal_when_ready(proc: subprocess.Popen, ready: str, signum: int) -> str:
    """Send ``signum`` once the process printed ``ready`` on stdout; wait for its end; return its stderr."""
    try:
        line = proc.stdout.readline().strip()
        assert line == ready, proc.stderr.read() if proc.poll() is not None else line
        proc.send_signal(signum)
        try:
            _, err = proc.communicate(timeout=120)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"still running 120 s after signal {signum}; its threads:\n"
                                 f"{native_stacks(proc.pid)}") from None
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    return err


def test_ctrl_c_while_the_node_module_imports_ends_the_process_cleanly_without_starting_the_node():
    """``ros2 launch`` stops every node when one dies at start; a node whose module is still importing then
    ends with code 0 and without a ``KeyboardInterrupt`` traceback, and its ``main`` never runs."""
    proc = subprocess.Popen([sys.executable, "-c", SLOW_IMPORT], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    err = _signal_when_ready(proc, "importing", signal.SIGINT)
    assert proc.returncode == 0, err
    assert "KeyboardInterrupt" not in err and "Traceback" not in err and "main ran" not in err, err


@pytest.mark.parametrize("kind", EXECUTORS)
def test_ctrl_c_while_a_callback_publishes_ends_the_node_quietly(kind):
    """Ctrl-C shuts the context down while a callback is about to publish: the publish fails, and the node
    ends with code 0 and ``close()`` run, with no fatal line and no stack (the events executor logs a
    callback's exception as fatal with where it was raised unless the node stops quietly)."""
    env = {**os.environ, EXECUTOR_ENV: kind}
    proc = subprocess.Popen([sys.executable, str(HERE / "publish_probe.py")], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    err = _signal_when_ready(proc, "in callback", signal.SIGINT)
    assert proc.returncode == 0, err
    assert "publish failed" in err, err  # the callback did fail under the shut-down context
    assert "FATAL" not in err and "Error occurred" not in err and "Traceback" not in err, err
    assert err.splitlines()[-1] == "closed", err


HUNG_NODE = """
import sys, threading
from rclpy.node import Node
from tactile_descriptors_ros.nodes.common import run_node


def wait_forever():
    print("hanging", flush=True)
    threading.Event().wait()  # a call that never returns: Ctrl-C only shuts the context down under it


class Hung(Node):
    def __init__(self):
        super().__init__("hung")
        wait_forever()


sys.exit(run_node(Hung))
"""

SPINNING_NODE = """
import sys
from rclpy.node import Node
from tactile_descriptors_ros.nodes.common import run_node


class Spinning(Node):
    def __init__(self):
        super().__init__("spinning")
        self.timer = self.create_timer(0.01, self.once)

    def once(self):
        self.timer.cancel()
        print("spinning", flush=True)


sys.exit(run_node(Spinning))
"""

STACK_HEADER = "(most recent call first)"


def _start(script: str, fault_handler: bool) -> subprocess.Popen:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONFAULTHANDLER"}
    if fault_handler:
        env["PYTHONFAULTHANDLER"] = "1"
    return subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env)


def test_sigterm_prints_where_a_hung_node_hangs_when_the_fault_handler_is_on():
    """A node stuck in a call that never returns ignores Ctrl-C; the SIGTERM ``ros2 launch`` escalates to then
    prints every thread's stack, naming the call, so a hang in a loaded test run shows where it was."""
    proc = _start(HUNG_NODE, fault_handler=True)
    lines: list[str] = []
    dumped = threading.Event()

    def read_stderr() -> None:
        for line in proc.stderr:  # the dump ends with the module-level frame that started the node
            lines.append(line)
            if 'File "<string>"' in line and "in <module>" in line:
                dumped.set()

    reader = threading.Thread(target=read_stderr, daemon=True)
    reader.start()
    try:
        assert proc.stdout.readline().strip() == "hanging", "".join(lines)
        proc.send_signal(signal.SIGTERM)
        assert dumped.wait(60.0), "no stack printed on SIGTERM: " + "".join(lines)
        assert proc.poll() is None, "".join(lines)  # the handler chained to rclpy's: no death by signal
    finally:
        proc.kill()
        proc.wait()
        reader.join(10.0)
    text = "".join(lines)
    assert STACK_HEADER in text and "in wait_forever" in text and "in __init__" in text, text


@pytest.mark.parametrize("fault_handler", [True, False])
def test_sigterm_still_stops_a_spinning_node_cleanly(fault_handler):
    """SIGTERM goes on to rclpy's shutdown whether or not the fault handler prints the stacks first: exit code 0;
    without the fault handler nothing is printed."""
    proc = _start(SPINNING_NODE, fault_handler)
    err = _signal_when_ready(proc, "spinning", signal.SIGTERM)
    assert proc.returncode == 0, err
    assert (STACK_HEADER in err) == fault_handler, err
    assert "Traceback" not in err, err


def test_a_process_that_does_not_end_is_reported_with_its_native_and_python_stacks():
    """What a shutdown test shows when a node hangs: the native call it is stuck in and the Python line
    that made it."""
    code = "import time\ndef stuck_here():\n    print('stuck', flush=True)\n    time.sleep(600)\nstuck_here()\n"
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "stuck"
        stacks = native_stacks(proc.pid)
    finally:
        proc.kill()
        proc.communicate()
    assert "clock_nanosleep" in stacks and "stuck_here (<string>:4)" in stacks, stacks


STUCK_TEARDOWN = """
import ctypes, sys
from rclpy.node import Node
from tactile_descriptors_ros.errors import TactileError
from tactile_descriptors_ros.nodes.common import run_node

FAIL = {fail}
if {no_timers}:  # a C library without POSIX timers: the fault handler's timer bounds the end
    from tactile_descriptors_ros.nodes import deadline

    def _no_timers():
        raise OSError("no timer_create in this C library")

    deadline._libc_with_timers = _no_timers


class Stuck(Node):
    def __init__(self):
        super().__init__("stuck")
        self.timer = self.create_timer(0.01, self.once)

    def once(self):
        self.timer.cancel()
        print("spinning", flush=True)
        if FAIL:
            raise TactileError("the device went away")

    def close(self):
        print("closed", file=sys.stderr, flush=True)
        if FAIL:
            raise OSError("the model's disk is gone")

    def destroy_node(self):
        # a native call that blocks holding the GIL, as a DDS teardown stuck on a locked shared-memory port does
        ctypes.PyDLL(None).sleep(600)


sys.exit(run_node(Stuck))
"""


@pytest.mark.parametrize("fail, status, closing", [(False, 0, "everything was saved"),
                                                   (True, 2, "closing had failed (logged above)")])
def test_a_node_whose_middleware_teardown_blocks_still_ends_after_closing(fail, status, closing):
    """A teardown that blocks in native code holding the GIL (no Python thread can run) does not hold the
    process: it ends ``END_WITHIN_S`` after ``close()`` with the status the node would have returned, and
    says why on stderr, and whether closing had finished."""
    from tactile_descriptors_ros.nodes.deadline import END_WITHIN_S

    proc = _start(STUCK_TEARDOWN.format(fail=fail, no_timers=False), fault_handler=False)
    signum = signal.SIGINT
    if fail:  # the node stops by itself; the signal only has to find it
        signum = 0
    err = _signal_when_ready(proc, "spinning", signum)
    assert proc.returncode == status, err
    lines = err.splitlines()
    warning = [i for i, line in enumerate(lines) if f"still not ended {END_WITHIN_S:.1f} s after the node closed"
               in line]
    assert len(warning) == 1 and "[stuck]" in lines[warning[0]], err
    assert f"{closing}; ending with status {status}" in lines[warning[0]], err
    assert lines.index("closed") < warning[0], err


def test_without_posix_timers_the_fault_handler_ends_a_blocked_teardown_with_its_stack():
    """Where libc has no ``timer_create``, the node says so when it closes, and the fault handler's timer ends
    the blocked teardown ``END_WITHIN_S`` later, with the Python stack and status 1."""
    from datetime import timedelta

    from tactile_descriptors_ros.nodes.deadline import END_WITHIN_S

    proc = _start(STUCK_TEARDOWN.format(fail=False, no_timers=True), fault_handler=False)
    err = _signal_when_ready(proc, "spinning", signal.SIGINT)
    assert proc.returncode == 1, err
    assert "[stuck]: no POSIX timers in this C library" in err, err
    assert f"Timeout ({timedelta(seconds=END_WITHIN_S)})!" in err and "in destroy_node" in err, err
    assert "still not ended" not in err, err
