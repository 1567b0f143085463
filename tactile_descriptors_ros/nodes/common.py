"""Shared pieces of the nodes: parameters, ``/diagnostics``, rates, ``main``.

``diagnostic_updater`` is not available as a wheel, so :class:`Diagnostics`
is a small equivalent: tasks registered by name, each returning a
:class:`Status`, published together as one ``diagnostic_msgs/DiagnosticArray``
on ``/diagnostics`` every ``diagnostics_period_s`` of wall time (a steady
clock, so diagnostics keep flowing under ``use_sim_time`` with no ``/clock``).
Status names follow the ROS convention ``"<node name>: <task>"``.
"""

from __future__ import annotations

import collections
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from ..errors import ConfigError, TactileError

__all__ = [
    "Status",
    "Diagnostics",
    "RateMeter",
    "declare",
    "steady_clock",
    "run_node",
]

_LEVELS = {"ok": 0, "warn": 1, "error": 2, "stale": 3}


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
        self.total = 0

    def add(self, count: int = 1) -> None:
        t = self._now()
        self._events.append((t, int(count)))
        self.total += int(count)
        self._expire(t)

    def _expire(self, t: float) -> None:
        while self._events and self._events[0][0] < t - self.window_s:
            self._events.popleft()

    @property
    def rate_hz(self) -> float:
        t = self._now()
        self._expire(t)
        return sum(c for _, c in self._events) / self.window_s


def steady_clock():
    """An rclpy steady clock (timers on it run on wall time, also under ``use_sim_time``)."""
    from rclpy.clock import Clock, ClockType

    return Clock(clock_type=ClockType.STEADY_TIME)


class Diagnostics:
    """Publish named diagnostic tasks on ``/diagnostics``.

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

    def add(self, task: str, fn: Callable[[], Status]) -> None:
        """Register a task; ``fn`` is called at every publication."""
        self._tasks.append((task, fn))

    def statuses(self) -> list:
        """The current ``DiagnosticStatus`` messages (a failing task reports ERROR, not silence)."""
        from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

        out = []
        for task, fn in self._tasks:
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


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


def declare(node, name: str, default: Any, description: str, *, choices: Sequence[Any] | None = None,
            minimum: float | None = None, read_only: bool = True) -> Any:
    """Declare a parameter and return its value, validated.

    Raises
    ------
    ConfigError
        Naming the parameter, for a value of the wrong type, not among
        ``choices`` or below ``minimum``.
    """
    from rcl_interfaces.msg import ParameterDescriptor

    extra = f" (one of: {', '.join(map(str, choices))})" if choices else ""
    value = node.declare_parameter(name, default,
                                   ParameterDescriptor(description=description + extra, read_only=read_only)).value
    if isinstance(default, bool) and not isinstance(value, bool):
        raise ConfigError(f"must be true or false, got {value!r}", key=name)
    if isinstance(default, float) and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if choices is not None and value not in choices:
        raise ConfigError(f"must be one of {tuple(choices)}, got {value!r}", key=name)
    if minimum is not None and (not isinstance(value, (int, float)) or value < minimum):
        raise ConfigError(f"must be at least {minimum}, got {value!r}", key=name)
    return value


def _interrupt_once() -> None:
    """Make SIGINT raise ``KeyboardInterrupt`` once; ignore the ones that follow.

    A Ctrl-C in a terminal reaches a node twice: from the terminal (the whole
    process group) and from ``ros2 launch``, which forwards it.  A second
    ``KeyboardInterrupt`` would cut the clean-up short (a traceback from a
    thread join or a service's destruction).  Installed before ``rclpy.init``,
    whose handler shuts the context down and then calls this one.
    """
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return  # signal handlers can be set only from the main thread (tests run nodes in threads)
    interrupted = False

    def handler(signum, frame):
        nonlocal interrupted
        if not interrupted:
            interrupted = True
            raise KeyboardInterrupt

    signal.signal(signal.SIGINT, handler)


def run_node(factory: Callable[[], Any], args: Sequence[str] | None = None) -> int:
    """Create a node, spin it until Ctrl-C or shutdown, then clean up.

    A :class:`~tactile_descriptors_ros.errors.TactileError` raised while
    building or spinning the node (misconfiguration, a device that cannot be
    opened) is logged as a fatal error and gives exit code 2 -- a clear
    message instead of a traceback.  The node's ``close()`` (if any) runs on
    every exit path so devices are closed and models saved.
    """
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

    _interrupt_once()
    rclpy.init(args=list(args) if args is not None else sys.argv)
    node = None
    code = 0
    try:
        node = factory()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except TactileError as exc:
        name = node.get_name() if node is not None else "node"
        print(f"[FATAL] [{name}]: {exc}", file=sys.stderr, flush=True)
        code = 2
    except Exception:
        if rclpy.ok():
            raise
        # a callback was cut short by Ctrl-C (e.g. publishing after the context shut down): a clean stop
    finally:
        if node is not None:
            close = getattr(node, "close", None)
            if close is not None:
                try:
                    close()
                except Exception as exc:  # noqa: BLE001 - report, keep shutting down
                    print(f"[ERROR] [{node.get_name()}]: while closing: {exc!r}", file=sys.stderr, flush=True)
            node.destroy_node()
        rclpy.try_shutdown()
    return code
