"""What the device drivers share: robot selection, lifecycle, reader thread, transport diagnostics.

:class:`DriverBase` is the common base of
:class:`~tactile_descriptors_ros.nodes.biotac_driver.BiotacDriver` and
:class:`~tactile_descriptors_ros.nodes.skin_driver.SkinDriver`.  It owns the
transport and the reader thread; a subclass says how to build its simulated
source (:meth:`DriverBase._simulated_source`), how to read
(:meth:`DriverBase._read`) and handle (:meth:`DriverBase._consume`) a batch,
which publishers to create and destroy, and its own diagnostics.

Lifecycle: configure opens the device (:meth:`DriverBase._open_source` may
build a decoder on it), activate starts the reader thread, deactivate stops
it, cleanup closes the device and destroys the publishers.  The device is
held by a :class:`~tactile_descriptors_ros.streams.link.DeviceLink`: a
:class:`~tactile_descriptors_ros.errors.TransportError` in the reader
(an unplugged device) is counted (``transport_errors``), the device is
closed and reopened every ``reconnect_s`` until it is back, without a
lifecycle transition; the time it was gone is counted as lost frames by the
stream (:meth:`DriverBase._reopened`).  Any other exception while reading
(``reader_errors``) or while handling what was read (``consume_errors``) is
counted and reported; the thread reads on.  The longest time between two
reads (``read_gap_max_ms``, ending ``read_gap_max_at_s`` after the first read)
and the reads that came more than :data:`READ_GAP_LONG_S` after the one before
(``read_gaps_long``) say when the thread did not read: a device that buffers
less than that loses frames.
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable
from typing import Any

from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn

from ..core.robot import RobotDescription, load_robot, select_body_parts
from ..errors import ConfigError, TactileError, TransportError
from ..params.schema import NodeSchema
from ..streams.link import DeviceLink
from ..transports import create_transport
from .common import Diagnostics, Status, StopsQuietly
from .conversions import message_kind
from .parameters import NodeParameters
from .qos import qos_of

__all__ = ["DriverBase", "READ_GAP_LONG_S"]

#: A read that starts more than this after the one before is counted (``read_gaps_long``) [s].
READ_GAP_LONG_S = 0.1


class DriverBase(StopsQuietly, LifecycleNode):
    """Base of the device drivers; ``kwargs`` go to :class:`rclpy.lifecycle.LifecycleNode`.

    Parameters
    ----------
    node_name : str
    transport_factory : callable, optional
        For tests: ``f(node) -> Transport`` replacing the ``transport`` parameter's backend.
    """

    #: name of the reader thread
    reader_thread_name = "reader"
    #: frames older than this are stale: ``~/tare`` refuses them, diagnostics report the sensor silent [s]
    stale_after_s = 1.0
    #: close a transport whose configure failed (else it is only dropped)
    close_on_failed_configure = True

    transport_name: str
    stamp_source: str
    sim_scene: str
    tp: dict[str, dict[str, Any]]

    def __init__(self, node_name: str, transport_factory=None, **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        self._transport_factory = transport_factory
        self.transport = None
        self.link: DeviceLink | None = None
        self.faults: Counter[str] = Counter()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        # Ctrl-C shuts the context down (rclpy's signal handler) before main() can stop
        # the reader thread: it stops then, and a publish that raced the shutdown is dropped.
        self.context.on_shutdown(self._stop.set)
        self._thread: threading.Thread | None = None
        self.last_error: str | None = None
        self._last_error_monotonic = float("-inf")
        self.scene_ended_logged = False
        self.read_period_s = 0.0
        #: reads of the device so far (each one decode and one publish round)
        self.reads = 0
        #: the longest time from one read's start to the next one's [s], and how many took longer than
        #: :data:`READ_GAP_LONG_S` (a device that was lost and reopened in between is not counted)
        self.read_gap_max_s = 0.0
        self.read_gaps_long = 0
        #: when the longest gap ended, after the first read [s]
        self.read_gap_max_at_s = 0.0
        self._read_started: float | None = None
        self._first_read: float | None = None

    # ---------------------------------------------------------- parameters
    def _declare_parameters(self, schema: NodeSchema, kind: str, example: str,
                            parts_what: str) -> tuple[RobotDescription, RobotDescription]:
        """Declare every parameter of ``schema``; return the full robot and the served body parts.

        Parameters
        ----------
        schema : NodeSchema
            The driver's parameters.
        kind : str
            Message kind of the body parts served (``biotac`` or ``skin``).
        example : str
            Shipped robot named in the error when ``robot`` is missing.
        parts_what : str
            What the body parts are, for the error when the robot has none.
        """
        self.params = params = NodeParameters(self, schema)
        robot_arg = params.declare("robot")
        if not robot_arg:
            raise ConfigError(f"parameter 'robot' is required (e.g. {example} or a YAML path)", key="robot")
        full = load_robot(robot_arg)
        parts = [p.name for p in full.body_parts if message_kind(full.cell_types[p.cell_type]) == kind]
        if not parts:
            raise ConfigError(f"robot {full.name!r} has no {parts_what} body parts", key="body_parts")
        served = select_body_parts(full, params.declare("body_parts", default=parts))
        params.declare_all(robot=full)
        self.transport_name = params["transport"]
        self.stamp_source = params["stamp_source"]
        self.resync_s = params["resync_s"]
        self.tare_on_start_s = params["tare_on_start_s"]
        self.reconnect_s = params["reconnect_s"]
        self.read_period_s = params["read_period_s"]
        self.sim_scene = params["sim.scene"]
        self.sim_speed = params["sim.speed"]
        self.topic_fmt = params["frames_topic"]
        self.qos_frames = qos_of(params, "frames")
        return full, served

    def _tare_history(self) -> tuple[float, str]:
        """How long the stream keeps samples for a tare [s], and what decides it (for a refusal's reason)."""
        raise NotImplementedError

    def _check_tare_window(self, name: str, window_s: float) -> None:
        """A tare averages the samples the stream keeps: a longer window would silently be a shorter one.

        Raises
        ------
        ConfigError
            Naming ``name`` and what decides the history.
        """
        history_s, why = self._tare_history()
        if window_s > history_s:
            raise ConfigError(f"{window_s:g} s is longer than the {history_s:g} s of samples the driver keeps for a "
                              f"tare ({why})", key=name)

    def _tare_window_hook(self, values, changed):
        """``ros2 param set ... tare.window_s``: checked against the history; the next ``~/tare`` reads it."""
        self._check_tare_window("tare.window_s", values["tare.window_s"])

    def _start(self, tasks: Iterable[tuple[str, Callable[[], Status]]]) -> None:
        """Create ``~/tare`` and the diagnostics (``tasks``), then configure and activate if ``autostart``."""
        from std_srvs.srv import Trigger

        for name in ("tare_on_start_s", "tare.window_s"):
            self._check_tare_window(name, self.params[name])
        self.params.on_set("tare", self._tare_window_hook)
        self.tare_srv = self.create_service(Trigger, "~/tare", self._srv_tare)
        self.diagnostics = Diagnostics(self, self.params["diagnostics_period_s"], hardware_id=self.transport_name)
        for name, task in tasks:
            self.diagnostics.add(name, task)
        self.params.finish()
        if self.params["autostart"]:
            if self.trigger_configure() != TransitionCallbackReturn.SUCCESS:
                raise TransportError(f"configure failed: {self.last_error}")
            if self.trigger_activate() != TransitionCallbackReturn.SUCCESS:
                raise TransportError(f"activate failed: {self.last_error}")

    # ------------------------------------------------- subclass obligations
    def _simulated_source(self):
        """The source of the ``simulated`` transport (``sim.scene`` is set)."""
        raise NotImplementedError

    def _open_source(self) -> None:
        """After the transport opened: build what decodes it (may raise :class:`TactileError`)."""

    def _configured(self) -> TransitionCallbackReturn:
        """After a successful open: create state and publishers."""
        raise NotImplementedError

    def _destroy_publishers(self) -> None:
        """Destroy the lifecycle publishers made by :meth:`_configured`."""
        raise NotImplementedError

    def _read(self) -> list:
        """One read of the device (the reader thread's loop body)."""
        raise NotImplementedError

    def _consume(self, items: list) -> None:
        """Handle what one :meth:`_read` returned."""
        raise NotImplementedError

    def _reopened(self, gap_s: float) -> None:
        """The device was reopened after ``gap_s`` away: rebind the source to ``self.transport``."""
        raise NotImplementedError

    def _srv_tare(self, request, response):
        raise NotImplementedError

    # ------------------------------------------------------------- lifecycle
    def _make_transport(self):
        if self._transport_factory is not None:
            return self._transport_factory(self)
        if self.transport_name == "simulated":
            if not self.sim_scene:
                raise ConfigError("transport 'simulated' needs the parameter sim.scene", key="sim.scene")
            return create_transport("simulated", source=self._simulated_source())
        if self.transport_name == "loopback":
            return create_transport("loopback", timeout_s=0.05)
        return create_transport(self.transport_name, **self.tp[self.transport_name])

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        try:
            self.link = DeviceLink(self._make_transport, retry_s=getattr(self, "reconnect_s", 0.25))
            self.link.open()
            self.transport = self.link.transport
            self._open_source()
        except TactileError as exc:
            self.last_error = str(exc)
            self.get_logger().error(f"cannot open {self.transport_name} transport: {exc}")
            if self.transport is not None and self.close_on_failed_configure:
                self.transport.close()
            self.transport = None
            self.link = None
            return TransitionCallbackReturn.FAILURE
        return self._configured()

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, daemon=True, name=self.reader_thread_name)
        self._thread.start()
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._stop_thread()
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._stop_thread()
        self._close_transport()
        self._destroy_publishers()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.close()
        return TransitionCallbackReturn.SUCCESS

    def close(self) -> None:
        """Stop reading and close the device (called on every exit path by ``main``)."""
        self._stop_thread()
        self._close_transport()

    def _stop_thread(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None

    def _close_transport(self) -> None:
        link, self.link = self.link, None
        transport, self.transport = self.transport, None
        if link is not None:
            link.close()
        elif transport is not None:
            transport.close()

    # ---------------------------------------------------------------- reading
    def scene_ended(self) -> bool:
        """The simulated transport's scene has been played to its end (always False on hardware)."""
        if self.transport_name != "simulated" or self.transport is None:
            return False
        return bool(getattr(getattr(self.transport, "source", None), "finished", False))

    def _note_scene_end(self) -> None:
        if not self.scene_ended_logged and self.scene_ended():
            self.scene_ended_logged = True
            self.get_logger().info(f"simulated scene {self.sim_scene} ended: no more frames (the sensors are idle, "
                                   "not unplugged)")

    def _run(self) -> None:
        while not self._stop.is_set() and self.context.ok():
            link = self.link
            if link is not None and not link.connected:
                if not link.poll_reopen():
                    self._stop.wait(max(0.01, link.wait_s()))
                    continue
                self.transport = link.transport
                self.get_logger().info(f"{self.transport_name} device back after {link.last_gap_s:.2f} s")
                try:
                    self._reopened(link.last_gap_s)
                except Exception as exc:  # noqa: BLE001 - report and keep the node alive
                    self._count_error("reader_errors", f"after reopening: {exc!r}")
                continue
            started = time.monotonic()
            self._note_read_gap(started)
            try:
                items = self._read()
                self.reads += 1
            except TransportError as exc:
                self.faults["transport_errors"] += 1
                self.last_error = str(exc)
                self.get_logger().error(f"transport: {exc}; reopening every {self.reconnect_s} s",
                                        throttle_duration_sec=5.0)
                self._read_started = None  # the time until the device is back is no reader's gap
                if link is not None:
                    link.lost(exc)
                else:
                    self._stop.wait(0.5)
                continue
            except Exception as exc:  # noqa: BLE001 - report and keep the node alive
                self._count_error("reader_errors", f"reader: {exc!r}")
                self._stop.wait(0.5)
                continue
            try:
                self._consume(items)
            except Exception as exc:  # noqa: BLE001 - a bad batch is counted, the thread reads on
                if not self.context.ok():
                    return  # published after shutdown: the node is stopping, not faulty
                self._count_error("consume_errors", f"handling a read: {exc!r}")
            if not items:
                self._note_scene_end()
            if self.read_period_s > 0:
                # Every read costs a decode and a publish round for all cells whatever it holds: a large skin
                # read as soon as anything is due pays that round a thousand times a second.
                self._stop.wait(max(0.0, self.read_period_s - (time.monotonic() - started)))

    def _note_read_gap(self, started: float) -> None:
        if self._first_read is None:
            self._first_read = started
        if self._read_started is not None:
            gap_s = started - self._read_started
            if gap_s > self.read_gap_max_s:
                self.read_gap_max_s = gap_s
                self.read_gap_max_at_s = started - self._first_read
            self.read_gaps_long += gap_s > READ_GAP_LONG_S
        self._read_started = started

    def _count_error(self, counter: str, text: str) -> None:
        self.faults[counter] += 1
        self.last_error = text
        self._last_error_monotonic = time.monotonic()
        self.get_logger().error(text, throttle_duration_sec=5.0)

    # ------------------------------------------------------------ diagnostics
    def _transport_values(self, settings: dict[str, Any]) -> dict[str, Any]:
        """Key/values of the transport status: name, ``settings``, stamp source, device description, link, faults."""
        values = {"transport": self.transport_name, **settings, "stamp_source": self.stamp_source,
                  "reads": self.reads, "read_gap_max_ms": round(1e3 * self.read_gap_max_s, 3),
                  "read_gap_max_at_s": round(self.read_gap_max_at_s, 3), "read_gaps_long": self.read_gaps_long}
        if self.transport is not None:
            values.update({f"device_{k}": v for k, v in self.transport.describe().items()})
        if self.link is not None:
            values.update({f"link_{k}": v for k, v in self.link.as_dict().items()})
        values.update(dict(self.faults))
        if self.last_error:
            values["last_error"] = self.last_error
        return values

    def _transport_error(self, values: dict[str, Any]) -> Status | None:
        """The status of a closed or lost transport, or of recent reader faults; ``None`` when all is well.

        Faults are history (counters in ``values``); the level says what holds
        now: error while the device is gone, warn for a reader or handling
        fault in the last 10 s, nothing once the device is back and reading.
        """
        if self.transport is None or (self.link is not None and not self.link.connected):
            if self.link is not None and not self.link.connected:
                return Status("error", f"device lost {self.link.down_for_s:.1f} s ago, reopening: "
                                       f"{self.link.last_error}", values)
            return Status("error", f"not open{': ' + self.last_error if self.last_error else ''}", values)
        if time.monotonic() - self._last_error_monotonic < 10.0:
            return Status("warn", self.last_error or "reader errors", values)
        return None
