"""``skin_driver``: multimodal skin cells -> ``SkinPartFrames`` (transport -> codec -> message).

Transports (parameter ``transport``):

* ``can``       -- python-can (``can.interface``, ``can.channel``; ``virtual`` in
  tests), our CAN layout (``docs/protocols.md``);
* ``serial``    -- pyserial (``serial.port``; ``loop://`` in tests), our serial framing;
* ``loopback``  -- the serial framing over an in-process loopback (tests);
* ``simulated`` -- a scene (``sim.scene``) played as CAN frames by the simulator.

Cell ids are mapped to body parts by the robot description.  Frames of a
cell id that is not in the description are counted per id and reported in
``/diagnostics`` (never dropped silently, never guessed onto a body part);
cells of body parts this node does not serve are counted separately.

Every cell's samples are cut every ``batch_s`` of sample time (accelerometer
x, y, z, the three force sensors, proximity, the last temperature), and the
batches of all cells of a body part go out together as one
``SkinPartFrames`` on the body part's frames topic
(:class:`~tactile_descriptors_ros.streams.skin_parts.PartGatherer`: once
every cell that is sending has its batch, or when one cell is a batch ahead
of a late or silent one, or after ``2 * batch_s`` of waiting).  Sample times (``stamp_source``): ``clock``
runs a sample clock per cell and modality (the node clock at its first
sample plus sequence number times the nominal period, so a lost frame leaves
a gap in time), re-anchored when it drifts from the node clock by more than
``resync_s``; ``device`` uses the bus time stamps (CAN adapters' receive
time; the simulator's sample time).

``~/tare`` sets the force baselines to their resting level
(:func:`~..core.tare.resting_level`) over the last ``tare.window_s`` (refused while a cell reads a force at
or above the contact threshold).  Lifecycle as in
:mod:`~tactile_descriptors_ros.nodes.biotac_driver`.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Sequence

import numpy as np
from rclpy.lifecycle import TransitionCallbackReturn

from ..codecs.cdr import load_compiled as load_cdr
from ..codecs.cdr import write_skin_part
from ..codecs.skin import ACCEL_MPS2_PER_COUNT, NOMINAL_RATE_HZ, Modality, SkinSampleBatch
from ..codecs.skin_can import SkinCanDecoder, load_compiled
from ..codecs.skin_serial import SkinSerialDecoder
from ..errors import ConfigError
from ..params.skin_driver import SKIN_DRIVER
from ..streams.skin import MAX_BACKLOG_S, READ_FRAMES, RECENT_FORCE, CellState, SkinStream, drain_frames
from ..streams.skin import load_compiled as load_stamping
from ..streams.skin_parts import SkinPartFrames
from .common import RateMeter, Status, run_node
from .conversions import skin_part_to_msg
from .driver_base import DriverBase

__all__ = ["SkinDriver", "main"]

class SkinDriver(DriverBase):
    """The skin driver; ``kwargs`` go to :class:`rclpy.lifecycle.LifecycleNode`.

    ``transport_factory(node) -> Transport`` replaces the ``transport`` parameter's backend (tests).
    """

    reader_thread_name = "skin-reader"
    close_on_failed_configure = False

    def __init__(self, node_name: str = "skin_driver", transport_factory=None, **kwargs) -> None:
        super().__init__(node_name, transport_factory, **kwargs)
        self.full_robot, self.robot = self._declare_parameters(SKIN_DRIVER, "skin", "nao", "skin-cell")
        params = self.params
        self.batch_s = params["batch_s"]
        self.tp = {
            "can": {"interface": params["can.interface"], "channel": params["can.channel"]},
            "serial": {"port": params["serial.port"], "baudrate": params["serial.baudrate"]},
        }
        if params["can.bitrate"]:
            self.tp["can"]["bitrate"] = params["can.bitrate"]
        self.sim_wire = params["sim.wire"]
        # each message's CDR bytes written in one compiled pass (codecs/cdr.py), published as they are
        self.frames_serialized = params["frames.serialized"] and load_cdr()
        self.sim_loop = params["sim.loop"]
        self.is_can = self.transport_name == "can" or (self.transport_name == "simulated" and self.sim_wire == "can")
        # the compiled decoding and stamping, loaded before the bus opens: its frames would queue meanwhile, and a
        # first read more than MAX_BACKLOG_S behind sheds the oldest
        if self.is_can:
            load_compiled()
        load_stamping()

        ct = self.robot.cell_types[self.robot.body_parts[0].cell_type]
        self.accel_rate_hz = ct.vibration.rate_hz
        self.force_rate_hz = ct.deformation.rate_hz
        self.accel_scale = ct.vibration.si_per_count if ct.vibration.unit == "m/s^2" else ACCEL_MPS2_PER_COUNT
        self.force_n_per_count = ct.force.n_per_count
        self.served = {c.id: p.name for p in self.robot.body_parts for c in p.cells}
        self.frame_ids = {c.id: str(c.extra.get("frame_id", f"skin_cell_{c.id}")) for p in self.robot.body_parts
                          for c in p.cells}
        self.known = set(self.full_robot.cell_index())
        # header.frame_id of a body part's messages: its link when the robot has a geometry, else its name
        geo = self.robot.geometry
        self.part_frames = {p.name: geo.part_links[p.name] if geo is not None else p.name for p in self.robot.body_parts}
        # a read keeps at most MAX_BACKLOG_S of the bus's frames: every known cell's accelerometer, force,
        # proximity (at the force rate) and temperature frames
        per_cell_hz = self.accel_rate_hz + 2 * self.force_rate_hz + NOMINAL_RATE_HZ[Modality.TEMPERATURE]
        self.max_read_frames = max(READ_FRAMES, int(len(self.known) * per_cell_hz * MAX_BACKLOG_S))
        self.decoder = None
        self.stream: SkinStream | None = None
        self._rates: dict[str, RateMeter] = {}  # samples per body part
        self._arrival_ns: int | None = None
        self.part_publishers: dict[str, object] = {}
        self.part_messages: dict[str, int] = {p.name: 0 for p in self.robot.body_parts}
        self._start([("bus", self._bus_status)]
                    + [(part.name, lambda p=part: self._part_status(p)) for part in self.robot.body_parts])

    def _tare_history(self) -> tuple[float, str]:
        return RECENT_FORCE / self.force_rate_hz, (f"{RECENT_FORCE} force samples at the robot's "
                                                   f"{self.force_rate_hz:g} Hz")

    # ------------------------------------------------------------- lifecycle
    def _simulated_source(self):
        from ..sim.sources import LoopedSkinCanSource, SkinCanSource, SkinSerialSource, load_scene_for

        scene = load_scene_for(self.sim_scene, self.full_robot.name)
        if self.sim_loop:
            if self.sim_wire != "can":
                raise ConfigError("sim.loop plays CAN frames: set sim.wire to can", key="sim.loop")
            return LoopedSkinCanSource(scene, speed=self.sim_speed, chunk_s=2.0)
        source_cls = SkinCanSource if self.sim_wire == "can" else SkinSerialSource
        return source_cls(scene, speed=self.sim_speed, chunk_s=2.0)

    def _configured(self) -> TransitionCallbackReturn:
        self.stream = SkinStream({cid: (part, self.frame_ids[cid]) for cid, part in self.served.items()},
                                 self.accel_rate_hz, self.force_rate_hz, self.batch_s, self.stamp_source,
                                 self.resync_s, self.tare_on_start_s, lambda: self.get_clock().now().nanoseconds,
                                 self.faults, self._log_stream,
                                 scales=(self.accel_scale, self.force_n_per_count, 0.0))
        rates = self.stream.rates_hz()
        self.decoder = SkinCanDecoder(known_cell_ids=self.known, rates_hz=rates) if self.is_can else \
            SkinSerialDecoder(known_cell_ids=self.known, rates_hz=rates)
        self._rates = {p.name: RateMeter() for p in self.robot.body_parts}
        self._part_index = np.full(0x10000, -1, np.int64)
        for k, p in enumerate(self.robot.body_parts):
            for c in p.cells:
                self._part_index[c.id] = k
        self._last_data = time.monotonic()
        from tactile_descriptors_msgs.msg import SkinPartFrames

        for part in self.robot.body_parts:
            topic = self.topic_fmt.format(body_part=part.name)
            self.part_publishers[part.name] = self.create_lifecycle_publisher(SkinPartFrames, topic, self.qos_frames)
        self.get_logger().info(f"{self.transport_name} transport open: {len(self.cells)} cells on "
                               f"{len(self.robot.body_parts)} body parts")
        return TransitionCallbackReturn.SUCCESS

    def _destroy_publishers(self) -> None:
        for pub in self.part_publishers.values():
            self.destroy_lifecycle_publisher(pub)
        self.part_publishers.clear()

    # ---------------------------------------------------------------- reading
    def _read(self) -> SkinSampleBatch:
        if self.is_can:  # every queued frame at once (the newest of a long backlog), decoded with array operations
            frames, shed = drain_frames(self.transport, 0.05, limit=self.max_read_frames)
            if shed:
                self.faults["frames_shed"] += shed
            self._arrival_ns = time.time_ns()  # python-can's clock, for frames without a bus time
            return self.decoder.decode_frames(frames, self._arrival_ns)
        data = self.transport.read(1 << 20, 0.05)
        self._arrival_ns = time.time_ns()
        if not data:
            return SkinSampleBatch.empty()
        return self.decoder.feed_batch(data, self._arrival_ns)

    def _consume(self, batch: SkinSampleBatch) -> None:
        now = time.monotonic()
        with self._lock:
            if len(batch):
                self._last_data = now
                due = self.stream.add_parts(batch, self._arrival_ns)
                k = self._part_index[batch.cell_id]
                counts = np.bincount(k[k >= 0], minlength=len(self.robot.body_parts))
                for part, n in zip(self.robot.body_parts, counts.tolist()):
                    if n:
                        self._rates[part.name].add(n)
            elif self.stream.pending() and now - self._last_data >= 2 * self.batch_s:
                due = self.stream.flush()  # the bus went quiet: the last batches go out
            else:
                due = []
        for part in due:
            self._publish(part)

    def _reopened(self, gap_s: float) -> None:
        with self._lock:
            self.stream.resume()

    def _publish(self, part: SkinPartFrames) -> None:
        frame_id = self.part_frames[part.body_part]  # the body part's link in the TF tree
        msg = write_skin_part(part, frame_id) if self.frames_serialized else None
        if msg is None:
            msg = skin_part_to_msg(part)
            msg.header.frame_id = frame_id
        self.part_publishers[part.body_part].publish(msg)
        self.part_messages[part.body_part] += 1

    def _log_stream(self, level: str, text: str) -> None:
        if level == "info":
            self.get_logger().info(text)
        else:
            self.get_logger().warning(text, throttle_duration_sec=5.0)

    @property
    def cells(self) -> dict[int, CellState]:
        """The served cells' state (empty before configure)."""
        return self.stream.cells if self.stream is not None else {}

    @property
    def other_part_frames(self) -> Counter:
        """Frames per cell id of configured cells of body parts this node does not serve."""
        return self.stream.other_part_frames if self.stream is not None else Counter()

    # ------------------------------------------------------------------- tare
    def _srv_tare(self, request, response):
        with self._lock:
            now = time.monotonic()
            # cells that sent frames but none lately (a cell that never sent fails its own tare below)
            stale = [c.cell_id for c in self.cells.values()
                     if c.last_monotonic is not None and now - c.last_monotonic > self.stale_after_s]
            if stale:
                why = "the simulated scene has ended" if self.scene_ended() else "unplugged or stopped?"
                response.success = False
                response.message = (f"refused: stale frames from {len(stale)} of {len(self.cells)} cells (e.g. cell "
                                     f"{stale[0]}: nothing in the last {self.stale_after_s} s; {why}); a tare needs "
                                     "current frames")
                return response
            threshold_n = self.params["contact.force_threshold_n"]
            touching = [(c.cell_id, f) for c in self.cells.values()
                        if (f := self.stream.force_n(c, self.force_n_per_count)) is not None and f >= threshold_n]
            if touching:
                response.success = False
                response.message = (f"refused: {len(touching)} cells in contact (e.g. cell {touching[0][0]}: "
                                    f"{touching[0][1]:.2f} N >= {threshold_n} N)")
                return response
            window_s = self.params["tare.window_s"]
            results = {c.cell_id: self.stream.tare_cell(c, window_s) for c in self.cells.values()}
        failed = {cid: why for cid, (ok, why) in results.items() if not ok}
        response.success = not failed
        response.message = (f"tared {len(results) - len(failed)} cells" +
                            (f"; failed: {', '.join(f'{c} ({w})' for c, w in list(failed.items())[:5])}"
                             if failed else ""))
        return response

    # ------------------------------------------------------------ diagnostics
    def _bus_status(self) -> Status:
        values = self._transport_values({"frames_serialized": self.frames_serialized})
        unknown: dict = {}
        if self.decoder is not None:
            if isinstance(self.decoder, SkinCanDecoder):
                stats = self.decoder.stats.as_dict()
                unknown = stats.pop("unknown_cell_ids")
            else:
                stats = self.decoder.stats.as_dict()
                stats.update({f"rejected_{k}": v for k, v in self.decoder.reject_reasons.items()})
                unknown = dict(self.decoder.unknown_cell_ids)
            values.update({f"bus_{k}": v for k, v in stats.items()})
        if unknown:
            values["unknown_cell_ids"] = ", ".join(f"{c} ({n} frames)" for c, n in sorted(unknown.items()))
        if self.other_part_frames:
            values["cells_of_unserved_body_parts"] = len(self.other_part_frames)
        error = self._transport_error(values)
        if error is not None:
            return error
        if unknown:
            return Status("warn", f"frames from {len(unknown)} cell ids not in the robot description: "
                                  f"{', '.join(map(str, sorted(unknown)[:10]))}", values)
        return Status("ok", "open", values)

    def _part_status(self, part) -> Status:
        cells = [self.cells.get(c.id) for c in part.cells]
        now = time.monotonic()
        silent = [c.id for c, st in zip(part.cells, cells) if st is None or st.last_monotonic is None
                  or now - st.last_monotonic > self.stale_after_s]
        live = [st for st in cells if st is not None]
        meter = self._rates.get(part.name)
        values = {"cells": len(part.cells), "silent_cells": len(silent),
                  "samples_per_s": meter.rate_hz if meter is not None else 0.0,
                  "samples": meter.total if meter is not None else 0,
                  "messages": self.part_messages.get(part.name, 0),
                  "cell_batches": sum(st.messages for st in live), "lost_frames": sum(st.lost for st in live),
                  "tared_cells": sum(st.tared for st in live)}
        if silent and self.scene_ended():
            return Status("stale", "scene ended: the simulated scene was played to its end, no more frames", values)
        if silent:
            values["silent_cell_ids"] = ", ".join(map(str, silent[:20]))
            level = "error" if len(silent) == len(part.cells) else "warn"
            return Status(level, f"{len(silent)} of {len(part.cells)} cells silent", values)
        return Status("ok", f"{len(part.cells)} cells", values)


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of the ``skin_driver`` executable."""
    return run_node(SkinDriver, args)


if __name__ == "__main__":
    raise SystemExit(main())
