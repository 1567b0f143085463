"""The executor a node spins in (``TACTILE_EXECUTOR``): each serves subscriptions and timers, stops cleanly on
Ctrl-C, and ends a callback's fatal error with status 2; an unknown name is refused naming the valid ones."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import pytest

pytestmark = pytest.mark.ros

ECHO_NODE = """
import sys
from rclpy.node import Node
from std_msgs.msg import UInt32
from tactile_descriptors_ros.errors import TactileError
from tactile_descriptors_ros.nodes.common import run_node

FAIL = {fail}


class Echo(Node):
    def __init__(self):
        super().__init__("echo")
        self.pub = self.create_publisher(UInt32, "ping", 100)
        self.create_subscription(UInt32, "ping", self.got, 100)
        self.sent, self.seen = 0, []
        self.timer = self.create_timer(0.005, self.send)

    def send(self):
        self.pub.publish(UInt32(data=self.sent))
        self.sent += 1

    def got(self, msg):
        self.seen.append(msg.data)
        if len(self.seen) == 50:
            self.timer.cancel()
            print("served", self.seen == list(range(50)), flush=True)
            if FAIL:
                raise TactileError("the device went away")

    def close(self):
        print("closed", file=sys.stderr, flush=True)


sys.exit(run_node(Echo))
"""


def _run(kind: str, fail: bool) -> subprocess.Popen:
    env = {**os.environ, "TACTILE_EXECUTOR": kind}
    return subprocess.Popen([sys.executable, "-c", ECHO_NODE.format(fail=fail)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)


@pytest.mark.parametrize("kind", ["single", "events"])
def test_each_executor_serves_timers_and_subscriptions_in_order_and_stops_on_ctrl_c(kind):
    proc = _run(kind, fail=False)
    try:
        line = proc.stdout.readline().strip()  # the node's own 50 messages, through DDS, in order
        assert line == "served True", (line, proc.stderr.read() if proc.poll() is not None else "")
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    assert err.splitlines()[-1:] == ["closed"] and "Traceback" not in err, err


@pytest.mark.parametrize("kind", ["single", "events"])
def test_each_executor_ends_a_callbacks_fatal_error_with_status_2(kind):
    proc = _run(kind, fail=True)
    try:
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert out.strip() == "served True", err
    assert proc.returncode == 2, err
    fatal = [line for line in err.splitlines() if "FATAL" in line]
    ours = [line for line in fatal if line.endswith("[echo]: the device went away")]
    # the events executor (C++) also logs the exception itself, with where it was raised, before raising it on
    executors_own = [line for line in fatal if line.endswith("[echo]: Exception in 'subscriptions' callback: "
                                                           "the device went away")]
    assert len(ours) == 1, err
    assert len(executors_own) == (1 if kind == "events" else 0), err
    assert len(fatal) == len(ours) + len(executors_own), err
    assert "closed" in err.splitlines(), err


def test_an_unknown_executor_is_refused_naming_the_valid_ones():
    proc = _run("multi", fail=False)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 2, err
    assert out == "", out
    fatal = [line for line in err.splitlines() if "FATAL" in line]
    assert len(fatal) == 1 and "TACTILE_EXECUTOR='multi': not an executor; one of single, events" in fatal[0], err


def test_an_executor_named_by_the_caller_is_checked_like_the_environments():
    from tactile_descriptors_ros.errors import TactileError
    from tactile_descriptors_ros.nodes.common import executor_kind

    assert executor_kind("events") == "events"
    with pytest.raises(TactileError, match="not an executor; one of single, events"):
        executor_kind("multi")



def test_a_context_shut_down_while_the_executor_waits_with_nothing_due_still_ends_the_spin():
    """rclpy's SIGINT handler shuts the context down from its own thread and wakes the executor through a
    guard condition; a wait that misses the wake-up, with nothing else due, must still end (once, under
    load, a node whose only timer had stopped ignored Ctrl-C for 60 s).  The context is shut down the way
    that thread does it, without the wake-up, once the executor has begun to wait with nothing due.  (The
    events executor's wait times out by construction: ``spin_once`` with a timeout.)"""
    import sys
    import threading

    import rclpy
    from rclpy.executors import ExternalShutdownException

    from tactile_descriptors_ros.nodes.common import SPIN_WAKE_S, spin

    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node("spin_probe", context=ctx)
    stopped, waiting, ended = threading.Event(), threading.Event(), threading.Event()

    def once() -> None:
        timer.cancel()  # from here on nothing of the node is due
        stopped.set()

    timer = node.create_timer(0.01, once)

    def see_the_wait(frame, event, arg) -> None:  # the executor's call into rcl_wait, once the timer stopped
        if event == "c_call" and stopped.is_set() and getattr(arg, "__name__", "") == "wait" \
                and frame.f_code.co_name == "_wait_for_ready_callbacks":
            waiting.set()

    def run() -> None:
        sys.setprofile(see_the_wait)
        try:
            spin(node, "single")
        except ExternalShutdownException:
            pass
        finally:
            sys.setprofile(None)
        ended.set()

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    try:
        assert waiting.wait(30.0), "the executor never waited after the node's timer stopped"
        ctx.handle.shutdown()  # what the signal handler's thread does, without the guard condition's wake-up
        assert ended.wait(SPIN_WAKE_S + 5.0), "spin still waits after its context was shut down"
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
