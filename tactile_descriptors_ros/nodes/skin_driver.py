"""``skin_driver``: multimodal skin cells -> ``SkinCellFrame`` (transport -> codec -> message).

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

Every cell's samples are published every ``batch_s`` of sample time as one
``SkinCellFrame``: accelerometer (x, y, z), the three force sensors,
proximity, the last temperature.  Sample times (``stamp_source``): ``clock``
runs a sample clock per cell and modality (the node clock at its first
sample plus sequence number times the nominal period, so a lost frame leaves
a gap in time), re-anchored when it drifts from the node clock by more than
``resync_s``; ``device`` uses the bus time stamps (CAN adapters' receive
time; the simulator's sample time).

``~/tare`` zeroes the force baselines (refused while a cell reads a force at
or above the contact threshold).  Lifecycle as in
:mod:`~tactile_descriptors_ros.nodes.biotac_driver`.
"""

from __future__ import annotations

import time
from collections import Counter, deque
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from rclpy.lifecycle import TransitionCallbackReturn

from ..codecs.skin import ACCEL_MPS2_PER_COUNT, NOMINAL_RATE_HZ, Modality
from ..codecs.skin_can import SkinCanDecoder
from ..codecs.skin_serial import SkinSerialDecoder
from .biotac_driver import Unwrapper
from .common import RateMeter, Status, declare, run_node
from .conversions import SkinFrame, skin_frame_to_msg
from .driver_base import DriverBase
from .qos import QosDefaults, declare_qos
from .window_node import FRAMES_TOPIC

__all__ = ["SkinDriver", "main"]

TRANSPORTS = ("can", "serial", "simulated", "loopback")


@dataclass
class _Cell:
    cell_id: int
    body_part: str
    frame_id: str
    accel: list = field(default_factory=list)  # (t_ns, (x, y, z))
    force: list = field(default_factory=list)  # (t_ns, (f0, f1, f2))
    proximity: list = field(default_factory=list)  # (t_ns, p)
    temperature_c: float = float("nan")
    recent_force: deque = field(default_factory=lambda: deque(maxlen=500))  # (t_ns, mean counts, (f0,f1,f2))
    tare: np.ndarray = field(default_factory=lambda: np.zeros(3))
    tared: bool = False
    first_t_ns: int | None = None
    sequence: int = 0
    lost: int = 0
    lost_since_msg: int = 0
    samples: int = 0
    messages: int = 0
    last_monotonic: float | None = None
    rate: RateMeter = field(default_factory=RateMeter)
    seq: dict = field(default_factory=dict)  # modality -> (Unwrapper, first unwrapped, anchor_ns)


class SkinDriver(DriverBase):
    """The skin driver; ``kwargs`` go to :class:`rclpy.lifecycle.LifecycleNode`.

    ``transport_factory(node) -> Transport`` replaces the ``transport`` parameter's backend (tests).
    """

    reader_thread_name = "skin-reader"
    close_on_failed_configure = False

    def __init__(self, node_name: str = "skin_driver", transport_factory=None, **kwargs) -> None:
        super().__init__(node_name, transport_factory, **kwargs)
        self.full_robot, self.robot = self._declare_robot("skin", "nao", "skin-cell")
        self.transport_name = declare(self, "transport", "can", "device transport", choices=TRANSPORTS)
        self.batch_s = declare(self, "batch_s", 0.05, "sample time per message and cell [s]", minimum=0.001)
        self._declare_stamps_and_tare(self.full_robot.contact.force_threshold_n,
                                      "force baseline from the first samples [s]", "samples averaged by ~/tare [s]")
        self.topic_fmt = declare(self, "frames_topic", FRAMES_TOPIC, "frames topic of a body part ({body_part})")
        self.tp = {
            "can": {"interface": declare(self, "can.interface", "socketcan", "python-can interface"),
                    "channel": declare(self, "can.channel", "can0", "python-can channel")},
            "serial": {"port": declare(self, "serial.port", "/dev/ttyUSB0", "serial port or pyserial URL"),
                       "baudrate": declare(self, "serial.baudrate", 3000000, "baud rate", minimum=1)},
        }
        bitrate = declare(self, "can.bitrate", 0, "CAN bitrate (0 = leave as configured)", minimum=0)
        if bitrate:
            self.tp["can"]["bitrate"] = bitrate
        self.sim_scene = declare(self, "sim.scene", "", "scene played by the simulated transport")
        self.sim_speed = declare(self, "sim.speed", 1.0, "simulated time per wall time", minimum=1e-3)
        self.sim_wire = declare(self, "sim.wire", "can", "framing of the simulated bus: can (skin CAN layout) or "
                                "serial (skin serial framing)", choices=("can", "serial"))
        autostart = declare(self, "autostart", True, "configure and activate at start")
        self.qos_frames = declare_qos(self, "frames", QosDefaults("reliable", "volatile", 200))

        ct = self.robot.cell_types[self.robot.body_parts[0].cell_type]
        self.accel_rate_hz = ct.vibration.rate_hz
        self.force_rate_hz = ct.deformation.rate_hz
        self.accel_scale = ct.vibration.si_per_count if ct.vibration.unit == "m/s^2" else ACCEL_MPS2_PER_COUNT
        self.force_n_per_count = ct.force.n_per_count
        self.served = {c.id: p.name for p in self.robot.body_parts for c in p.cells}
        self.frame_ids = {c.id: str(c.extra.get("frame_id", f"skin_cell_{c.id}")) for p in self.robot.body_parts
                          for c in p.cells}
        self.known = set(self.full_robot.cell_index())
        self.decoder = None
        self.cells: dict[int, _Cell] = {}
        self.other_part_frames: Counter[int] = Counter()
        self.part_publishers: dict[str, object] = {}
        self._start(autostart, [("bus", self._bus_status)]
                    + [(part.name, lambda p=part: self._part_status(p)) for part in self.robot.body_parts])

    # ------------------------------------------------------------- lifecycle
    def _simulated_source(self):
        from ..sim.sources import SkinCanSource, SkinSerialSource, load_scene_for

        scene = load_scene_for(self.sim_scene, self.full_robot.name)
        source_cls = SkinCanSource if self.sim_wire == "can" else SkinSerialSource
        return source_cls(scene, speed=self.sim_speed)

    def _configured(self) -> TransitionCallbackReturn:
        self.is_can = self.transport_name == "can" or (self.transport_name == "simulated" and self.sim_wire == "can")
        self.decoder = SkinCanDecoder(known_cell_ids=self.known) if self.is_can else \
            SkinSerialDecoder(known_cell_ids=self.known)
        self.cells = {cid: _Cell(cid, part, self.frame_ids[cid]) for cid, part in self.served.items()}
        from tactile_descriptors_msgs.msg import SkinCellFrame

        for part in self.robot.body_parts:
            topic = self.topic_fmt.format(body_part=part.name)
            self.part_publishers[part.name] = self.create_lifecycle_publisher(SkinCellFrame, topic, self.qos_frames)
        self.get_logger().info(f"{self.transport_name} transport open: {len(self.cells)} cells on "
                               f"{len(self.robot.body_parts)} body parts")
        return TransitionCallbackReturn.SUCCESS

    def _destroy_publishers(self) -> None:
        for pub in self.part_publishers.values():
            self.destroy_lifecycle_publisher(pub)
        self.part_publishers.clear()

    # ---------------------------------------------------------------- reading
    def _read(self) -> list:
        if self.is_can:
            samples = []
            msg = self.transport.recv(0.05)
            while msg is not None:
                s = self.decoder.decode(msg)
                if s is not None:
                    samples.append(s)
                if len(samples) >= 5000:
                    break
                msg = self.transport.recv(0.0)
            return samples
        data = self.transport.read(65536, 0.05)
        return self.decoder.feed(data) if data else []

    def _consume(self, samples: list) -> None:
        if not samples:
            return
        with self._lock:
            touched = set()
            for s in samples:
                cell = self.cells.get(s.cell_id)
                if cell is None:  # a configured cell of a body part this node does not serve
                    self.other_part_frames[s.cell_id] += 1
                    continue
                self._add(cell, s)
                touched.add(cell.cell_id)
            for cid in touched:
                self._maybe_publish(self.cells[cid])

    def _time(self, cell: _Cell, s) -> int:
        """Sample time: bus time (``device``) or a sample clock per cell and modality (``clock``)."""
        mod = int(s.modality)
        rate = {1: self.accel_rate_hz, 2: self.force_rate_hz, 3: self.force_rate_hz}.get(
            mod, NOMINAL_RATE_HZ[Modality(mod)])
        clk = cell.seq.get(mod)
        if clk is None:
            clk = cell.seq[mod] = {"unwrap": Unwrapper(256), "first": None, "last": None, "anchor": None}
        useq = clk["unwrap"](s.sequence)
        if clk["last"] is not None and useq > clk["last"] + 1:
            gap = useq - clk["last"] - 1
            cell.lost += gap
            cell.lost_since_msg += gap
        clk["last"] = useq if clk["last"] is None else max(useq, clk["last"])
        if self.stamp_source == "device":
            if s.stamp_ns is not None:
                return int(s.stamp_ns)
            self.faults["no_device_time"] += 1
        now = self.get_clock().now().nanoseconds
        if clk["anchor"] is None:
            clk["anchor"], clk["first"] = now, useq
        t = clk["anchor"] + int(round((useq - clk["first"]) * 1e9 / rate))
        if self.resync_s > 0 and abs(t - now) > self.resync_s * 1e9:
            self.faults["clock_resync"] += 1
            clk["anchor"], clk["first"] = now, useq
            t = now
        return t

    def _add(self, cell: _Cell, s) -> None:
        t = self._time(cell, s)
        cell.samples += 1
        cell.rate.add()
        cell.last_monotonic = time.monotonic()
        if cell.first_t_ns is None:
            cell.first_t_ns = t
        if s.modality == Modality.ACCEL:
            cell.accel.append((t, s.values))
        elif s.modality == Modality.FORCE:
            cell.force.append((t, s.values))
            cell.recent_force.append((t, float(np.mean(s.values)), s.values))
        elif s.modality == Modality.PROXIMITY:
            cell.proximity.append((t, s.values[0]))
        else:
            cell.temperature_c = s.values[0] * 0.01

    def _maybe_publish(self, cell: _Cell) -> None:
        if not cell.accel:
            return
        if not cell.tared and self.tare_on_start_s > 0:
            if cell.accel[-1][0] - cell.first_t_ns >= self.tare_on_start_s * 1e9:
                ok, why = self._tare_cell(cell, self.tare_on_start_s)
                if not ok:
                    self.get_logger().warning(f"cell {cell.cell_id}: start tare failed: {why}", throttle_duration_sec=5.0)
                    cell.tared = True  # publish anyway, untared (the diagnostics say so)
            cell.accel.clear()
            cell.force.clear()
            cell.proximity.clear()
            return
        if cell.accel[-1][0] - cell.accel[0][0] + 1e9 / self.accel_rate_hz < self.batch_s * 1e9:
            return
        acc = sorted(cell.accel, key=lambda a: a[0])  # late (reordered) frames back in time order
        t0 = acc[0][0]
        force = sorted(cell.force, key=lambda f: f[0])
        prox = sorted(cell.proximity, key=lambda p: p[0])
        if len(prox) != len(force):
            prox = []
        frame = SkinFrame(
            stamp_ns=t0,
            accel=np.array([v for _, v in acc], np.int16).T.reshape(3, -1),
            accel_offset_ns=np.array([t - t0 for t, _ in acc], np.int64),
            force=np.array([v for _, v in force], np.uint16).T.reshape(3, -1),
            force_offset_ns=np.array([t - t0 for t, _ in force], np.int64),
            proximity=np.array([p for _, p in prox], np.uint16),
            temperature_c=cell.temperature_c, sequence=cell.sequence, bad_frames=cell.lost_since_msg)
        cell.accel, cell.force, cell.proximity = [], [], []
        cell.lost_since_msg = 0
        cell.sequence += 1
        msg = skin_frame_to_msg(frame, cell_id=cell.cell_id, body_part=cell.body_part, frame_id=cell.frame_id,
                                accel_mps2_per_count=self.accel_scale, force_n_per_count=self.force_n_per_count,
                                force_tare_counts=cell.tare)
        self.part_publishers[cell.body_part].publish(msg)
        cell.messages += 1

    # ------------------------------------------------------------------- tare
    def _force_n(self, cell: _Cell) -> float | None:
        if not cell.recent_force:
            return None
        last = np.array([v for _, _, v in list(cell.recent_force)[-5:]], np.float64)
        return float(np.mean(last - cell.tare[None, :])) * self.force_n_per_count

    def _tare_cell(self, cell: _Cell, window_s: float) -> tuple[bool, str]:
        if not cell.recent_force:
            return False, "no force samples yet"
        newest = cell.recent_force[-1][0]
        vals = [v for t, _, v in cell.recent_force if t >= newest - window_s * 1e9]
        if len(vals) < 3:
            return False, f"only {len(vals)} force samples in the last {window_s} s"
        cell.tare = np.mean(np.array(vals, np.float64), axis=0)
        cell.tared = True
        return True, "ok"

    def _srv_tare(self, request, response):
        with self._lock:
            touching = [(c.cell_id, f) for c in self.cells.values()
                        if (f := self._force_n(c)) is not None and f >= self.contact_threshold_n]
            if touching:
                response.success = False
                response.message = (f"refused: {len(touching)} cells in contact (e.g. cell {touching[0][0]}: "
                                    f"{touching[0][1]:.2f} N >= {self.contact_threshold_n} N)")
                return response
            results = {c.cell_id: self._tare_cell(c, self.tare_window_s) for c in self.cells.values()}
        failed = {cid: why for cid, (ok, why) in results.items() if not ok}
        response.success = not failed
        response.message = (f"tared {len(results) - len(failed)} cells" +
                            (f"; failed: {', '.join(f'{c} ({w})' for c, w in list(failed.items())[:5])}"
                             if failed else ""))
        return response

    # ------------------------------------------------------------ diagnostics
    def _bus_status(self) -> Status:
        values = self._transport_values({})
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
                  or now - st.last_monotonic > 1.0]
        live = [st for st in cells if st is not None]
        values = {"cells": len(part.cells), "silent_cells": len(silent),
                  "samples_per_s": sum(st.rate.rate_hz for st in live),
                  "messages": sum(st.messages for st in live), "lost_frames": sum(st.lost for st in live),
                  "tared_cells": sum(st.tared for st in live)}
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
