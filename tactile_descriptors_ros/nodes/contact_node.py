"""``contact_node``: tactile frames -> contact per body part, and what rviz2 and the views draw.

Subscribes to the frames of the body parts it serves (``BioTacFrameBatch`` or
``SkinPartFrames``) and, for every frames message (the drivers' batch: the
frame rate, not the descriptor rate), publishes the body part's contact
(:mod:`~..core.contact`) while either of its topics has a subscriber
(``contact.lazy``; false: whether or not).  A skin body part's frames are
taken as their serialised bytes and read in one compiled pass
(:mod:`~..codecs.cdr`, ``frames.serialized``), as the window node takes them:

* ``tactile/<body part>/contact`` (``Contact``): in contact, total normal
  force, centre of pressure and normal in the body part's link frame, the
  active cells, each cell's force (and a BioTac's electrodes' share);
* ``tactile/<body part>/wrench`` (``geometry_msgs/WrenchStamped``): the same
  contact as a force and torque at the link frame's origin.

Once per display period (``view.rate_hz``; :mod:`~..core.display`):

* ``tactile/<body part>/markers`` (``visualization_msgs/MarkerArray``): each
  cell (and site) coloured by force, grey when stale, the contact point and
  normal, the latest prediction and its confidence as text; only the markers
  that changed, and every marker once per ``view.refresh_s``;
* ``tactile/<body part>/image`` (``sensor_msgs/Image``, rgb8): the "tactile
  image", the body part's cells on their flat layout; when a colour changed,
  and once per ``view.refresh_s``;
* ``tactile/contacts`` (``ContactArray``): every body part's contact of the
  period, what ``tactile view`` draws.

It needs the robot's geometry (``geometry`` in the robot description).
Everything runs on the sensor stamps; the display period runs on wall time.
Topics, parameters, QoS, rate and latency: ``docs/view.md``.
"""

from __future__ import annotations

import array
import math
import time
from collections import Counter, deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from rclpy.node import Node

from ..codecs.cdr import SkinPartFramesCdr
from ..codecs.cdr import load_compiled as load_cdr
from ..core.colormap import force_colours
from ..core.contact import ContactWindow, load_compiled, reduce_chunk, reduce_skin_runs
from ..core.display import PartDisplay, PredictionHistory
from ..core.geometry import Taxels, layout_2d
from ..core.robot import BodyPart, load_robot, select_body_parts
from ..core.tactile_image import ImageLayout, image_layout, render
from ..errors import ConfigError, SignalError
from ..params.contact_node import CONTACT_NODE
from ..topics import (
    CONTACT_TOPIC,
    CONTACTS_TOPIC,
    DESCRIPTOR_TOPIC,
    IMAGE_TOPIC,
    MARKERS_TOPIC,
    PREDICTION_TOPIC,
    WRENCH_TOPIC,
)
from .common import Diagnostics, Status, StopsQuietly, host_age_ms, run_node, steady_clock, take_frames
from .contact_msgs import MarkerStyle, PartMarkers, contact_to_msg, image_to_msg, wrench_to_msg
from .conversions import biotac_msg_to_chunk, message_kind, stamp_to_ns
from .parameters import NodeParameters
from .qos import qos_of

__all__ = ["ContactNode", "main"]


@dataclass
class _Part:
    """What the node keeps of one body part."""

    part: BodyPart
    kind: str  # "biotac" | "skin"
    frame_id: str
    taxels: Taxels
    cell_ids: np.ndarray
    n_deformation: int
    vibration_scale: float
    vibration_unit: str
    display: PartDisplay
    markers: PartMarkers
    image: ImageLayout
    pubs: dict
    window: ContactWindow  # one message's, reused
    messages: int = 0
    image_rgb: np.ndarray | None = None  # the taxel colours of the last image published


class ContactNode(StopsQuietly, Node):
    """The contact node; ``kwargs`` go to :class:`rclpy.node.Node` (``context``, ``parameter_overrides``)."""

    def __init__(self, node_name: str = "contact_node", **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        from geometry_msgs.msg import WrenchStamped
        from sensor_msgs.msg import Image
        from visualization_msgs.msg import MarkerArray

        from tactile_descriptors_msgs.msg import (
            BioTacFrameBatch,
            Contact,
            ContactArray,
            Descriptor,
            Prediction,
            SkinPartFrames,
        )

        self.params = params = NodeParameters(self, CONTACT_NODE)
        robot_arg = params.declare("robot")
        if not robot_arg:
            raise ConfigError("parameter 'robot' is required (e.g. shadow_hand, nao or a YAML path)", key="robot")
        full = load_robot(robot_arg)
        self.robot = select_body_parts(full, params.declare("body_parts", default=[p.name for p in full.body_parts]))
        if self.robot.geometry is None:
            raise ConfigError(f"robot {self.robot.name!r} has no geometry section: contact location and the views "
                              "need where the cells are (docs/view.md)", key="robot", source=self.robot.source)
        geo = self.robot.geometry
        view = self.robot.view
        params.declare_all(robot=self.robot, defaults={"view.rate_hz": view.rate_hz,
                                                       "view.force_max_n": view.force_max_n,
                                                       "view.stale_s": view.stale_s})
        self.threshold_n = params["contact.force_threshold_n"]
        self.floor_n = params["contact.floor_n"]
        self.lazy = params["contact.lazy"]
        self.rate_hz = params["view.rate_hz"]
        self.force_max_n = params["view.force_max_n"]
        stale_s = params["view.stale_s"]
        size_px = params["view.image_size_px"]
        refresh_s = params["view.refresh_s"]
        self.markers_on = params["view.markers"]
        self.images_on = params["view.images"]
        topic_fmt = params["frames_topic"]
        self.drain_max = params["frames.drain_max"]
        # skin cells' frames taken serialised and read in one compiled pass (codecs/cdr.py)
        self.frames_serialized = params["frames.serialized"] and load_cdr()
        params.on_set("threshold", lambda values, _names: lambda: self._set_threshold(
            values["contact.force_threshold_n"]))
        params.on_set("floor", lambda values, _names: lambda: self._set_floor(values["contact.floor_n"]))
        params.on_set("lazy", lambda values, _names: lambda: setattr(self, "lazy", values["contact.lazy"]))
        params.on_set("scale", lambda values, _names: lambda: setattr(self, "force_max_n", values["view.force_max_n"]))
        params.on_set("drain", lambda values, _names: lambda: setattr(self, "drain_max", values["frames.drain_max"]))
        qos_frames = qos_of(params, "frames")
        qos_contact = qos_of(params, "contact")
        qos_view = qos_of(params, "view")
        qos_pred = qos_of(params, "prediction")

        self.parts: dict[str, _Part] = {}
        self.subs = []
        self._handlers: dict[object, Callable] = {}
        for part in self.robot.body_parts:
            ct = self.robot.cell_types[part.cell_type]
            kind = message_kind(ct)
            taxels = geo.taxels(self.robot, part.name)
            flat = layout_2d(taxels.positions, taxels.normals)
            try:
                img = image_layout(flat, size_px)
            except ValueError as exc:
                raise ConfigError(str(exc), key="view.image_size_px") from None
            pubs = {"contact": self.create_publisher(Contact, CONTACT_TOPIC.format(body_part=part.name), qos_contact),
                    "wrench": self.create_publisher(WrenchStamped, WRENCH_TOPIC.format(body_part=part.name),
                                                    qos_contact)}
            if self.rate_hz > 0 and self.markers_on:
                pubs["markers"] = self.create_publisher(MarkerArray, MARKERS_TOPIC.format(body_part=part.name),
                                                        qos_view)
            if self.rate_hz > 0 and self.images_on:
                pubs["image"] = self.create_publisher(Image, IMAGE_TOPIC.format(body_part=part.name), qos_view)
            ids = np.array([c.id for c in part.cells], dtype=np.int64)
            self.parts[part.name] = _Part(
                part, kind, geo.part_links[part.name], taxels, ids, len(ct.deformation.channels),
                ct.vibration.si_per_count, ct.vibration.unit,
                PartDisplay(taxels, ids, len(ct.deformation.channels), threshold_n=self.threshold_n,
                            floor_n=self.floor_n, stale_s=stale_s),
                PartMarkers(taxels, MarkerStyle.of(taxels), [geo.cell_poses[c.id] for c in part.cells]), img, pubs,
                ContactWindow(ids, len(ct.deformation.channels)))
            mtype, handler = (BioTacFrameBatch, self._on_biotac) if kind == "biotac" else \
                (SkinPartFrames, self._on_skin_part)
            sub = self.create_subscription(mtype, topic_fmt.format(body_part=part.name), self._on_frames, qos_frames,
                                           raw=self.frames_serialized and kind != "biotac")
            self.subs.append(sub)
            self._handlers[sub] = handler
        self._by_type = {BioTacFrameBatch: self._on_biotac, SkinPartFrames: self._on_skin_part,
                         SkinPartFramesCdr: self._on_skin_part}
        if any(p.kind == "skin" for p in self.parts.values()):
            load_compiled()  # the sums of a body part's message, before its first message
        self._sensor_cell = {(p.name, c.name): c.id for p in self.robot.body_parts for c in p.cells}
        self.history = PredictionHistory()
        self.contacts_pub = self.create_publisher(ContactArray, CONTACTS_TOPIC, qos_view) if self.rate_hz > 0 else None
        self.create_subscription(Prediction, PREDICTION_TOPIC, self._on_prediction, qos_pred)
        self.create_subscription(Descriptor, DESCRIPTOR_TOPIC, self._on_descriptor, qos_pred)
        self.faults: Counter[str] = Counter()
        self.newest_ns = -1
        self.contacts_published = 0
        self.contacts_unsubscribed = 0  # frames messages whose contact nobody subscribed to (contact.lazy)
        self.display_ticks = 0
        self.markers_published = 0
        self.images_published = 0
        # the display's own CPU (thread time of its ticks and of its bookkeeping per message), for
        # diagnostics: what the views cost this node whatever rate the frames come at
        self.display_tick_cpu_s = 0.0
        self.display_merge_cpu_s = 0.0
        self.display_merges = 0
        self.display_on = self.rate_hz > 0
        # ticks between full marker arrays and images (every tick when refresh_s is shorter than a period)
        self.refresh_ticks = max(1, round(refresh_s * self.rate_hz)) if self.display_on else 1
        self.frames_taken = 0
        self._age_ms: deque[float] = deque(maxlen=5000)
        self.contacts_not_host_time = 0
        self._tick_ms: deque[float] = deque(maxlen=500)
        self.diagnostics = Diagnostics(self, params["diagnostics_period_s"])
        self.diagnostics.add("contact", self._status)
        params.finish()
        # the display period: a timer, and the frames callback when a period is due (a flood of frames, which
        # the executor serves before it waits again, would otherwise hold the timer off for seconds)
        self._period_s = 1.0 / self.rate_hz if self.rate_hz > 0 else math.inf
        self._last_tick_s = -math.inf
        self._timer = self.create_timer(self._period_s, self._tick_if_due, clock=steady_clock()) \
            if self.rate_hz > 0 else None
        self.get_logger().info(
            f"robot {self.robot.name}: contact of {len(self.parts)} body parts "
            f"({', '.join(self.parts)}) at the frame rate"
            + (f", markers, images and tactile/contacts at {self.rate_hz:g} Hz" if self.rate_hz > 0 else ""))

    # ------------------------------------------------------- parameters
    def _set_threshold(self, value: float) -> None:
        self.threshold_n = value
        for p in self.parts.values():
            p.display.threshold_n = value

    def _set_floor(self, value: float) -> None:
        self.floor_n = value
        for p in self.parts.values():
            p.display.floor_n = value

    # ------------------------------------------------------------ input
    def _on_frames(self, msg) -> None:
        """Frames callback: this message and every one already waiting, each its own contact."""
        now_ns = time.time_ns()
        for sub_msg, handle in self._drain(msg):
            handle(sub_msg, now_ns)
        if self.display_on:
            self._tick_if_due()

    def _drain(self, first) -> list[tuple[object, Callable]]:
        out, taken = take_frames(first, self.subs, self._handlers, self._by_type, self.drain_max, self.faults,
                                 self.get_logger())
        self.frames_taken += taken
        return out

    def _on_biotac(self, msg, now_ns: int) -> None:
        p = self.parts.get(msg.body_part)
        cid = self._sensor_cell.get((msg.body_part, msg.sensor_name))
        if p is None or cid is None:
            self.faults["unknown_sensor"] += 1
            self.get_logger().warning(f"frames from unknown sensor {msg.sensor_name!r} on body part "
                                      f"{msg.body_part!r}; dropped", throttle_duration_sec=5.0)
            return
        try:
            r = reduce_chunk(biotac_msg_to_chunk(msg), float(msg.pac_pa_per_count) or p.vibration_scale)
        except SignalError as exc:
            self.faults["malformed"] += 1
            self.get_logger().warning(f"malformed BioTacFrameBatch from {msg.sensor_name}: {exc}",
                                      throttle_duration_sec=5.0)
            return
        window = p.window
        window.reset()
        window.add(cid, r)
        if self.display_on:
            self._display_merge(p, window)
        self._publish_contact(p, window, now_ns)

    def _on_skin_part(self, msg, now_ns: int) -> None:
        p = self.parts.get(msg.body_part)
        if p is None:
            self.faults["unknown_body_part"] += 1
            return
        try:
            a = [_np(msg.accel_x, np.int16), _np(msg.accel_y, np.int16), _np(msg.accel_z, np.int16)]
            if not a[0].size == a[1].size == a[2].size:
                raise SignalError("accelerometer axes differ in length")
            runs = reduce_skin_runs(
                _np(msg.cell_ids, np.uint32), _np(msg.force, np.uint16), _np(msg.force_count, np.uint32),
                _np(msg.force_offset_ns, np.int64), _np(msg.force_tare_counts, np.float64),
                float(msg.force_n_per_count), np.stack(a), _np(msg.accel_count, np.uint32),
                float(msg.accel_mps2_per_count) or p.vibration_scale, stamp_to_ns(msg.header.stamp))
        except SignalError as exc:
            self.faults["malformed"] += 1
            self.get_logger().warning(f"malformed SkinPartFrames of body part {msg.body_part!r}: {exc}",
                                      throttle_duration_sec=5.0)
            return
        window = p.window
        window.reset()
        foreign = window.add_runs(runs)
        if foreign:
            self.faults["unknown_cell"] += foreign
        if self.display_on:
            self._display_merge(p, window)
        self._publish_contact(p, window, now_ns)

    def _display_merge(self, p: _Part, window: ContactWindow) -> None:
        """The message's window into the display period's (its thread CPU counted: the display's cost)."""
        c0 = time.thread_time()
        p.display.merge(window, time.monotonic())
        self.display_merge_cpu_s += time.thread_time() - c0
        self.display_merges += 1

    def _publish_contact(self, p: _Part, window: ContactWindow, now_ns: int) -> None:
        if window.end_ns < 0:
            self.faults["no_valid_force"] += 1
            return
        if self.lazy and not (p.pubs["contact"].get_subscription_count() or p.pubs["wrench"].get_subscription_count()):
            # locating the contact and building and publishing its two messages were most of a skin message's
            # cost in this node; the display merged the message already
            self.contacts_unsubscribed += 1
            self.newest_ns = max(self.newest_ns, window.end_ns)
            return
        est = window.contact(p.taxels, threshold_n=self.threshold_n, floor_n=self.floor_n)
        p.pubs["contact"].publish(contact_to_msg(
            est, body_part=p.part.name, frame_id=p.frame_id, cell_ids=p.cell_ids, start_ns=window.start_ns,
            end_ns=window.end_ns, threshold_n=self.threshold_n, taxels=p.taxels, vibration_unit=p.vibration_unit))
        p.pubs["wrench"].publish(wrench_to_msg(est, frame_id=p.frame_id, stamp_ns=window.end_ns))
        p.messages += 1
        self.contacts_published += 1
        self.newest_ns = max(self.newest_ns, window.end_ns)
        age_ms = host_age_ms(time.time_ns(), window.end_ns)
        if age_ms is not None:
            self._age_ms.append(age_ms)
        else:  # device stamps (a simulator's scene time, a bridge's own clock): no age on the host clock
            self.contacts_not_host_time += 1

    def _on_prediction(self, msg) -> None:
        self.history.prediction(int(msg.exploration_id), stamp_to_ns(msg.window_end), str(msg.class_name),
                                list(msg.class_names), list(msg.scores), bool(msg.has_model))

    def _on_descriptor(self, msg) -> None:
        self.history.descriptor(int(msg.exploration_id), stamp_to_ns(msg.window_end), list(msg.body_parts),
                                list(msg.contact))

    # ----------------------------------------------------------- output
    def _tick_if_due(self) -> None:
        """A display tick when 90 % of a period has passed since the last (timer jitter is no reason to skip one)."""
        now = time.monotonic()
        if now - self._last_tick_s >= 0.9 * self._period_s:
            self._last_tick_s = now
            self._tick()

    def _tick(self) -> None:
        """Close every body part's display period; markers, images, tactile/contacts."""
        from tactile_descriptors_msgs.msg import ContactArray

        started, cpu0 = time.perf_counter(), time.thread_time()
        wall = time.monotonic()
        latest = self.history.latest
        arr = ContactArray()
        arr.robot = self.robot.name
        arr.header.frame_id = self.robot.geometry.root_frame
        end = -1
        full = self.display_ticks % self.refresh_ticks == 0
        for name, p in self.parts.items():
            frame = p.display.tick(self.newest_ns, wall)
            stamp = frame.end_ns if frame.end_ns >= 0 else self.newest_ns
            end = max(end, stamp)
            text = ""
            if latest is not None and latest.has_model and name in latest.body_parts:
                text = f"{latest.class_name} {100 * latest.confidence:.0f}%"
            if "markers" in p.pubs:
                changed = p.markers.update(frame, stamp_ns=stamp, force_max_n=self.force_max_n, text=text,
                                           full=full)
                if changed is not None:
                    p.pubs["markers"].publish(changed)
                    self.markers_published += len(changed.markers)
            if "image" in p.pubs:
                rgb = force_colours(np.where(frame.taxel_stale, np.nan, frame.contact.taxel_force_n),
                                    self.force_max_n)
                if full or p.image_rgb is None or not np.array_equal(rgb, p.image_rgb):
                    p.pubs["image"].publish(image_to_msg(render(p.image, rgb), frame_id=p.frame_id,
                                                         stamp_ns=stamp))
                    p.image_rgb = rgb
                    self.images_published += 1
            arr.contacts.append(contact_to_msg(
                frame.contact, body_part=name, frame_id=p.frame_id, cell_ids=p.cell_ids,
                start_ns=frame.start_ns if frame.start_ns >= 0 else stamp, end_ns=stamp,
                threshold_n=self.threshold_n, taxels=p.taxels, vibration_unit=p.vibration_unit))
        arr.header.stamp = self._stamp(end)
        self.contacts_pub.publish(arr)
        self.display_ticks += 1
        self._tick_ms.append(1e3 * (time.perf_counter() - started))
        self.display_tick_cpu_s += time.thread_time() - cpu0

    @staticmethod
    def _stamp(t_ns: int):
        from .conversions import ns_to_stamp

        return ns_to_stamp(max(t_ns, 0))

    def _status(self) -> Status:
        values: dict = {"contacts_published": self.contacts_published,
                        "contacts_unsubscribed": self.contacts_unsubscribed, "display_ticks": self.display_ticks,
                        "markers_published": self.markers_published, "images_published": self.images_published,
                        "display_tick_cpu_ms": round(1e3 * self.display_tick_cpu_s, 3),
                        "display_merges": self.display_merges,
                        "display_merge_cpu_ms": round(1e3 * self.display_merge_cpu_s, 3),
                        "frames_messages_taken": self.frames_taken,
                        "frames_serialized": self.frames_serialized,
                        "contacts_not_host_time": self.contacts_not_host_time}
        for name, samples in (("contact_age", self._age_ms), ("display_tick", self._tick_ms)):
            if samples:
                a = np.fromiter(samples, np.float64, len(samples))
                values.update({f"{name}_ms_p50": float(np.median(a)), f"{name}_ms_p95": float(np.percentile(a, 95)),
                               f"{name}_ms_max": float(a.max())})
        for name, p in self.parts.items():
            values[f"{name}_contacts"] = p.messages
        values.update({f"fault_{k}": v for k, v in sorted(self.faults.items())})
        bad = {k: v for k, v in self.faults.items() if v}
        if bad:
            return Status("warn", "faults: " + ", ".join(f"{k}={v}" for k, v in sorted(bad.items())), values)
        return Status("ok", f"{self.contacts_published} contacts, {self.contacts_unsubscribed} with no subscriber",
                      values)


def _np(values, dtype) -> np.ndarray:
    """An rclpy array field (``array.array``, a view) or a sequence as a numpy array."""
    if isinstance(values, array.array):
        return np.frombuffer(values, dtype=dtype) if len(values) else np.zeros(0, dtype)
    return np.asarray(values, dtype=dtype)


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of the ``contact_node`` executable."""
    return run_node(ContactNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
