"""``tactile view --bag``: play a bag into the view, with its progress and seeking (no ROS needed).

The bag's frames topics go through the same core as the contact node
(:func:`~..core.contact.reduce_chunk`, :func:`~..core.contact.reduce_skin_runs`,
:class:`~..core.display.PartDisplay`), one display frame per display period
of bag time; predictions, descriptors and labels recorded in the bag fill the
prediction history.  Playback runs at ``speed`` times the recorded pace (log
times), or as fast as it can (``speed`` 0, for snapshots).

Which robot: the one given, else the ``robot`` of the bag's descriptors or
contacts, else a shipped robot description whose body parts and cells the
frames name.  None found (an imported recording of a sensor no description
has), or one without geometry: the cells are laid out in a grid and the view
says so.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..bags.io import BagMessage, BagReader
from ..core.contact import reduce_chunk, reduce_skin_runs
from ..core.display import PartDisplay
from ..core.robot import RobotDescription, config_dir, load_robot
from ..errors import BagError, ConfigError, SignalError
from .model import ViewModel

__all__ = ["BagPlayer", "resolve_bag_robot"]

_PKG = "tactile_descriptors_msgs/msg/"
FRAMES_TYPES = (_PKG + "BioTacFrameBatch", _PKG + "SkinPartFrames")


def _ns(stamp) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def _frames_topics(reader: BagReader) -> dict[str, str]:
    assert reader.info is not None
    return {t.name: t.msgtype for t in reader.info.topics.values() if t.msgtype in FRAMES_TYPES}


def _first_messages(reader: BagReader, topics: list[str], per_topic: int = 5) -> Iterator[tuple[BagMessage, Any]]:
    if not topics:
        return  # (an empty selection would read every topic)
    seen: dict[str, int] = {}
    for m in reader.messages(topics):
        if seen.get(m.topic, 0) >= per_topic:
            if len(seen) == len(topics) and all(v >= per_topic for v in seen.values()):
                return
            continue
        seen[m.topic] = seen.get(m.topic, 0) + 1
        yield m, reader.deserialize(m)


def _cells_seen(reader: BagReader) -> dict[str, dict[str, Any]]:
    """Body parts the frames name, with their cells (BioTac sensor names or skin cell ids) and kind."""
    parts: dict[str, dict[str, Any]] = {}
    topics = _frames_topics(reader)
    for m, msg in _first_messages(reader, list(topics)):
        entry = parts.setdefault(str(msg.body_part), {"kind": "", "cells": {}})
        if m.msgtype.endswith("BioTacFrameBatch"):
            entry["kind"] = "biotac"
            entry["cells"].setdefault(str(msg.sensor_name), int(msg.electrode_count))
        else:
            entry["kind"] = "skin"
            for cid in np.asarray(msg.cell_ids).tolist():
                entry["cells"].setdefault(int(cid), 3)
    return parts


def resolve_bag_robot(reader: BagReader, robot: str | None = None) -> tuple[RobotDescription | None, str]:
    """The bag's robot and how it was found (see the module docstring)."""
    if robot:
        return load_robot(robot), "given"
    assert reader.info is not None
    named = [t.name for t in reader.info.topics.values()
             if t.msgtype in (_PKG + "Descriptor", _PKG + "ContactArray")]
    for _, msg in _first_messages(reader, named, 1):
        try:
            return load_robot(str(msg.robot)), f"named by the bag's {type(msg).__name__.split('__')[-1]}"
        except ConfigError:
            continue
    seen = _cells_seen(reader)
    if not seen:
        return None, "no frames in the bag"
    for path in sorted(config_dir().glob("*.yaml")):
        try:
            cand = load_robot(path)
        except ConfigError:
            continue
        ok = True
        for name, entry in seen.items():
            try:
                part = cand.body_part(name)
            except ConfigError:
                ok = False
                break
            known = {c.name for c in part.cells} | {c.id for c in part.cells}
            if not all(c in known for c in entry["cells"]):
                ok = False
                break
        if ok:
            return cand, f"matched by its body parts and cells ({path.name})"
    return None, "no robot description has the bag's body parts and cells"


class BagPlayer:
    """Play a bag into a :class:`~.model.ViewModel` and publish a frame per display period.

    Parameters
    ----------
    path : str or path
    publish : callable
        ``publish(kind, payload)`` (a :class:`~.server.Hub`'s).
    robot : str, optional
        Robot name or YAML path (see :func:`resolve_bag_robot`).
    speed : float
        Bag seconds per wall second; 0 plays as fast as it can.
    floor_n : float
        As the contact node's ``contact.floor_n``.
    """

    def __init__(self, path: str | Path, publish: Callable[[str, Any], None], *, robot: str | None = None,
                 speed: float = 1.0, floor_n: float = 0.05) -> None:
        if speed < 0:
            raise ConfigError(f"must be 0 (as fast as possible) or positive, got {speed}", key="speed")
        self.path = Path(path)
        self.publish = publish
        self.speed = float(speed)
        self.floor_n = float(floor_n)
        self.reader = BagReader(self.path).open()
        info = self.reader.info
        assert info is not None
        if not _frames_topics(self.reader):
            raise BagError(f"{self.path}: no BioTacFrameBatch or SkinPartFrames topic to view")
        self.robot, self.robot_found = resolve_bag_robot(self.reader, robot)
        seen = _cells_seen(self.reader)
        parts = None
        if self.robot is None:
            parts = {name: list(range(len(e["cells"]))) for name, e in seen.items()}
        self.model = ViewModel(self.robot, source=str(self.path), parts=parts)
        self.start_ns, self.end_ns = info.start_ns, info.end_ns
        self.duration_s = max(0.0, (self.end_ns - self.start_ns) / 1e9)
        threshold = self.robot.contact.force_threshold_n if self.robot is not None else 0.2
        self.displays: dict[str, PartDisplay] = {}
        self._cell_of: dict[tuple[str, Any], int] = {}
        self._scale: dict[str, float] = {}
        for name in self.model.parts:
            if self.robot is not None:
                part = self.robot.body_part(name)
                ct = self.robot.cell_types[part.cell_type]
                n_def, self._scale[name] = len(ct.deformation.channels), ct.vibration.si_per_count
                for c in part.cells:
                    self._cell_of[(name, c.name)] = self._cell_of[(name, c.id)] = c.id
            else:
                e = seen[name]
                n_def, self._scale[name] = (max(e["cells"].values()) if e["cells"] else 3), 1.0
                for k, key in enumerate(e["cells"]):
                    self._cell_of[(name, key)] = k
            self.displays[name] = self.model.part_display(name, n_def, threshold, self.floor_n)
        self.position_ns = self.start_ns
        self.ended = False
        self.faults: dict[str, int] = {}
        self._seek_to: float | None = None
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()

    # ----------------------------------------------------------- control
    def start(self) -> BagPlayer:
        self._thread = threading.Thread(target=self._run, daemon=True, name="tactile-view-bag")
        self._thread.start()
        return self

    def seek(self, t_s: float) -> float:
        """Jump to ``t_s`` seconds from the bag's start (clipped to the bag); returns where."""
        t = min(max(0.0, float(t_s)), self.duration_s)
        with self._lock:
            self._seek_to = t
        self._wake.set()
        return t

    def close(self) -> None:
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        self.reader.close()

    # ------------------------------------------------------------- play
    def play_until(self, t_s: float | None = None) -> dict:
        """Play (as fast as possible, on this thread) up to ``t_s`` seconds from the start, or the end; the last frame."""
        stop = self.end_ns + 1 if t_s is None else self.start_ns + int(t_s * 1e9)
        last = deque(self._frames(self.start_ns, stop, paced=False), maxlen=1)
        return last[0] if last else self._emit(self.start_ns, final=True)

    def _run(self) -> None:
        begin = self.start_ns
        while not self._stop.is_set():
            for _ in self._frames(begin, self.end_ns + 1, paced=self.speed > 0):
                if self._stop.is_set() or self._seek_to is not None:
                    break
            with self._lock:
                seek, self._seek_to = self._seek_to, None
            if seek is not None:
                begin = self.start_ns + int(seek * 1e9)
                continue
            self.ended = True
            self._emit(self.position_ns, final=True)
            self._wake.wait()  # the end: wait for a seek (or close)
            self._wake.clear()
            with self._lock:
                seek, self._seek_to = self._seek_to, None
            if seek is not None:
                begin, self.ended = self.start_ns + int(seek * 1e9), False

    def _reset(self) -> None:
        for d in self.displays.values():
            d.window.reset()
            d.window.newest_ns[:] = -1
            d.cell_force[:] = np.nan
            d.last_wall_s = float("-inf")
            if d.site_change is not None:
                d.site_change[:] = np.nan
        self.model.history = type(self.model.history)()
        for p in self.model.parts.values():
            p.trace.clear()
            p.last = {}
        self.model.t_ns = -1

    def _frames(self, begin_ns: int, stop_ns: int, *, paced: bool) -> Iterator[dict]:
        """Frames from ``begin_ns`` to ``stop_ns`` (log time); predictions and labels before ``begin_ns`` too."""
        self._reset()
        period_ns = int(1e9 / self.model.rate_hz)
        next_tick = begin_ns + period_ns
        wall0, log0 = time.monotonic(), begin_ns
        warm = max(self.start_ns, begin_ns - int(1e9 * self.model.stale_s))  # cells' last values before a seek
        for m in self.reader.messages(start_ns=self.start_ns, stop_ns=stop_ns):
            t = m.log_time_ns
            if t < warm and not m.msgtype.endswith(("Prediction", "Label", "Descriptor")):
                continue
            while t >= next_tick:
                if paced:
                    wait = (next_tick - log0) / 1e9 / self.speed - (time.monotonic() - wall0)
                    if wait > 0 and self._wake.wait(wait):
                        return
                yield self._emit(next_tick)
                next_tick += period_ns
            self._take(m, t, paced)
            if self._stop.is_set() or self._seek_to is not None:
                return
        if next_tick - period_ns < stop_ns:
            yield self._emit(min(stop_ns, self.end_ns))

    def _take(self, m: BagMessage, t_ns: int, paced: bool) -> None:
        try:
            msg = self.reader.deserialize(m)
        except BagError:
            self.faults["undecodable"] = self.faults.get("undecodable", 0) + 1
            return
        h = self.model.history
        if m.msgtype.endswith("Prediction"):
            h.prediction(int(msg.exploration_id), _ns(msg.window_end), str(msg.class_name), list(msg.class_names),
                         list(np.asarray(msg.scores, dtype=float)), bool(msg.has_model))
        elif m.msgtype.endswith("Descriptor"):
            h.descriptor(int(msg.exploration_id), _ns(msg.window_end), list(msg.body_parts),
                         [bool(c) for c in np.asarray(msg.contact).tolist()])
        elif m.msgtype.endswith("Label"):
            h.label(int(msg.exploration_id), str(msg.class_name))
        elif m.msgtype in FRAMES_TYPES:
            self._frames_msg(m, msg, t_ns)

    def _frames_msg(self, m: BagMessage, msg: Any, t_ns: int) -> None:
        from ..nodes.conversions import biotac_msg_to_chunk

        name = str(msg.body_part)
        display = self.displays.get(name)
        if display is None:
            self.faults["unknown_body_part"] = self.faults.get("unknown_body_part", 0) + 1
            return
        wall = t_ns / 1e9  # bag time stands in for the wall clock: staleness follows the recording
        try:
            if m.msgtype.endswith("BioTacFrameBatch"):
                cid = self._cell_of.get((name, str(msg.sensor_name)))
                if cid is None:
                    self.faults["unknown_sensor"] = self.faults.get("unknown_sensor", 0) + 1
                    return
                display.add(cid, reduce_chunk(biotac_msg_to_chunk(msg), float(msg.pac_pa_per_count) or
                                              self._scale[name]), wall)
            else:
                ids = np.asarray(msg.cell_ids, dtype=np.int64)
                mapped = np.array([self._cell_of.get((name, int(c)), -1) for c in ids], dtype=np.int64)
                runs = reduce_skin_runs(
                    mapped, np.asarray(msg.force, dtype=np.uint16), np.asarray(msg.force_count),
                    np.asarray(msg.force_offset_ns, dtype=np.int64), np.asarray(msg.force_tare_counts, dtype=float),
                    float(msg.force_n_per_count),
                    np.stack([np.asarray(msg.accel_x), np.asarray(msg.accel_y), np.asarray(msg.accel_z)]),
                    np.asarray(msg.accel_count), float(msg.accel_mps2_per_count) or self._scale[name],
                    _ns(msg.header.stamp))
                display.add_runs(runs, wall)
        except SignalError:
            self.faults["malformed"] = self.faults.get("malformed", 0) + 1

    def _emit(self, t_ns: int, final: bool = False) -> dict:
        """Close a display period at log time ``t_ns`` and publish the frame."""
        now = max((int(d.window.newest_ns.max()) for d in self.displays.values()), default=-1)
        wall = t_ns / 1e9
        for name, d in self.displays.items():
            self.model.update_frame(name, d.tick(now, wall))
        self.position_ns = t_ns
        self.model.progress = {"position_s": round(max(0.0, (t_ns - self.start_ns) / 1e9), 3),
                               "duration_s": round(self.duration_s, 3), "ended": bool(final and self.ended),
                               "speed": self.speed}
        frame = self.model.frame()
        self.publish("frame", frame)
        return frame
