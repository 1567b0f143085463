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
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from rclpy.lifecycle import TransitionCallbackReturn

from ..codecs.skin import ACCEL_MPS2_PER_COUNT, NO_STAMP, NOMINAL_RATE_HZ, Modality, SkinSampleBatch
from ..codecs.skin_can import SkinCanDecoder
from ..codecs.skin_serial import SkinSerialDecoder
from .common import RateMeter, Status, declare, run_node
from .conversions import SkinFrame, skin_frame_to_msg
from .driver_base import DriverBase
from .qos import QosDefaults, declare_qos
from .window_node import FRAMES_TOPIC

__all__ = ["SkinDriver", "main"]

TRANSPORTS = ("can", "serial", "simulated", "loopback")


class _Stream:
    """Pending samples of one modality of one cell: time stamps and counts, as a list of array pieces."""

    __slots__ = ("t", "v")

    def __init__(self) -> None:
        self.t: list[np.ndarray] = []
        self.v: list[np.ndarray] = []

    def add(self, t_ns: np.ndarray, values: np.ndarray) -> None:
        self.t.append(t_ns)
        self.v.append(values)

    def clear(self) -> None:
        self.t, self.v = [], []

    def __bool__(self) -> bool:
        return bool(self.t)

    def arrays(self, width: int) -> tuple[np.ndarray, np.ndarray]:
        """All pending samples, sorted by time (late, reordered frames back in place)."""
        if not self.t:
            return np.zeros(0, np.int64), np.zeros((0, width), np.int64)
        t = np.concatenate(self.t) if len(self.t) > 1 else self.t[0]
        v = np.concatenate(self.v) if len(self.v) > 1 else self.v[0]
        order = np.argsort(t, kind="stable")
        return t[order], v[order]

    def keep(self, t_ns: np.ndarray, values: np.ndarray) -> None:
        """Replace the pending samples by these (sorted) ones."""
        self.t, self.v = ([t_ns], [values]) if t_ns.size else ([], [])


@dataclass
class _Cell:
    cell_id: int
    body_part: str
    frame_id: str
    accel: _Stream = field(default_factory=_Stream)  # (t_ns, (x, y, z))
    force: _Stream = field(default_factory=_Stream)  # (t_ns, (f0, f1, f2))
    proximity: _Stream = field(default_factory=_Stream)  # (t_ns, p)
    temperature_c: float = float("nan")
    recent_force_t: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # last 500 force samples
    recent_force_v: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.int64))
    tare: np.ndarray = field(default_factory=lambda: np.zeros(3))
    tared: bool = False
    first_t_ns: int | None = None
    last_accel_t_ns: int | None = None
    sequence: int = 0
    lost: int = 0
    lost_since_msg: int = 0
    samples: int = 0
    messages: int = 0
    last_monotonic: float | None = None
    rate: RateMeter = field(default_factory=RateMeter)


#: Force samples kept per cell for ~/tare and the contact check.
RECENT_FORCE = 500


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
        return source_cls(scene, speed=self.sim_speed, chunk_s=2.0)

    def _configured(self) -> TransitionCallbackReturn:
        self.is_can = self.transport_name == "can" or (self.transport_name == "simulated" and self.sim_wire == "can")
        self.decoder = SkinCanDecoder(known_cell_ids=self.known) if self.is_can else \
            SkinSerialDecoder(known_cell_ids=self.known)
        self.cells = {cid: _Cell(cid, part, self.frame_ids[cid]) for cid, part in self.served.items()}
        self._cell_list = list(self.cells.values())
        self._cell_index = np.full(0x10000, -1, dtype=np.int64)
        for i, cell in enumerate(self._cell_list):
            self._cell_index[cell.cell_id] = i
        k = 4 * len(self._cell_list)
        self._clk = {"have": np.zeros(k, bool), "last_raw": np.zeros(k, np.int64), "value": np.zeros(k, np.int64),
                     "last": np.zeros(k, np.int64), "anchored": np.zeros(k, bool), "anchor": np.zeros(k, np.int64),
                     "first": np.zeros(k, np.int64)}
        self._period_ns = 1e9 / np.array([self.accel_rate_hz, self.force_rate_hz, self.force_rate_hz,
                                          NOMINAL_RATE_HZ[Modality.TEMPERATURE]])
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
    def _read(self) -> SkinSampleBatch:
        if self.is_can:  # every queued frame at once, decoded with array operations
            return self.decoder.decode_frames(self.transport.recv_batch(65536, 0.05))
        data = self.transport.read(1 << 20, 0.05)
        if not data:
            return SkinSampleBatch.empty()
        return self.decoder.feed_batch(data)

    def _consume(self, batch: SkinSampleBatch) -> None:
        if not len(batch):
            return
        with self._lock:
            ci = self._cell_index[batch.cell_id]
            served = ci >= 0
            if not served.all():  # configured cells of body parts this node does not serve
                ids, counts = np.unique(batch.cell_id[~served], return_counts=True)
                for c, k in zip(ids.tolist(), counts.tolist()):
                    self.other_part_frames[c] += k
                batch, ci = batch.take(served), ci[served]
                if not len(batch):
                    return
            self._add_batch(ci, batch)

    def _add_batch(self, ci: np.ndarray, batch: SkinSampleBatch) -> None:
        """Add a batch of served samples: sequence unwrapping, lost frames and sample times for every
        (cell, modality) at once with array operations, then the samples to each cell's buffers."""
        key = ci * 4 + (batch.modality - 1)
        order = np.argsort(key, kind="stable")  # per cell and modality, in arrival order
        ks = key[order]
        n = ks.size
        starts = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]])
        ends = np.r_[starts[1:], n]
        lens = ends - starts
        gk = ks[starts]
        clk = self._clk
        have = clk["have"][gk]
        # unwrap the 8-bit sequence numbers (as biotac_driver.Unwrapper does, per cell and modality)
        raw = batch.sequence[order] & 0xFF
        d = np.empty(n, np.int64)
        d[1:] = raw[1:] - raw[:-1]
        d[starts] = raw[starts] - np.where(have, clk["last_raw"][gk], raw[starts])
        d %= 256
        d[d >= 128] -= 256
        cs = np.cumsum(d)
        base = np.where(have, clk["value"][gk], raw[starts]) - (cs[starts] - d[starts])
        useq = cs + np.repeat(base, lens)
        # frames lost: jumps beyond the highest number seen so far
        prev = np.empty(n, np.int64)
        prev[1:] = useq[:-1]
        prev[starts] = np.where(have, clk["last"][gk], useq[starts] - 1)
        offset = np.repeat(np.arange(gk.size, dtype=np.int64) << 42, lens)
        highest = np.maximum.accumulate(prev + offset) - offset
        lost = np.maximum(useq - highest - 1, 0)
        clk["have"][gk] = True
        clk["last_raw"][gk] = raw[ends - 1]
        clk["value"][gk] = useq[ends - 1]
        clk["last"][gk] = np.maximum(highest[ends - 1], useq[ends - 1])
        # sample times
        t = np.empty(n, np.int64)
        need = np.ones(n, bool)
        if self.stamp_source == "device":
            stamp = batch.stamp_ns[order]
            need = stamp == NO_STAMP
            t[~need] = stamp[~need]
            if need.any():
                self.faults["no_device_time"] += int(need.sum())
        if need.any():
            group = np.repeat(np.arange(gk.size), lens)
            if self.stamp_source == "device":
                need = self._extrapolate_device_times(t, need, useq, gk, group, starts, ends)
            if need.any():
                t[need] = self._clock_times(gk, group[need], useq[need])
            if self.stamp_source == "device":  # missing bus times later on extrapolate from the last known one
                stamped = np.flatnonzero(~need)
                if stamped.size:
                    last = stamped[np.searchsorted(stamped, ends - 1, side="right") - 1]
                    ok = (last >= starts) & (last >= 0)
                    self._clk["anchored"][gk[ok]] = True
                    self._clk["anchor"][gk[ok]] = t[last[ok]]
                    self._clk["first"][gk[ok]] = useq[last[ok]]
        # into the cells' buffers
        vals = batch.values[order]
        cell_of = gk // 4
        mono = time.monotonic()
        lost_per_group = np.add.reduceat(lost, starts)
        touched: dict[int, _Cell] = {}
        for g, (c, m, a, b, nl) in enumerate(zip(cell_of.tolist(), (gk % 4 + 1).tolist(), starts.tolist(),
                                                 ends.tolist(), lost_per_group.tolist())):
            cell = self._cell_list[c]
            tt, vv = t[a:b], vals[a:b]
            cell.lost += nl
            cell.lost_since_msg += nl
            cell.samples += b - a
            cell.rate.add(b - a)
            cell.last_monotonic = mono
            if cell.first_t_ns is None:
                cell.first_t_ns = int(tt[0])
            if m == Modality.ACCEL:
                cell.accel.add(tt, vv)
                last = int(tt.max())
                cell.last_accel_t_ns = last if cell.last_accel_t_ns is None else max(last, cell.last_accel_t_ns)
            elif m == Modality.FORCE:
                cell.force.add(tt, vv)
                cell.recent_force_t = np.concatenate([cell.recent_force_t, tt])[-RECENT_FORCE:]
                cell.recent_force_v = np.concatenate([cell.recent_force_v, vv])[-RECENT_FORCE:]
            elif m == Modality.PROXIMITY:
                cell.proximity.add(tt, vv[:, :1])
            else:
                cell.temperature_c = float(vv[-1, 0]) * 0.01
            touched[c] = cell
        for cell in touched.values():
            self._maybe_publish(cell)

    def _extrapolate_device_times(self, t: np.ndarray, need: np.ndarray, useq: np.ndarray, gk: np.ndarray,
                                  group: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
        """``device`` stamps: a sample without a bus time (python-can's timestamp 0.0) gets the time of the
        nearest stamped sample of its cell and modality in this batch plus the sequence distance times the
        nominal period.  Fills ``t`` in place; returns the samples still without a time."""
        n = t.size
        pos = np.arange(n)
        stamped = np.where(~need, pos, -1)
        offset = np.repeat(starts, ends - starts)
        before = np.maximum.accumulate(stamped)  # nearest stamped sample at or before, any group
        after = np.minimum.accumulate(np.where(~need, pos, n)[::-1])[::-1]  # nearest at or after
        ref = np.where(before >= offset, before, np.where(after < np.repeat(ends, ends - starts), after, -1))
        fill = need & (ref >= 0)
        if fill.any():
            r = ref[fill]
            period = self._period_ns[gk[group[fill]] % 4]
            t[fill] = t[r] + np.rint((useq[fill] - useq[r]) * period).astype(np.int64)
        return need & ~fill

    def _clock_times(self, gk: np.ndarray, group: np.ndarray, useq: np.ndarray) -> np.ndarray:
        """Sample-clock times (``clock`` stamps, or ``device`` samples without a bus time): per cell and
        modality the node clock at its first sample plus sequence number times the nominal period,
        re-anchored when it drifts from the node clock by more than ``resync_s``."""
        clk = self._clk
        now = self.get_clock().now().nanoseconds
        keys = gk[group]
        first_of = np.r_[True, group[1:] != group[:-1]]
        new = first_of & ~clk["anchored"][keys]
        clk["anchor"][keys[new]] = now
        clk["first"][keys[new]] = useq[new]
        clk["anchored"][keys[new]] = True
        period = self._period_ns[keys % 4]
        t = clk["anchor"][keys] + np.rint((useq - clk["first"][keys]) * period).astype(np.int64)
        if self.resync_s > 0:
            limit = self.resync_s * 1e9
            far = np.abs(t - now) > limit
            for k in np.unique(keys[far]).tolist():  # rare: walk that cell and modality sample by sample
                for i in np.flatnonzero(keys == k).tolist():
                    ti = int(clk["anchor"][k]) + int(round((int(useq[i]) - int(clk["first"][k])) * period[i]))
                    if abs(ti - now) > limit:
                        self.faults["clock_resync"] += 1
                        clk["anchor"][k], clk["first"][k] = now, useq[i]
                        ti = now
                    t[i] = ti
        return t

    def _maybe_publish(self, cell: _Cell) -> None:
        """Publish every complete ``batch_s`` of a cell's accelerometer samples, one message each."""
        if not cell.accel:
            return
        if not cell.tared and self.tare_on_start_s > 0:
            if cell.last_accel_t_ns - cell.first_t_ns >= self.tare_on_start_s * 1e9:
                ok, why = self._tare_cell(cell, self.tare_on_start_s)
                if not ok:
                    self.get_logger().warning(f"cell {cell.cell_id}: start tare failed: {why}", throttle_duration_sec=5.0)
                    cell.tared = True  # publish anyway, untared (the diagnostics say so)
            cell.accel.clear()
            cell.force.clear()
            cell.proximity.clear()
            return
        period_ns = 1e9 / self.accel_rate_hz
        batch_ns = self.batch_s * 1e9
        acc_t, acc_v = cell.accel.arrays(3)
        if acc_t[-1] - acc_t[0] + period_ns < batch_ns:
            cell.accel.keep(acc_t, acc_v)
            return
        f_t, f_v = cell.force.arrays(3)
        p_t, p_v = cell.proximity.arrays(1)
        while acc_t.size and acc_t[-1] - acc_t[0] + period_ns >= batch_ns:
            t0 = int(acc_t[0])
            end = t0 + batch_ns - period_ns / 2  # this message: accelerometer samples of [t0, t0 + batch_s)
            na = int(np.searchsorted(acc_t, end, side="right"))
            nf = int(np.searchsorted(f_t, end, side="right"))
            np_ = int(np.searchsorted(p_t, end, side="right"))
            self._publish(cell, t0, acc_t[:na], acc_v[:na], f_t[:nf], f_v[:nf], p_v[:np_, 0] if np_ == nf else None)
            acc_t, acc_v = acc_t[na:], acc_v[na:]
            f_t, f_v, p_t, p_v = f_t[nf:], f_v[nf:], p_t[np_:], p_v[np_:]
        cell.accel.keep(acc_t, acc_v)
        cell.force.keep(f_t, f_v)
        cell.proximity.keep(p_t, p_v)

    def _publish(self, cell: _Cell, t0: int, acc_t: np.ndarray, acc_v: np.ndarray, f_t: np.ndarray,
                 f_v: np.ndarray, prox: np.ndarray | None) -> None:
        frame = SkinFrame(
            stamp_ns=t0,
            accel=acc_v.T.astype(np.int16),
            accel_offset_ns=acc_t - t0,
            force=f_v.T.astype(np.uint16),
            force_offset_ns=f_t - t0,
            proximity=np.zeros(0, np.uint16) if prox is None else prox.astype(np.uint16),
            temperature_c=cell.temperature_c, sequence=cell.sequence, bad_frames=cell.lost_since_msg)
        cell.lost_since_msg = 0
        cell.sequence += 1
        msg = skin_frame_to_msg(frame, cell_id=cell.cell_id, body_part=cell.body_part, frame_id=cell.frame_id,
                                accel_mps2_per_count=self.accel_scale, force_n_per_count=self.force_n_per_count,
                                force_tare_counts=cell.tare)
        self.part_publishers[cell.body_part].publish(msg)
        cell.messages += 1

    # ------------------------------------------------------------------- tare
    def _force_n(self, cell: _Cell) -> float | None:
        if not cell.recent_force_t.size:
            return None
        last = cell.recent_force_v[-5:].astype(np.float64)
        return float(np.mean(last - cell.tare[None, :])) * self.force_n_per_count

    def _tare_cell(self, cell: _Cell, window_s: float) -> tuple[bool, str]:
        if not cell.recent_force_t.size:
            return False, "no force samples yet"
        newest = cell.recent_force_t[-1]
        vals = cell.recent_force_v[cell.recent_force_t >= newest - window_s * 1e9]
        if len(vals) < 3:
            return False, f"only {len(vals)} force samples in the last {window_s} s"
        cell.tare = np.mean(vals.astype(np.float64), axis=0)
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
