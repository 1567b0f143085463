"""``window_node``: tactile frames -> contact gate -> windows -> ``Descriptor``.

Subscribes to the frames of the body parts it serves (``BioTacFrameBatch`` or
``SkinPartFrames``, chosen by each body part's cell type), converts them to
:class:`~tactile_descriptors_ros.core.windowing.CellChunk` (force: BioTac
``(PDC - tare) * force_n_per_count``; skin cell: mean of the three tared force
sensors times their scale), cuts fixed or exploration windows with
:class:`~tactile_descriptors_ros.core.windowing.Windower` and publishes the
robot descriptor of each window (Kaboli et al. 2018, eq. 11-18, 28-29).

Frames are taken in batches: a frames callback also takes every message
already waiting on all the node's frames subscriptions (at most
``frames.drain_max``), converts them, hands them to the windower in one
:meth:`~tactile_descriptors_ros.core.windowing.Windower.add_many` call and
polls for finished windows once.  rclpy's executor costs about 0.2 ms of CPU
per callback here, more than the conversion and the windowing together, so a
node that has fallen behind catches up instead of paying that per message
(``lab/docs/performance.md, section Latency``).  A skin body part's frames are
taken as their serialised bytes and read in one compiled pass
(:mod:`~tactile_descriptors_ros.codecs.cdr`, ``frames.serialized``): rclpy
building each message cost the node about a sixth of its CPU in the NAO graph.

The node subscribes as soon as it starts.  The descriptor kernel loads from
its on-disk cache (``make setup`` fills it) on a thread meanwhile, in about a
second, which the constructor waits for (at most ``WARM_UP_WAIT_S``; frames
queue on the subscriptions).  When the cache is missing the kernel compiles
for about 30 s: the node runs on, and windows that close before the kernel is
ready are held and described in order once it is, so no touch at start-up is
lost (``windows_held_at_start`` in diagnostics).

Everything runs on the *sensor time stamps*: live data, ``use_sim_time`` and
replayed bags give the same windows.  Faults (unknown sensors, malformed
messages, lost frames, the windower's out-of-order / duplicate / clock-jump
counters) are counted and reported on ``/diagnostics``, with the latency
path's timing: ``frames_age_ms_*`` (host time when a message is taken minus
its newest sample's stamp: acquisition to intake, for sensor stamps on the
host clock, as the drivers' ``clock`` stamps are; messages stamped on
another clock, ``device`` stamps, are counted in ``frames_not_host_time``
instead) and
``cut_ms_*`` (the windower's poll that cut one or more windows: their cells'
samples copied out of its buffers) and ``describe_ms_*`` (window cut to
descriptor published), median, p95 and max over the last messages and windows.

In exploration mode an exploration's window is described during its release
time (``window.describe_ahead``, :mod:`~tactile_descriptors_ros.core.ahead`):
when the release is decided and the window still holds the same samples,
that descriptor is published at once (``described_ahead_used``; the cost of
those descriptions is ``describe_ahead_ms_*``).  In fixed mode the next
window's samples are cut once its end is within ``CUT_AHEAD_S`` (50 ms) of the newest ones
(``window.cut_ahead``, :meth:`~tactile_descriptors_ros.core.windowing.Windower.cut_fixed_ahead`),
so the poll that closes it copies only the samples since
(``cut_ahead_used``, ``cut_ahead_recut``; the early cut's cost is
``cut_ahead_ms_*``).

Topics, parameters and QoS: ``docs/nodes.md``.
"""

from __future__ import annotations

import threading
import time
from collections import Counter, deque
from collections.abc import Callable, Mapping, Sequence

import numpy as np
from rclpy.node import Node

from ..codecs.cdr import SkinPartFramesCdr
from ..codecs.cdr import load_compiled as load_cdr
from ..codecs.sequence import SequenceEvent, SequenceTracker
from ..core.aggregation import RobotDescriptor
from ..core.ahead import DescribeAhead
from ..core.blocks import describe_blocks
from ..core.fast import warm_up
from ..core.groups import check_groups, groups_of_channels, selection_name
from ..core.robot import check_blocks, load_robot, select_body_parts
from ..core.windowing import CellChunk, PartChunk, Window, Windower, rehearsal_window
from ..errors import ConfigError, SignalError
from ..params.window_node import WINDOW_NODE
from ..streams.skin_parts import RunChecker
from ..topics import DESCRIPTOR_TOPIC, layout_topic
from .common import (
    Diagnostics,
    RateMeter,
    Status,
    StopsQuietly,
    host_age_ms,
    keep_freed_memory,
    run_node,
    steady_clock,
    take_frames,
)
from .conversions import (
    biotac_msg_to_chunk,
    descriptor_layout_to_msg,
    descriptor_to_msg,
    layout_id,
    message_kind,
    skin_part_msg_to_part_chunk,
)
from .parameters import NodeParameters
from .qos import qos_of

__all__ = ["WindowNode", "frames_matched", "main"]



class WindowNode(StopsQuietly, Node):
    """The window node; ``kwargs`` go to :class:`rclpy.node.Node` (``context``, ``parameter_overrides``)."""

    def __init__(self, node_name: str = "window_node", **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        from tactile_descriptors_msgs.msg import BioTacFrameBatch, Descriptor, DescriptorLayout, SkinPartFrames

        self.params = params = NodeParameters(self, WINDOW_NODE)
        robot_arg = params.declare("robot")
        if not robot_arg:
            raise ConfigError("parameter 'robot' is required (e.g. shadow_hand, nao or a YAML path)", key="robot")
        full = load_robot(robot_arg)
        self.robot = select_body_parts(full, params.declare("body_parts", default=[p.name for p in full.body_parts]))
        root = self.robot.geometry.root_frame if self.robot.geometry is not None else self.robot.name
        params.declare_all(robot=self.robot, defaults={"frame_id": root})
        self.layout = params["descriptor.layout"]
        self.groups = self._groups()
        self.block_s, self.block_hop_s = check_blocks(
            params["descriptor.block_s"], params["descriptor.block_hop_s"],
            rates_hz=[ct.deformation.rate_hz for ct in self.robot.cell_types.values()])
        # What a user tunes on a running robot (the schema's "windower" parameters): checked together by the
        # windower, applied from the next window (length, hop) or onset/release decision (thresholds) on.
        self.windower = Windower(self.robot, mode=params["window.mode"], **_windower_settings(params))
        params.on_set("windower", self._retune_windower)
        self.force_threshold_n = self.windower.onset_n
        # an exploration's window is described while its release time runs (core/ahead.py); a description
        # made under another contact threshold or frame id than the decision's is not used
        self.ahead = DescribeAhead(self._descriptor_msg, lambda: (self.force_threshold_n, self.params["frame_id"])) \
            if params["window.describe_ahead"] else None
        self.cut_ahead = params["window.cut_ahead"] and self.windower.mode == "fixed"
        self.id_stride = params["exploration_id_stride"]
        self.id_offset = params["exploration_id_offset"]
        if self.id_offset >= self.id_stride and self.id_stride > 1:
            raise ConfigError(f"must be below exploration_id_stride ({self.id_stride})",
                              key="exploration_id_offset")
        topic_fmt = params["frames_topic"]
        self.descriptors_published = 0
        self.last_quality: dict[str, int] = {}
        self.faults: Counter[str] = Counter()
        self._untared: set[str] = set()
        self._sequences = SequenceTracker(1 << 32, window=0)  # message sequence numbers are 32-bit
        self._rates: dict[str, RateMeter] = {}
        self._last_seen: dict[str, float] = {}

        # The descriptor kernel loads from its cache (filled by ``make setup``) in about a second, but
        # compiles for about 30 s when the cache is missing or stale.  The node subscribes at once and
        # warms the kernel up on a thread: frames are windowed as they come, and the windows that close
        # before the kernel is ready are held and described, in order, as soon as it is.
        self.kernel_ready = threading.Event()
        self.kernel_info: dict | None = None
        self.held_windows: list[Window] = []
        self.windows_held_at_start = 0
        qos_frames = qos_of(params, "frames")
        qos_desc = qos_of(params, "descriptor")
        self.pub = self.create_publisher(Descriptor, DESCRIPTOR_TOPIC, qos_desc)
        # the labels of the values, once per layout, latched beside the descriptors (remapped with them)
        self.layout_pub = self.create_publisher(DescriptorLayout, layout_topic(self.pub.topic_name),
                                                qos_of(params, "layout"))
        self.layouts_published: set[str] = set()
        self._layout_ids: dict[tuple[str, ...], str] = {}  # labels -> layout_id
        self._cells_by_name: dict[tuple[str, str], int] = {}
        self._extra: dict[str, tuple[str, ...]] = {}  # body part -> its cell type's extra channels
        self.subs = []
        # skin cells' frames taken serialised and read in one compiled pass (codecs/cdr.py)
        self.frames_serialized = params["frames.serialized"] and load_cdr()
        self._part_sub: dict[str, object] = {}  # body part -> its frames subscription
        self._handlers: dict[object, object] = {}
        for part in self.robot.body_parts:
            kind = message_kind(self.robot.cell_types[part.cell_type])
            topic = topic_fmt.format(body_part=part.name)
            self._rates[part.name] = RateMeter()
            for cell in part.cells:
                self._cells_by_name[(part.name, cell.name)] = cell.id
            self._extra[part.name] = self.robot.cell_types[part.cell_type].extra_channels
            if kind == "biotac":
                cb = self._on_biotac
                mtype = BioTacFrameBatch
            else:
                cb = self._on_skin_part
                mtype = SkinPartFrames
            sub = self.create_subscription(mtype, topic, self._on_frames, qos_frames,
                                           raw=self.frames_serialized and kind != "biotac")
            self.subs.append(sub)
            self._part_sub[part.name] = sub
            self._handlers[sub] = cb
        self._by_type = {BioTacFrameBatch: self._on_biotac, SkinPartFrames: self._on_skin_part,
                         SkinPartFramesCdr: self._on_skin_part}
        self.frames_taken = 0
        self.batches = 0
        self.largest_batch = 0
        # timing of the latency path (diagnostics): how old the frames are when taken, how long a window takes
        self._frames_age_ms: deque[float] = deque(maxlen=5000)
        self.frames_not_host_time = 0
        self._describe_ms: deque[float] = deque(maxlen=500)
        self._ahead_ms: deque[float] = deque(maxlen=500)
        self._cut_ahead_ms: deque[float] = deque(maxlen=500)
        self._sample_types: tuple[np.dtype, np.dtype] | None = None  # of the first frames: the rehearsal's
        self.rehearsal_ms: float | None = None  # how long the rehearsal of the describing path took (_rehearse)
        self._cut_ms: deque[float] = deque(maxlen=500)
        self._cell_part = {c.id: p.name for p in self.robot.body_parts for c in p.cells}
        # a message's runs checked at once against the served cells and their batch numbers
        self._runs = RunChecker({p.name: [c.id for c in p.cells] for p in self.robot.body_parts})
        self.diagnostics = Diagnostics(self, params["diagnostics_period_s"])
        self.diagnostics.add("windows", self._status)
        params.finish()
        self._release_timer = self.create_timer(0.05, self._release_held, clock=steady_clock())
        self._warm_thread = threading.Thread(target=self._warm_up, daemon=True, name="kernel-warm-up")
        self._warm_thread.start()
        # A cached kernel loads in about a second: wait for it (frames meanwhile queue on the subscriptions,
        # which exist already), so a graph starting together finds the node as ready as before.  A
        # compilation takes longer: then the node runs on and holds its first windows until the kernel is in.
        self.kernel_ready.wait(self.WARM_UP_WAIT_S)
        self.get_logger().info(
            f"robot {self.robot.name}: {len(self.robot.body_parts)} body parts "
            f"({', '.join(p.name for p in self.robot.body_parts)}), {self.windower.mode} windows, "
            f"{self.layout} descriptors of feature groups {selection_name(self.groups)} on {self.pub.topic_name}"
            + (f", mean over {self.block_s:g} s blocks" if self.block_s else ""))

    def _groups(self) -> tuple[str, ...]:
        """``descriptor.groups`` (or the legacy ``descriptor.channels``), checked against every served cell type.

        Raises
        ------
        ConfigError
            At start-up, naming the group and the cell type, for a group a
            served cell type cannot feed; for both parameters changed at once.
        """
        d = self.robot.descriptor
        channels = self.params["descriptor.channels"]
        groups = tuple(self.params["descriptor.groups"])
        if channels != d.channels and channels:
            if groups != d.groups:
                raise ConfigError("set descriptor.groups or the legacy descriptor.channels, not both",
                                  key="descriptor.groups")
            groups = groups_of_channels(channels)
        for name in dict.fromkeys(p.cell_type for p in self.robot.body_parts):
            check_groups(self.robot.cell_types[name], groups, key="descriptor.groups")
        return groups

    #: longest wait for the kernel in the constructor before running on with held windows [s]
    WARM_UP_WAIT_S = 5.0

    # ------------------------------------------------------- parameters
    def _retune_windower(self, values, changed):
        """``ros2 param set`` of window/contact settings: checked together now, applied by the returned function."""
        settings = _windower_settings(values)
        self.windower.retune(dry_run=True, **settings)  # ConfigError: refused, nothing changed

        def apply() -> None:
            self.windower.retune(**settings)
            self.force_threshold_n = self.windower.onset_n

        return apply

    # ------------------------------------------------------------ input
    def _seen(self, part: str, frames: int) -> None:
        self._rates[part].add(frames)
        self._last_seen[part] = time.monotonic()

    def _on_frames(self, msg) -> None:
        """Frames callback: this message and every one already waiting, into the windower, one poll.

        A body part's ``SkinPartFrames`` goes in as one :class:`PartChunk`
        (:meth:`Windower.add_part`: a few array operations whatever its
        number of cells); BioTac batches (one cell each) go in together
        through :meth:`Windower.add_many`.  Messages keep their order.
        """
        items: list[tuple[int, CellChunk]] = []
        took = False
        now_ns = time.time_ns()
        for sub_msg, handle in self._drain(msg):
            got = handle(sub_msg)
            if self._sample_types is None and len(got):
                first = got if isinstance(got, PartChunk) else got[0][1]
                self._sample_types = (first.vibration.dtype, first.deformation.dtype)
            if isinstance(got, PartChunk):
                took |= self._buffer(items)
                items = []
                took |= self._buffer(got)
            else:
                items += got
            newest = _newest_sample_ns(sub_msg)
            if newest is not None:
                age_ms = host_age_ms(now_ns, newest)
                if age_ms is not None:
                    self._frames_age_ms.append(age_ms)
                else:  # device stamps (a simulator's scene time, a bridge's own clock): no age on the host clock
                    self.frames_not_host_time += 1
        took |= self._buffer(items)
        if took:
            started = time.perf_counter()
            windows = self.windower.poll()
            if windows:
                self._cut_ms.append(1e3 * (time.perf_counter() - started))
            self._emit(windows)
            if self.rehearsal_ms is not None and not self.held_windows:
                started = time.perf_counter()
                if self.ahead is not None and self.ahead.offer(self.windower):
                    self._ahead_ms.append(1e3 * (time.perf_counter() - started))
                elif self.cut_ahead and self.windower.cut_fixed_ahead():
                    self._cut_ahead_ms.append(1e3 * (time.perf_counter() - started))
        if self.rehearsal_ms is None and self._sample_types is not None and self.kernel_ready.is_set():
            self._rehearse(*self._sample_types)

    def _rehearse(self, vibration_dtype: np.dtype, deformation_dtype: np.dtype) -> None:
        """Describe a window of noise in the live data's sample types once, here, before the first real one.

        The first description on a thread pages in its buffers, plans its
        transforms and loads the compiled code for the data's types: the
        NAO's first window took 33-62 ms to describe instead of 10.  The
        rehearsal (:func:`~..core.windowing.rehearsal_window`, the node's
        window length and feature groups) takes that cost at the first
        frames instead, which queue meanwhile.  Its descriptor is not
        published; its layout is (:meth:`_announce_layout`).
        """
        started = time.perf_counter()
        cut_ms = 0.0
        try:
            window = rehearsal_window(self.robot, self.windower.length_ns / 1e9, vibration_dtype, deformation_dtype)
            cut_ms = 1e3 * (time.perf_counter() - started)
            desc = self._describe(window)
            # the labels depend on the robot and the parameters only: a classifier has them before the first
            # descriptor (it holds a descriptor until its layout comes)
            self._announce_layout(desc)
        except (ConfigError, SignalError) as exc:  # a warm-up only: the real windows report their own faults
            self.get_logger().warning(f"describing path not rehearsed: {exc}")
        self.rehearsal_ms = 1e3 * (time.perf_counter() - started)
        self.get_logger().info(f"describing path rehearsed in {self.rehearsal_ms:.0f} ms (window of noise made "
                               f"and cut in {cut_ms:.0f} ms)")

    def _buffer(self, data: list[tuple[int, CellChunk]] | PartChunk) -> bool:
        """Hand a message's chunks (one per cell, or a body part's runs) to the windower; False if there are none."""
        if not len(data):
            return False
        try:
            if isinstance(data, PartChunk):
                self.windower.add_part(data)
            else:
                self.windower.add_many(data)
        except SignalError as exc:  # the chunks before the offending one stay buffered
            self.faults["malformed"] += 1
            self.get_logger().warning(f"frames not buffered: {exc}", throttle_duration_sec=5.0)
        return True

    def _drain(self, first) -> list[tuple[object, Callable]]:
        """``first`` and the messages waiting on the frames subscriptions (at most ``frames.drain_max``)."""
        out, taken = take_frames(first, self.subs, self._handlers, self._by_type, self.params["frames.drain_max"],
                                 self.faults, self.get_logger())
        self.frames_taken += taken
        self.batches += 1
        self.largest_batch = max(self.largest_batch, taken)
        return out

    def _on_biotac(self, msg) -> list[tuple[int, CellChunk]]:
        part = msg.body_part
        cid = self._cells_by_name.get((part, msg.sensor_name))
        if cid is None:
            self.faults["unknown_sensor"] += 1
            self.get_logger().warning(f"frames from unknown sensor {msg.sensor_name!r} on body part {part!r}; "
                                   "dropped (not in the robot description)",
                                   throttle_duration_sec=5.0)
            return []
        try:
            chunk = biotac_msg_to_chunk(msg, self._extra[part])
        except SignalError as exc:
            self.faults["malformed"] += 1
            self.get_logger().warning(f"malformed BioTacFrameBatch from {msg.sensor_name}: {exc}",
                                   throttle_duration_sec=5.0)
            return []
        if msg.pdc_tare_counts != 0.0:
            self._untared.discard(msg.sensor_name)
        elif msg.sensor_name not in self._untared:
            self._untared.add(msg.sensor_name)
            self.get_logger().warning(f"{msg.sensor_name} was never tared: its force is PDC counts times the scale "
                                   "and may read as permanent contact (call the driver's ~/tare)")
        self._sequence(msg.sensor_name, int(msg.first_frame_sequence), int(msg.frame_count))
        self.faults["bad_words"] += int(msg.bad_words)
        self._seen(part, int(msg.frame_count))
        return [(cid, chunk)]

    def _on_skin_part(self, msg) -> PartChunk | list:
        """One ``SkinPartFrames`` as one chunk; runs of unknown or misplaced cells are dropped and counted.

        The checks run over the message's runs at once: each cell's batch
        number against the one it sent before (``lost_cell_batches``: a
        cell's batches that never arrived; ``sequence_restart``: a driver
        that started again), its ``bad_frames``.
        """
        part = msg.body_part
        try:
            chunk = skin_part_msg_to_part_chunk(msg, self._extra.get(part, ()))
        except SignalError as exc:
            self.faults["malformed"] += 1
            self.get_logger().warning(f"malformed SkinPartFrames of body part {part!r}: {exc}",
                                      throttle_duration_sec=5.0)
            return []
        if not chunk.cell_ids.size:
            return []
        got = self._runs.check(part, chunk.cell_ids, _as_array(msg.sequence, np.uint32),
                               _as_array(msg.bad_frames, np.uint32))
        if got.unknown:
            self.faults["unknown_cell"] += got.unknown
            self.get_logger().warning(f"frames from cell {got.first_unknown} which is not in the served body parts; "
                                      "dropped", throttle_duration_sec=5.0)
        if got.other_part:
            cid = got.first_other_part
            self.faults["body_part_mismatch"] += got.other_part
            self.get_logger().warning(f"cell {cid} sent on body part {part!r} but the robot description puts it on "
                                      f"{self._cell_part[cid]!r}; dropped", throttle_duration_sec=5.0)
        n_mine = chunk.cell_ids.size - got.unknown - got.other_part
        if not n_mine:
            return []
        self.faults["lost_cell_batches"] += got.lost
        self.faults["sequence_restart"] += got.restarts
        self.faults["bad_frames"] += got.bad_frames
        self._seen(part, n_mine)
        return chunk.take(got.mine)

    def _sequence(self, key: str, first: int, count: int) -> None:
        event, lost = self._sequences.track_run(key, first, max(count, 1))
        self.faults["lost_frames"] += lost
        if event == SequenceEvent.RESET:
            self.faults["sequence_restart"] += 1

    # ----------------------------------------------------------- output
    def _warm_up(self) -> None:
        """Kernel warm-up thread: load (or compile) the descriptor kernel, then let the held windows go."""
        try:
            info = warm_up()
        except Exception as exc:  # noqa: BLE001 - the reference serves; say why
            info = {"accelerator": "reference", "import_s": 0.0, "first_call_s": 0.0, "error": repr(exc)}
        self.kernel_info = info
        self.get_logger().info(f"descriptor kernel: {info['accelerator']} "
                               f"(ready in {info['import_s'] + info['first_call_s']:.2f} s"
                               f"{', ' + str(info['error']) if info.get('error') else ''})")
        self.kernel_ready.set()

    def _emit(self, windows: list[Window]) -> None:
        """Publish finished windows in order; hold them while the kernel warms up."""
        if not self.kernel_ready.is_set():
            self.held_windows.extend(windows)
            self.windows_held_at_start += len(windows)
            return
        if self.held_windows:
            self._release_held()
        for w in windows:
            self._publish(w)

    def _release_held(self) -> None:
        """Timer: once the kernel is ready, describe the windows held meanwhile (then stop the timer)."""
        if not self.kernel_ready.is_set():
            return
        held, self.held_windows = self.held_windows, []
        if held:
            self.get_logger().info(f"kernel ready: describing the {len(held)} windows that closed while it warmed up")
        for w in held:
            self._publish(w)
        if self._release_timer is not None:
            self._release_timer.cancel()
            self.destroy_timer(self._release_timer)
            self._release_timer = None

    def _publish(self, window: Window) -> None:
        started = time.perf_counter()
        try:
            made = self.ahead.take(window) if self.ahead is not None else None
            desc, msg = made if made is not None else self._descriptor_msg(window)
        except SignalError as exc:
            self.faults["describe_failed"] += 1
            self.get_logger().error(f"window {window.start_ns}..{window.end_ns}: {exc}")
            return
        self.pub.publish(msg)
        self._describe_ms.append(1e3 * (time.perf_counter() - started))
        self.descriptors_published += 1
        self.last_quality = {bp.name: bp.quality for bp in desc.body_parts}
        if window.mode == "exploration":
            touching = [bp.name for bp in desc.body_parts if bp.contact]
            self.get_logger().info(
                f"exploration {msg.exploration_id}: {(window.end_ns - window.start_ns) / 1e9:.2f} s, "
                f"contact {', '.join(touching) or 'none'}")

    def _descriptor_msg(self, window: Window) -> tuple[RobotDescriptor, object]:
        """The descriptor of ``window`` and its ``Descriptor`` message (its layout announced first)."""
        desc = self._describe(window)
        eid = window.exploration_id * self.id_stride + self.id_offset if window.exploration_id else 0
        layout = self._announce_layout(desc)
        return desc, descriptor_to_msg(desc, window, frame_id=self.params["frame_id"], exploration_id=eid,
                                       layout=layout)

    def _describe(self, window: Window) -> RobotDescriptor:
        """This node's descriptor of ``window``: its feature groups, layout, blocks and contact threshold."""
        return describe_blocks(self.robot, window.cells, block_s=self.block_s, block_hop_s=self.block_hop_s,
                               layout=self.layout, groups=self.groups, force_threshold_n=self.force_threshold_n,
                               stacks=window.stacks)

    def _announce_layout(self, desc: RobotDescriptor) -> str:
        """The id of ``desc``'s labels; their ``DescriptorLayout`` is published before the first descriptor that
        names it (latched), once per layout."""
        layout = self._layout_ids.get(desc.labels)
        if layout is None:  # hashing a NAO layout's 917 labels takes 0.2 ms; it changes only with the parameters
            layout = self._layout_ids[desc.labels] = layout_id(desc.labels)
        if layout not in self.layouts_published:
            self.layout_pub.publish(descriptor_layout_to_msg(desc, frame_id=self.params["frame_id"],
                                                             stamp_ns=self.get_clock().now().nanoseconds))
            self.layouts_published.add(layout)
        return layout

    def _status(self) -> Status:
        faults = dict(self.faults)
        faults.update({f"windower_{k}": v for k, v in self.windower.faults.items()})
        values: dict = {"descriptors_published": self.descriptors_published,
                        "kernel": self.kernel_info["accelerator"] if self.kernel_info else "warming up",
                        "windows_held_at_start": self.windows_held_at_start,
                        "rehearsal_ms": -1.0 if self.rehearsal_ms is None else round(self.rehearsal_ms, 1),
                        "messages_received": self.frames_taken,
                        "frames_per_callback": self.frames_taken / self.batches if self.batches else 0.0,
                        "frames_messages_taken": self.frames_taken,
                        "frames_serialized": self.frames_serialized,
                        "windower_buffer_mb": round(self.windower.buffer_bytes / 2**20, 3),
                        "largest_frames_batch": self.largest_batch,
                        "frames_not_host_time": self.frames_not_host_time,
                        "explorations": self.windower.exploration_id, "in_contact": self.windower.in_contact}
        if self.ahead is not None:
            values.update({f"described_ahead_{k}": v for k, v in self.ahead.counts().items()})
        if self.cut_ahead:
            values.update({f"cut_ahead_{k}": self.windower.heads[k] for k in ("used", "recut")})
        for name, samples in (("frames_age", self._frames_age_ms), ("cut", self._cut_ms), ("describe", self._describe_ms),
                              ("describe_ahead", self._ahead_ms), ("cut_ahead", self._cut_ahead_ms)):
            if samples:
                arr = np.fromiter(samples, np.float64, len(samples))
                values.update({f"{name}_ms_p50": float(np.median(arr)), f"{name}_ms_p95": float(np.percentile(arr, 95)),
                               f"{name}_ms_max": float(arr.max()), f"{name}_n": arr.size})
        now = time.monotonic()
        silent = []
        for part, meter in self._rates.items():
            values[f"{part}_rate_hz"] = meter.rate_hz  # BioTac frames/s, skin cell batches/s
            # the subscription's own count: what a player waits for (frames_matched)
            publishers = values[_publishers_key(part)] = self._part_sub[part].get_publisher_count()
            seen = self._last_seen.get(part)
            if seen is None or now - seen > self.params["diagnostics.silent_after_s"]:
                # a silent part with matched publishers is a sender that stopped or a delivery that did
                # (docs/nodes.md: a node stopped for seconds); with none, nothing publishes the topic
                if seen is not None:
                    values[f"{part}_silent_s"] = round(now - seen, 1)
                silent.append(f"{part} ({_publishers(publishers)})")
        values.update({f"fault_{k}": v for k, v in sorted(faults.items())})
        values.update({f"quality_{k}": v for k, v in self.last_quality.items()})
        bad = {k: v for k, v in faults.items() if v and k != "windower_exploration_too_short"}
        if self._untared:
            values["untared_sensors"] = ", ".join(sorted(self._untared))
        if silent:
            return Status("warn", f"no frames from {', '.join(silent)}", values)
        if self._untared:
            return Status("warn", f"never tared: {values['untared_sensors']}", values)
        if bad:
            return Status("warn", "faults: " + ", ".join(f"{k}={v}" for k, v in sorted(bad.items())), values)
        return Status("ok", f"{self.descriptors_published} descriptors", values)



def _windower_settings(values) -> dict[str, float]:
    """The schema's ``windower`` parameters as :class:`Windower` keywords (``window.length_s`` -> ``length_s``)."""
    return {name.rsplit(".", 1)[1]: values[name] for name in WINDOW_NODE.apply_groups()["windower"]}


def _publishers_key(part: str) -> str:
    return f"{part}_publishers"


def frames_matched(values: Mapping[str, str], part: str) -> bool:
    """Whether a window node's diagnostics show its subscription to ``part``'s frames matched to a publisher.

    Discovery matches each side of a topic on its own: a publisher can count
    the window node's subscription before that subscription knows the
    publisher, and a best-effort, volatile subscription drops what a
    publisher it does not know yet sends.  A player that must not lose its
    first frames waits for this, the reader's side, as well as for its own
    ``get_subscription_count()``.

    Parameters
    ----------
    values : mapping of str to str
        The ``window_node: windows`` status's key-value pairs, as published.
    part : str
        A body part the node serves.

    Returns
    -------
    bool
        True when the status reports at least one matched publisher of the
        part's frames.
    """
    try:
        return int(values.get(_publishers_key(part), "0")) > 0
    except ValueError:
        return False


def _publishers(count: int) -> str:
    """``"no publisher"``, ``"1 publisher matched"``, ``"3 publishers matched"``."""
    if count == 0:
        return "no publisher"
    return f"{count} publisher{'s' if count > 1 else ''} matched"


def _newest_sample_ns(msg) -> int | None:
    """Stamp of a frames message's newest vibration sample [ns] (None when it has none)."""
    offsets = getattr(msg, "accel_offset_ns", None)
    if offsets is None:
        offsets = msg.pac_offset_ns
    if not len(offsets):
        return None
    # numpy's max: Python's over a message's arrays made a number object per sample (18 us for a NAO body part)
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec + int(_as_array(offsets, np.int64).max())


def _as_array(values, dtype) -> np.ndarray:
    """An rclpy array field (``array.array``) or a rosbags one (ndarray) as a numpy array (no copy)."""
    if isinstance(values, np.ndarray):
        return values
    return np.frombuffer(values, dtype=dtype) if len(values) else np.zeros(0, dtype)


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of the ``window_node`` executable.

    The process's allocator keeps the memory of a window it freed for the next one
    (:func:`~.common.keep_freed_memory`): without, every window's arrays came from fresh pages, which took
    the cut 9 ms in the node instead of 5 (``tactile bench --latency``, the NAO)."""
    keep_freed_memory()
    return run_node(WindowNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
