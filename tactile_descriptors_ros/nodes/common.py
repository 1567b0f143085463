"""Shared pieces of the nodes: ``/diagnostics``, rates, ``main`` (parameters: :mod:`.parameters`).

``diagnostic_updater`` is not available as a wheel, so :class:`Diagnostics`
is a small equivalent: tasks registered by name, each returning a
:class:`Status`, published together as one ``diagnostic_msgs/DiagnosticArray``
on ``/diagnostics`` every ``diagnostics_period_s`` of wall time (a steady
clock, so diagnostics keep flowing under ``use_sim_time`` with no ``/clock``).
Status names follow the ROS convention ``"<node name>: <task>"``.
"""

from __future__ import annotations

import collections
import faulthandler
import functools
import gc
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from ..core.pauses import GcPauses
from ..errors import TactileError
from .deadline import END_WITHIN_S, end_process_after
from .entry import note_interrupts

__all__ = [
    "host_age_ms",
    "Status",
    "Diagnostics",
    "RateMeter",
    "steady_clock",
    "run_node",
    "spin",
    "executor_kind",
    "default_executor",
    "events_resume_coroutines",
    "take_waiting",
    "take_frames",
    "keep_freed_memory",
    "StopsQuietly",
    "quiet_after_shutdown",
]

#: A stamp further than this from the host clock [ms] is not on it (``stamp_source: device``: a simulator's
#: scene time, a bridge's own clock): the age of such data is counted as not on host time, never timed.
HOST_TIME_LIMIT_MS = 3_600_000.0


def host_age_ms(now_ns: int, stamp_ns: int) -> float | None:
    """``now_ns - stamp_ns`` in ms, or ``None`` when the stamp is not on the host clock (further than
    :data:`HOST_TIME_LIMIT_MS`): a diagnostic counts such data, it never times it."""
    age_ms = (now_ns - stamp_ns) / 1e6
    return age_ms if abs(age_ms) < HOST_TIME_LIMIT_MS else None

_LEVELS = {"ok": 0, "warn": 1, "error": 2, "stale": 3}


def quiet_after_shutdown(context: Any, callback: Callable) -> Callable:
    """``callback``, made to return quietly when it fails because ``context`` was shut down under it.

    Ctrl-C shuts a node's context down from rclpy's signal thread, so a callback running at that moment
    fails in its next ``publish`` ("publisher's context is invalid").  The node is stopping cleanly
    (:func:`run_node` treats it so), but the events executor first logs the exception as fatal with where
    it was raised, a stack in the terminal of a user who pressed Ctrl-C.  Failures while the context is
    still valid are raised as before.  Coroutine functions are returned unchanged (the executor awaits them).
    """
    import inspect

    if inspect.iscoroutinefunction(callback):
        return callback

    @functools.wraps(callback)
    def call(*args: Any) -> Any:
        try:
            return callback(*args)
        except Exception:
            if context.ok():
                raise
            return None  # the node is stopping: the executor looks at the context and returns

    return call


class StopsQuietly:
    """A node mixin (before ``Node`` or ``LifecycleNode`` in the bases) whose subscription and timer
    callbacks end quietly when Ctrl-C shuts the context down under them (:func:`quiet_after_shutdown`)."""

    def create_subscription(self, msg_type: Any, topic: str, callback: Callable, *args: Any, **kwargs: Any) -> Any:
        return super().create_subscription(msg_type, topic, quiet_after_shutdown(self.context, callback),  # type: ignore[misc]
                                           *args, **kwargs)

    def create_timer(self, timer_period_sec: float, callback: Callable, *args: Any, **kwargs: Any) -> Any:
        return super().create_timer(timer_period_sec, quiet_after_shutdown(self.context, callback),  # type: ignore[misc]
                                    *args, **kwargs)


def take_waiting(subs: Sequence[Any], handlers: dict[Any, Callable], budget: int) -> list[tuple[object, Callable]]:
    """Messages already waiting on ``subs``, at most ``budget``, each with its subscription's handler.

    Takes one message per subscription in turn until none has any left, so a
    busy body part does not starve the others.  rclpy has no call for this:
    it is ``Subscription.handle.take_message``, as its executor does it.  A
    subscription destroyed while shutting down counts as empty.
    """
    from rclpy.exceptions import InvalidHandle

    out: list[tuple[object, Callable]] = []
    while budget > 0:
        took = 0
        for sub in subs:
            if budget <= 0:
                break
            try:
                with sub.handle:
                    got = sub.handle.take_message(sub.msg_type, sub.raw)
            except InvalidHandle:
                got = None
            if got is not None:
                out.append((got[0], handlers[sub]))
                took += 1
                budget -= 1
        if not took:
            break
    return out


def take_frames(first: object, subs: Sequence[Any], handlers: dict[Any, Callable], by_type: dict[type, Callable],
                budget: int, faults: collections.Counter, logger: Any) -> tuple[list[tuple[object, Callable]], int]:
    """The frames callback's message ``first`` and those waiting on ``subs`` (:func:`take_waiting`), each with its
    handler, and how many were taken.

    A message taken serialised (``bytes``, from a ``raw`` subscription: the frames of skin cells) is read
    first (:func:`~.conversions.skin_part_from_serialized`); bytes that cannot be read are counted in
    ``faults["malformed"]``, logged (throttled) and left out.  ``first``'s handler is its type's in ``by_type``.
    """
    from .conversions import skin_part_from_serialized

    taken = [(first, None)] + take_waiting(subs, handlers, budget)
    out: list[tuple[object, Callable]] = []
    for msg, handler in taken:
        if isinstance(msg, bytes):
            try:
                msg = skin_part_from_serialized(msg)
            except Exception as exc:  # noqa: BLE001 - rclpy's error type for bytes it cannot read is not public
                faults["malformed"] += 1
                logger.warning(f"unreadable SkinPartFrames bytes dropped: {exc}", throttle_duration_sec=5.0)
                continue
        out.append((msg, handler or by_type[type(msg)]))
    return out, len(taken)


@dataclass
class Status:
    """One diagnostic status: level (ok, warn, error, stale), message, key/values."""

    level: str
    message: str
    values: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.level not in _LEVELS:
            raise ValueError(f"diagnostic level must be one of {tuple(_LEVELS)}, got {self.level!r}")


class RateMeter:
    """Events per second over a sliding window of wall time (a steady clock).

    Thread-safe: a driver's reader thread adds while the executor's
    diagnostics timer reads (a deque iterated while another thread appends
    raises, and the diagnostics task would report a failure instead of the
    rates).

    Parameters
    ----------
    window_s : float
        Length of the averaging window.
    now : callable, optional
        Clock in seconds (``time.monotonic``); injectable for tests.
    """

    def __init__(self, window_s: float = 2.0, now: Callable[[], float] = time.monotonic) -> None:
        self.window_s = float(window_s)
        self._now = now
        self._events: collections.deque[tuple[float, int]] = collections.deque()
        self._lock = threading.Lock()
        self._in_window = 0  # sum of the counts in _events, kept as they come and go (a read is O(1))
        self.total = 0

    def add(self, count: int = 1) -> None:
        t = self._now()
        with self._lock:
            self._events.append((t, int(count)))
            self._in_window += int(count)
            self.total += int(count)
            self._expire(t)

    def _expire(self, t: float) -> None:
        while self._events and self._events[0][0] < t - self.window_s:
            self._in_window -= self._events.popleft()[1]

    @property
    def rate_hz(self) -> float:
        t = self._now()
        with self._lock:
            self._expire(t)
            return self._in_window / self.window_s


def steady_clock():
    """An rclpy steady clock (timers on it run on wall time, also under ``use_sim_time``)."""
    from rclpy.clock import Clock, ClockType

    return Clock(clock_type=ClockType.STEADY_TIME)


class Diagnostics:
    """Publish named diagnostic tasks on ``/diagnostics``, and after them the ``process`` status (the garbage
    collector's runs and pauses in this process, ``gc_*``).

    Parameters
    ----------
    node : rclpy.node.Node
    period_s : float
        Publication period (wall time).
    hardware_id : str
        ``hardware_id`` of every status (e.g. the serial port or CAN channel).
    """

    def __init__(self, node, period_s: float = 1.0, hardware_id: str = "") -> None:
        from diagnostic_msgs.msg import DiagnosticArray

        self.node = node
        self.hardware_id = hardware_id
        self._tasks: list[tuple[str, Callable[[], Status]]] = []
        self._pub = node.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._timer = node.create_timer(float(period_s), self.publish, clock=steady_clock())
        self.last: list[Any] = []
        GC_PAUSES.install()

    def add(self, task: str, fn: Callable[[], Status]) -> None:
        """Register a task; ``fn`` is called at every publication."""
        self._tasks.append((task, fn))

    def statuses(self) -> list:
        """The current ``DiagnosticStatus`` messages (a failing task reports ERROR, not silence)."""
        from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

        out = []
        for task, fn in [*self._tasks, ("process", _process_status)]:  # the process's own status last
            try:
                st = fn()
            except Exception as exc:  # noqa: BLE001 - a broken task must show up, not stop the node
                st = Status("error", f"diagnostic task failed: {exc!r}")
            msg = DiagnosticStatus()
            msg.level = bytes([_LEVELS[st.level]])
            msg.name = f"{self.node.get_name()}: {task}"
            msg.message = st.message
            msg.hardware_id = self.hardware_id
            msg.values = [KeyValue(key=str(k), value=_fmt(v)) for k, v in st.values.items()]
            out.append(msg)
        return out

    def publish(self) -> None:
        from diagnostic_msgs.msg import DiagnosticArray

        arr = DiagnosticArray()
        arr.header.stamp = self.node.get_clock().now().to_msg()
        arr.status = self.statuses()
        self.last = arr.status
        self._pub.publish(arr)


#: Environment variables by which a user sets glibc's allocator thresholds: :func:`keep_freed_memory` then
#: leaves them as set.
MALLOC_ENV = ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_", "MALLOC_TOP_PAD_", "GLIBC_TUNABLES")
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # mallopt(3) parameters (malloc.h)


def keep_freed_memory(mmap_threshold_bytes: int = 32 << 20, trim_threshold_bytes: int = 128 << 20) -> bool:
    """Let glibc's allocator keep freed memory for the next allocations of the process (``mallopt(3)``).

    A window node allocates a window's arrays (about 7 MB for the NAO's 116
    cells) and frees them once the descriptor is out.  glibc serves blocks
    above a threshold (128 kB, raised up to the largest block freed) with
    ``mmap`` and gives freed memory at the top of the heap back to the system
    above another (twice the first): every window then asks the kernel for
    fresh pages and touches each one (a page fault per 4 kB, about 1,700 a
    NAO window when nothing else is allocated between two windows).  Fixed
    thresholds (allocations up to ``mmap_threshold_bytes`` from the heap,
    freed memory kept up to ``trim_threshold_bytes``) reuse the same pages;
    the process keeps up to that much memory it freed.  Nothing is changed
    when one of :data:`MALLOC_ENV` is set (the user's thresholds stand) or
    where the C library has no ``mallopt`` (not glibc).

    Returns
    -------
    bool
        Whether both thresholds were set.
    """
    if any(os.environ.get(name) for name in MALLOC_ENV):
        return False
    try:
        import ctypes

        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    return bool(mallopt(_M_MMAP_THRESHOLD, int(mmap_threshold_bytes))) \
        and bool(mallopt(_M_TRIM_THRESHOLD, int(trim_threshold_bytes)))


def _process_status() -> Status:
    """The process's garbage-collector pauses (:class:`~tactile_descriptors_ros.core.pauses.GcPauses`)."""
    values = GC_PAUSES.snapshot()
    return Status("ok", f"longest full collection {values['gc_max_ms_g2']:.1f} ms", values)


def gc_mode(mode: str | None = None) -> str:
    """The heap mode of :func:`run_node`: ``mode``, else ``$TACTILE_GC``, else ``freeze``; any other is
    refused, naming the valid ones."""
    return _env_choice(mode, GC_ENV, GC_MODES, "freeze", "a heap mode")


def _env_choice(given: str | None, env: str, choices: Sequence[str], default: str, what: str) -> str:
    """``given``, else the environment variable ``env``, else ``default``; a value not in ``choices`` is a
    :class:`TactileError` naming them."""
    value = given or os.environ.get(env, "") or default
    if value not in choices:
        raise TactileError(f"{env}={value!r}: not {what}; one of {', '.join(choices)}")
    return value


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


#: The collector's pauses in this process, measured from the first :class:`Diagnostics` on (``gc_*`` in the
#: ``process`` task of every node's diagnostics).
GC_PAUSES = GcPauses()
#: The environment variable that says whether :func:`run_node` settles the heap once the node is built
#: (:func:`~tactile_descriptors_ros.core.pauses.settle_heap`): ``freeze`` (default) or ``off``.
GC_ENV = "TACTILE_GC"
GC_MODES = ("freeze", "off")
#: The environment variable that picks the executor a node spins in (:func:`spin`): ``single`` or ``events``
#: (default: :func:`default_executor`).
EXECUTOR_ENV = "TACTILE_EXECUTOR"
EXECUTORS = ("single", "events")
#: The first rclpy major version whose ``EventsExecutor`` runs a coroutine callback as a coroutine, resuming it
#: when the future it awaits is set by another callback (Kilted's rclpy 9 does; Jazzy's rclpy 7 calls it as a
#: plain function and hands the coroutine object on as the service's response, which rclpy refuses).
EVENTS_RESUME_COROUTINES_FROM_RCLPY = 9
#: A spinning node looks at its context at least this often [s], whatever else is due (:func:`spin`).
SPIN_WAKE_S = 1.0


@functools.cache
def rclpy_major() -> int:
    """The installed rclpy's major version (7 in the Jazzy wheels, 9 in Kilted's); 0 if it says none.  Read
    from its package metadata once per process: :func:`spin` asks for it twice."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return int(version("rclpy").split(".")[0])
    except (PackageNotFoundError, ValueError):
        return 0


def events_resume_coroutines() -> bool:
    """Whether this rclpy's ``EventsExecutor`` resumes coroutine callbacks (:data:`EVENTS_RESUME_COROUTINES_FROM_RCLPY`)."""
    return rclpy_major() >= EVENTS_RESUME_COROUTINES_FROM_RCLPY


def default_executor() -> str:
    """``events`` where this rclpy's ``EventsExecutor`` serves every callback the nodes have (Kilted), else
    ``single`` (Jazzy: its ``EventsExecutor`` does not await the classifier's coroutine ``~/label`` service)."""
    return "events" if events_resume_coroutines() else "single"


def executor_kind(kind: str | None = None) -> str:
    """The executor to spin in: ``kind`` if given, else ``$TACTILE_EXECUTOR``, else :func:`default_executor`
    (:func:`spin`); any other name is refused, naming the valid ones."""
    return _env_choice(kind, EXECUTOR_ENV, EXECUTORS, default_executor(), "an executor")


def _look_at_the_context() -> None:
    """The wake-up timer's callback: nothing to do, the executor looks at the context when it returns."""


def spin(node: Any, kind: str | None = None) -> None:
    """Serve ``node``'s callbacks until its context shuts down (Ctrl-C, ``rclpy.shutdown``).

    ``kind`` (default: ``$TACTILE_EXECUTOR``, else :func:`default_executor`) picks the executor:

    ``events``
        rclpy's ``EventsExecutor`` (C++, ``rclpy.experimental``; Jazzy and Kilted): about 0.18 ms of CPU
        per message taken, half of ``single``'s on the same messages (``lab/docs/performance.md``,
        Latency).  It is driven by ``spin_once``, as rclpy's own ``Executor.spin`` drives the Python
        executors: its ``spin()`` in these wheels turns without serving timers.  Shutting the context
        down wakes it.  It serves timers on the ROS clock under ``use_sim_time`` as ``single`` does.  A node
        whose ``coroutine_callbacks`` attribute is true (the classifier: its ``~/label`` service awaits
        the learning) is refused it where it does not resume coroutines (:func:`events_resume_coroutines`).
    ``single``
        rclpy's ``SingleThreadedExecutor`` (Python): about 0.35 ms of CPU per message taken.

    A callback's exception ends the spin and is raised here, with either executor; the events executor
    also logs it itself first (``Exception in 'subscriptions' callback: ...`` and where it was raised).

    Either executor looks at the context at least every :data:`SPIN_WAKE_S`: rclpy's SIGINT handler
    shuts the context down from a thread of its own and wakes the executors with a guard condition, and
    ``SingleThreadedExecutor.spin`` waits with no timeout, so a wait that misses that wake-up, with no
    timer or message due, never ends (seen once under load: a node whose only timer had stopped ignored
    Ctrl-C for 60 s).  A timer of the node wakes it; the events executor's ``spin_once`` times out.
    """
    kind = executor_kind(kind)
    if kind == "events" and getattr(node, "coroutine_callbacks", False) and not events_resume_coroutines():
        raise TactileError(f"{EXECUTOR_ENV}=events: rclpy {rclpy_major()}'s EventsExecutor does not await "
                           f"coroutine callbacks, and this node has some (its services would not answer); use "
                           f"single, or rclpy {EVENTS_RESUME_COROUTINES_FROM_RCLPY} or later")
    if kind == "single":
        from rclpy.executors import SingleThreadedExecutor

        executor = SingleThreadedExecutor(context=node.context)
        executor.add_node(node)
        wake = node.create_timer(SPIN_WAKE_S, _look_at_the_context, clock=steady_clock())  # also under sim time
        try:
            executor.spin()
        finally:
            node.destroy_timer(wake)
        return
    from rclpy.experimental import EventsExecutor

    executor = EventsExecutor(context=node.context)
    executor.add_node(node)
    try:
        while node.context.ok():
            executor.spin_once(timeout_sec=SPIN_WAKE_S)
    finally:
        executor.shutdown()


def run_node(factory: Callable[..., Any], args: Sequence[str] | None = None) -> int:
    """Create a node, spin it until Ctrl-C or shutdown, then clean up.

    Ctrl-C (SIGINT) and SIGTERM go through rclpy's own shutdown path: its
    handler shuts the context down and ``spin`` returns; nothing is raised
    into the running code (:func:`~tactile_descriptors_ros.nodes.entry.note_interrupts`).  A
    :class:`~tactile_descriptors_ros.errors.TactileError` raised while
    building or spinning the node (misconfiguration, a device that cannot be
    opened) is logged as a fatal error under the node's own logger (its name
    after remapping, also when the constructor failed half-way) and gives
    exit code 2 -- a clear message instead of a traceback.  The node's
    ``close()`` (if any) runs on every exit path once the node was built, so
    devices are closed and models saved.

    With Python's fault handler on (``PYTHONFAULTHANDLER=1``, as the tests
    run nodes), SIGTERM first prints every thread's Python stack to stderr,
    then goes on to rclpy's handler as always: ``ros2 launch`` sends SIGTERM
    to a node still running 5 s after Ctrl-C, so a node hung in a call that
    never returns shows where.

    Once ``close()`` has run, the process ends within
    :data:`~tactile_descriptors_ros.nodes.deadline.END_WITHIN_S` with the
    same status, even if tearing down the middleware blocks
    (:mod:`~tactile_descriptors_ros.nodes.deadline`).
    """
    import rclpy
    from rclpy.executors import ExternalShutdownException

    interrupted = note_interrupts()
    rclpy.init(args=list(args) if args is not None else sys.argv)
    if faulthandler.is_enabled():  # after rclpy's handler is installed, so that the dump chains to it
        faulthandler.register(signal.SIGTERM, all_threads=True, chain=True)
    node = None  # also a node whose constructor failed half-way: its logger has the node's name
    built = False
    code = 0
    try:
        heap = gc_mode()
        if interrupted():  # Ctrl-C came before rclpy's handler was installed: stop before building the node
            return code
        if isinstance(factory, type):
            node = factory.__new__(factory)
            node.__init__()
        else:
            node = factory()
        built = True
        if heap == "freeze":  # start-up's objects (modules, compiled kernels) are never scanned again
            GC_PAUSES.install().settle()
        if rclpy.ok():  # a Ctrl-C during construction has shut the context down already
            spin(node)
    except ExternalShutdownException:
        pass
    except TactileError as exc:
        _logger_of(node, factory).fatal(str(exc))
        code = 2
    except Exception:
        if rclpy.ok() and not interrupted():
            code = 1  # the status Python gives the traceback that follows
            raise
        # a call failed because Ctrl-C shut the context down under it: a clean stop
    finally:
        saved = True
        if node is not None and built:
            close = getattr(node, "close", None)
            if close is not None:
                try:
                    close()
                except Exception as exc:  # noqa: BLE001 - report, keep shutting down
                    saved = False
                    _logger_of(node, factory).error(f"while closing: {exc!r}")
        # Closed: the middleware's teardown may not hold the process up for long.
        logger = _logger_of(node, factory)
        if not end_process_after(END_WITHIN_S, code, logger.name, saved):
            logger.warning(f"no POSIX timers in this C library: if tearing down the middleware blocks, the "
                           f"process ends {END_WITHIN_S:.1f} s from now with its stack and status 1")
        if node is not None:
            try:
                node.destroy_node()
            except Exception:  # noqa: BLE001 - a constructor that failed before rclpy made the node
                pass
        rclpy.try_shutdown()
        _ignore_interrupts()
        # Everything is closed and saved: spare the exit a full garbage collection of the node's
        # heap (seconds for a window node holding 116 cells' buffers on a busy machine, which
        # ros2 launch would escalate to SIGTERM).
        gc.freeze()
    return code


def _logger_of(node: Any, factory: Callable[..., Any]):
    """The node's logger (named after the node as remapped); before rclpy made the node, one of its default name."""
    import inspect

    from rclpy.logging import get_logger

    try:
        return node.get_logger()
    except Exception:  # noqa: BLE001 - the constructor failed before Node.__init__ set the logger up
        pass
    try:
        name = inspect.signature(factory).parameters["node_name"].default
    except (KeyError, TypeError, ValueError):
        name = getattr(factory, "__name__", "node")
    return get_logger(str(name))


def _ignore_interrupts() -> None:
    """Ignore SIGINT from here on: the node has stopped, and at exit Python would reset SIGINT to its
    default (death by signal, which ``ros2 launch`` reports as a crash) unless it is ignored."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
