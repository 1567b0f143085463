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


def test_the_heap_mode_comes_from_the_caller_or_the_environment_and_is_checked(monkeypatch):
    from tactile_descriptors_ros.errors import TactileError
    from tactile_descriptors_ros.nodes.common import gc_mode

    monkeypatch.delenv("TACTILE_GC", raising=False)
    assert gc_mode() == "freeze"
    monkeypatch.setenv("TACTILE_GC", "off")
    assert gc_mode() == "off" and gc_mode("freeze") == "freeze"
    monkeypatch.setenv("TACTILE_GC", "never")
    with pytest.raises(TactileError, match="TACTILE_GC='never': not a heap mode; one of freeze, off"):
        gc_mode()


@pytest.mark.parametrize("major, default", [(9, "events"), (10, "events"), (7, "single"), (0, "single")])
def test_a_node_spins_in_events_where_rclpy_resumes_coroutines_unless_the_environment_says(monkeypatch, major,
                                                                                         default):
    from tactile_descriptors_ros.nodes import common

    monkeypatch.setattr(common, "rclpy_major", lambda: major)
    monkeypatch.delenv(common.EXECUTOR_ENV, raising=False)
    assert common.executor_kind() == default
    monkeypatch.setenv(common.EXECUTOR_ENV, "")
    assert common.executor_kind() == default
    for kind in ("single", "events"):
        monkeypatch.setenv(common.EXECUTOR_ENV, kind)
        assert common.executor_kind() == kind


def test_the_installed_rclpy_says_its_major_version():
    from tactile_descriptors_ros.nodes.common import rclpy_major

    assert rclpy_major() in (7, 9), rclpy_major()  # the Jazzy and Kilted wheels this package is tested on


def _coroutine_service_answered(kind: str | None, *, coroutine_callbacks: bool = True) -> bool:
    """Whether :func:`spin` (executor ``kind``) answers a service whose callback is a coroutine awaiting a
    future that a 50 ms timer of the same node sets, as the classifier's ``~/label`` awaits the learning;
    :class:`TactileError` from :func:`spin` is raised here."""
    import threading
    import time

    import rclpy
    from rclpy.callback_groups import ReentrantCallbackGroup
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.task import Future
    from std_srvs.srv import Trigger

    from tactile_descriptors_ros.nodes.common import spin

    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node("coroutine_probe", context=ctx)
    node.coroutine_callbacks = coroutine_callbacks
    pending: list[Future] = []

    async def handle(request, response):
        done = Future()
        pending.append(done)
        await done
        response.success = True
        return response

    def settle() -> None:
        while pending:
            pending.pop().set_result(True)

    node.create_service(Trigger, "coroutine_probe", handle, callback_group=ReentrantCallbackGroup())
    node.create_timer(0.05, settle)
    errors: list[BaseException] = []

    def serve() -> None:
        try:
            _spin_quietly(spin, node, kind)
        except BaseException as exc:  # noqa: BLE001 - handed to the test
            errors.append(exc)

    spinner = threading.Thread(target=serve, daemon=True)
    client_node = rclpy.create_node("coroutine_client", context=ctx)
    client_executor = SingleThreadedExecutor(context=ctx)
    client_executor.add_node(client_node)
    try:
        spinner.start()
        client = client_node.create_client(Trigger, "coroutine_probe")
        deadline = time.monotonic() + 60.0  # a bound for a loaded machine; the answer comes within 0.1 s
        while not client.wait_for_service(timeout_sec=0.5):
            if errors:
                raise errors[0]
            assert time.monotonic() < deadline, "the probe's service was never discovered"
        answer = client.call_async(Trigger.Request())
        deadline = time.monotonic() + 20.0
        while not answer.done() and time.monotonic() < deadline and not errors:
            client_executor.spin_once(timeout_sec=0.1)
        if errors:
            raise errors[0]
        return answer.done() and answer.result().success
    finally:
        rclpy.try_shutdown(context=ctx)
        spinner.join(10.0)
        client_executor.shutdown()
        client_node.destroy_node()
        node.destroy_node()


def test_the_default_executor_answers_a_coroutine_service_that_awaits_another_callback(monkeypatch):
    """What the default (:func:`default_executor`) is chosen for, on the installed rclpy: the classifier's
    ``~/label`` is such a service."""
    from tactile_descriptors_ros.nodes.common import EXECUTOR_ENV

    monkeypatch.delenv(EXECUTOR_ENV, raising=False)
    assert _coroutine_service_answered(None)


@pytest.mark.filterwarnings("ignore:coroutine .* was never awaited:RuntimeWarning")  # Jazzy's events
def test_events_answers_a_coroutine_service_or_refuses_a_node_that_has_one_where_it_cannot():
    """With an rclpy whose ``EventsExecutor`` resumes coroutines (Kilted) ``events`` answers; with one whose
    executor never does (Jazzy) :func:`spin` refuses ``events`` to a node that says it has coroutine
    callbacks, naming why, instead of leaving its calls unanswered."""
    from tactile_descriptors_ros.errors import TactileError
    from tactile_descriptors_ros.nodes.common import events_resume_coroutines

    if events_resume_coroutines():
        assert _coroutine_service_answered("events")
    else:
        with pytest.raises(TactileError, match=r"TACTILE_EXECUTOR=events: rclpy 7's EventsExecutor does not await"):
            _coroutine_service_answered("events")
        assert _coroutine_service_answered("single")
        # why: spun in events, a node that does not say so gets its coroutine callback run as a plain one; the
        # coroutine object goes back as the response, which rclpy refuses with a bare TypeError
        with pytest.raises(TypeError):
            _coroutine_service_answered("events", coroutine_callbacks=False)


def test_the_classifier_node_says_it_has_coroutine_callbacks():
    from tactile_descriptors_ros.nodes.classifier_node import ClassifierNode

    assert ClassifierNode.coroutine_callbacks is True


@pytest.mark.parametrize("kind", ["single", "events"])
def test_each_executor_serves_a_timer_on_simulated_time_at_the_clocks_pace(kind):
    """Under ``use_sim_time`` a timer on the ROS clock fires by ``/clock``, not by the wall: 2 s of
    simulated time published over about 4 s of wall time fire a 0.05 s timer 40 times, each on a
    multiple of 0.05 s of the published clock (the classifier's ordering timer is such a timer)."""
    import threading
    import time

    import rclpy
    from rclpy.parameter import Parameter
    from rosgraph_msgs.msg import Clock

    from tactile_descriptors_ros.nodes.common import spin

    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node("sim_timer_probe", context=ctx,
                             parameter_overrides=[Parameter("use_sim_time", value=True)])
    clock_node = rclpy.create_node("sim_clock", context=ctx)
    pub = clock_node.create_publisher(Clock, "/clock", 10)
    fired: list[int] = []
    all_fired = threading.Event()

    def tick() -> None:
        fired.append(node.get_clock().now().nanoseconds)
        if len(fired) == 40:
            all_fired.set()

    node.create_timer(0.05, tick)
    start_ns = 100 * 10**9
    wall_s = []

    def feed() -> None:
        while pub.get_subscription_count() == 0 and ctx.ok():
            time.sleep(0.01)
        t0 = time.monotonic()
        for i in range(201):  # 0 .. 2.0 s of simulated time in 10 ms steps, at about half the wall's pace
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = divmod(start_ns + i * 10**7, 10**9)
            pub.publish(msg)
            time.sleep(0.02)
        wall_s.append(time.monotonic() - t0)

    spinner = threading.Thread(target=lambda: _spin_quietly(spin, node, kind), daemon=True)
    spinner.start()
    feeder = threading.Thread(target=feed, daemon=True)
    feeder.start()
    try:
        assert all_fired.wait(120.0), f"the timer fired {len(fired)} times"
        feeder.join(120.0)
        assert wall_s and wall_s[0] > 3.0, wall_s  # the wall ran twice as long as the simulated clock
        assert len(fired) in (40, 41), fired  # 2.0 s / 0.05 s; the last step may land on the 41st
        assert all(t >= start_ns and (t - start_ns) % (5 * 10**7) == 0 for t in fired), fired
    finally:
        rclpy.try_shutdown(context=ctx)
        spinner.join(10.0)
        node.destroy_node()
        clock_node.destroy_node()


def _spin_quietly(spin, node, kind: str) -> None:
    from rclpy.executors import ExternalShutdownException

    try:
        spin(node, kind)
    except ExternalShutdownException:
        pass



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
