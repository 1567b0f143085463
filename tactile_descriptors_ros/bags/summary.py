"""Readable summaries of tactile messages for ``tactile echo``: what ``ros2 topic echo`` cannot show.

A ``BioTacFrameBatch`` carries hundreds of numbers; a ``Descriptor`` up to a
few hundred values.  Printing them all hides what one looks for when
something is wrong, so :class:`EchoTracker` reduces each message to

* per-channel min / max / mean over the valid samples and the number of
  ``INVALID_COUNT`` (``INVALID_ACCEL``) samples, the force in newtons
  (``(pdc - pdc_tare_counts) * force_n_per_count``, as the contact gate of
  eq. 13 reads it), and consistency checks of array lengths;
* stream health across messages, per sensor: message rate, lost frames
  (gaps in ``first_frame_sequence`` / ``sequence``) and time-stamp gaps or
  jumps back; for a ``SkinPartFrames`` (all skin cells of a body part) per
  cell, summed over the body part;
* for a ``Descriptor``: per body part contact, cells in contact, mean force,
  the ``QUALITY_*`` bit mask decoded into names, and the values by label;
* for a ``Prediction``: the top scores and the margin between the best two.

Messages are rosbags objects (decoded from CDR by the type store), so the
same code serves bags and live topics, and needs no rclpy.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import yaml

from ..codecs.sequence import SequenceEvent, SequenceTracker
from ..layouts import DescriptorLayouts
from ..markers import INVALID_ACCEL, INVALID_COUNT

__all__ = [
    "channel_stats",
    "quality_names",
    "message_to_dict",
    "to_yaml",
    "EchoTracker",
    "format_summary",
]

_BATCH = "tactile_descriptors_msgs/msg/BioTacFrameBatch"
_SKIN = "tactile_descriptors_msgs/msg/SkinCellFrame"
_SKIN_PART = "tactile_descriptors_msgs/msg/SkinPartFrames"
_DESCRIPTOR = "tactile_descriptors_msgs/msg/Descriptor"
_LAYOUT = "tactile_descriptors_msgs/msg/DescriptorLayout"
_PREDICTION = "tactile_descriptors_msgs/msg/Prediction"
_LABEL = "tactile_descriptors_msgs/msg/Label"


def _stamp_ns(t: Any) -> int:
    return int(t.sec) * 1_000_000_000 + int(t.nanosec)


def _num(x: float) -> float | None:
    """JSON-safe float (NaN/inf become None)."""
    x = float(x)
    return x if math.isfinite(x) else None


def channel_stats(values: Any, invalid: int | None = None) -> dict[str, Any]:
    """Min, max, mean over the valid samples, and the counts of samples and invalid ones.

    Parameters
    ----------
    values : array_like
    invalid : int, optional
        The sentinel of an invalid sample (``INVALID_COUNT``, ``INVALID_ACCEL``).

    Returns
    -------
    dict
        ``n``, ``invalid``, ``min``, ``max``, ``mean`` (``None`` when no valid sample).
    """
    arr = np.asarray(values)
    n = int(arr.size)
    mask = arr != invalid if invalid is not None else np.ones(arr.shape, dtype=bool)
    if arr.dtype.kind == "f":
        mask &= np.isfinite(arr)
    valid = arr[mask]
    out: dict[str, Any] = {"n": n, "invalid": int(n - valid.size)}
    if valid.size:
        out.update(min=_num(valid.min()), max=_num(valid.max()), mean=_num(valid.astype(np.float64).mean()))
    else:
        out.update(min=None, max=None, mean=None)
    return out


def quality_names(mask: int, constants: Sequence[tuple[str, str, Any]]) -> list[str]:
    """Names of the ``QUALITY_*`` bits set in ``mask`` (unknown bits as ``BIT<k>``)."""
    names = []
    known = 0
    for name, _typ, value in constants:
        if name.startswith("QUALITY_"):
            known |= int(value)
            if mask & int(value):
                names.append(name[len("QUALITY_"):])
    rest = int(mask) & ~known
    k = 0
    while rest:
        if rest & 1:
            names.append(f"BIT{k}")
        rest >>= 1
        k += 1
    return names


def message_to_dict(msg: Any) -> Any:
    """A rosbags message object as plain Python (lists, numbers, strings) for YAML/JSON."""
    if dataclasses.is_dataclass(msg) and not isinstance(msg, type):
        return {
            f.name: message_to_dict(getattr(msg, f.name))
            for f in dataclasses.fields(msg)
            if f.name != "__msgtype__"
        }
    if isinstance(msg, np.ndarray):
        return [message_to_dict(x) for x in msg.tolist()] if msg.dtype == object else msg.tolist()
    if isinstance(msg, (list, tuple)):
        return [message_to_dict(x) for x in msg]
    if isinstance(msg, np.generic):
        return msg.item()
    if isinstance(msg, float) and not math.isfinite(msg):
        return str(msg)
    return msg


class _FlowDumper(yaml.SafeDumper):
    pass


def _represent_list(dumper: yaml.SafeDumper, data: list) -> Any:
    flow = all(not isinstance(x, (dict, list)) for x in data)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flow)


_FlowDumper.add_representer(list, _represent_list)


def to_yaml(msg: Any) -> str:
    """The full message as YAML (``ros2 topic echo`` style; number arrays on one line)."""
    return yaml.dump(message_to_dict(msg), Dumper=_FlowDumper, sort_keys=False, width=100)


@dataclasses.dataclass
class _Stream:
    first_log_ns: int | None = None
    last_log_ns: int | None = None
    count: int = 0
    expected_stamp_ns: int | None = None
    last_stamp_ns: int | None = None
    lost: int = 0
    sequence_gaps: int = 0
    restarts: int = 0
    stamp_gaps: int = 0
    stamp_backwards: int = 0


class EchoTracker:
    """Turns decoded messages into summaries, keeping per-stream state (rates, gaps).

    Parameters
    ----------
    constants : mapping of str to list
        Message type -> constants ``(name, type, value)`` from the type store
        (``store.fielddefs[msgtype][0]``), for decoding quality bits.
    top_k : int
        Scores shown for a ``Prediction``.
    """

    def __init__(self, constants: Mapping[str, Sequence[tuple[str, str, Any]]] | None = None, top_k: int = 3) -> None:
        self.constants = dict(constants or {})
        self.top_k = top_k
        self.streams: dict[str, _Stream] = {}
        self._sequences = SequenceTracker(1 << 32, window=0)  # message sequence numbers are 32-bit
        #: the labels of the descriptor layouts seen (``DescriptorLayout``), by layout id
        self.layouts = DescriptorLayouts()

    # ------------------------------------------------------------------ streams
    def _stream(self, key: str, log_ns: int) -> _Stream:
        s = self.streams.setdefault(key, _Stream())
        if s.first_log_ns is None:
            s.first_log_ns = log_ns
        s.last_log_ns = log_ns
        s.count += 1
        return s

    @staticmethod
    def _rate(s: _Stream) -> float | None:
        if s.count < 2 or s.first_log_ns is None or s.last_log_ns is None or s.last_log_ns <= s.first_log_ns:
            return None
        return (s.count - 1) * 1e9 / (s.last_log_ns - s.first_log_ns)

    def _check_sequence(self, s: _Stream, key: str, seq: int, count: int) -> int:
        """Items lost before a message whose run of ``count`` numbers starts at ``seq`` (32-bit).

        The one :class:`~tactile_descriptors_ros.codecs.sequence.SequenceTracker`
        unwraps the numbers: a step back is a restart of the sender's count, not
        four billion lost items.
        """
        event, lost = self._sequences.track_run(key, seq, max(int(count), 1))
        if event == SequenceEvent.RESET:
            s.restarts += 1
        if lost:
            s.sequence_gaps += 1
            s.lost += lost
        return lost

    def _check_stamp(self, s: _Stream, stamp_ns: int, expected_next_ns: int | None, tolerance_ns: int) -> int | None:
        """Gap (ns) between the expected and the actual stamp, when larger than ``tolerance_ns``."""
        gap = None
        if s.last_stamp_ns is not None and stamp_ns < s.last_stamp_ns:
            s.stamp_backwards += 1
            gap = stamp_ns - s.last_stamp_ns
        elif s.expected_stamp_ns is not None and abs(stamp_ns - s.expected_stamp_ns) > tolerance_ns:
            s.stamp_gaps += 1
            gap = stamp_ns - s.expected_stamp_ns
        s.last_stamp_ns = stamp_ns
        s.expected_stamp_ns = expected_next_ns
        return gap

    def _health(self, s: _Stream) -> dict[str, Any]:
        return {
            "messages": s.count,
            "rate_hz": self._rate(s),
            "lost": s.lost,
            "sequence_gaps": s.sequence_gaps,
            "restarts": s.restarts,
            "stamp_gaps": s.stamp_gaps,
            "stamp_backwards": s.stamp_backwards,
        }

    def stream_health(self) -> dict[str, dict[str, Any]]:
        """Per stream (topic, or topic#sensor): messages, rate, lost items, stamp gaps."""
        return {key: self._health(s) for key, s in self.streams.items()}

    # ------------------------------------------------------------------ messages
    def summarize(self, topic: str, msgtype: str, msg: Any, log_ns: int) -> dict[str, Any]:
        """One message's summary (JSON-friendly), updating the stream state of ``topic``."""
        handler = {
            _BATCH: self._biotac,
            _SKIN: self._skin,
            _SKIN_PART: self._skin_part,
            _DESCRIPTOR: self._descriptor,
            _LAYOUT: self._layout,
            _PREDICTION: self._prediction,
            _LABEL: self._label,
        }.get(msgtype, self._generic)
        out = {"topic": topic, "type": msgtype, "log_time_ns": int(log_ns)}
        out.update(handler(topic, msgtype, msg, log_ns))
        return out

    def _biotac(self, topic: str, msgtype: str, m: Any, log_ns: int) -> dict[str, Any]:
        stamp = _stamp_ns(m.header.stamp)
        n_frames = int(m.frame_count)
        n_el = int(m.electrode_count)
        problems = []
        pac = np.asarray(m.pac)
        frame_off = np.asarray(m.frame_offset_ns, dtype=np.int64)
        if len(m.pac_offset_ns) != pac.size:
            problems.append(f"pac has {pac.size} samples but {len(m.pac_offset_ns)} offsets")
        for name in ("pdc", "tac", "tdc", "frame_offset_ns"):
            if len(getattr(m, name)) != n_frames:
                problems.append(f"{name} has {len(getattr(m, name))} samples, frame_count is {n_frames}")
        electrodes = np.asarray(m.electrodes)
        if n_el <= 0 or electrodes.size != n_frames * n_el:
            problems.append(f"electrodes has {electrodes.size} samples, expected {n_frames} x {n_el}")
            el_channels: dict[str, Any] = {}
        else:
            grid = electrodes.reshape(n_frames, n_el)
            el_channels = {f"e{e + 1}": channel_stats(grid[:, e], INVALID_COUNT) for e in range(n_el)}
        pdc = np.asarray(m.pdc)
        valid_pdc = pdc[pdc != INVALID_COUNT].astype(np.float64)
        force = (valid_pdc - float(m.pdc_tare_counts)) * float(m.force_n_per_count)
        period_ns = int(np.median(np.diff(frame_off))) if frame_off.size > 1 else None
        key = f"{topic}#{m.sensor_name or m.body_part}"
        s = self._stream(key, log_ns)
        lost = self._check_sequence(s, key, int(m.first_frame_sequence), n_frames)
        expected = stamp + n_frames * period_ns if period_ns else None
        stamp_gap = self._check_stamp(s, stamp, expected, (period_ns or 10_000_000) // 2)
        duration_s = None
        if pac.size > 1 and len(m.pac_offset_ns) == pac.size:
            offs = np.asarray(m.pac_offset_ns, dtype=np.int64)
            if offs[-1] > offs[0]:
                duration_s = (offs[-1] - offs[0]) / 1e9
        pac_rate = (pac.size - 1) / duration_s if duration_s else None
        frame_rate = 1e9 / period_ns if period_ns else None
        return {
            "stamp_ns": stamp,
            "sensor_name": m.sensor_name,
            "body_part": m.body_part,
            "serial_number": m.serial_number,
            "chip_select": int(m.chip_select),
            "first_frame_sequence": int(m.first_frame_sequence),
            "frame_count": n_frames,
            "pac_rate_hz": pac_rate,
            "frame_rate_hz": frame_rate,
            "bad_words": int(m.bad_words),
            "force_n": channel_stats(force) if force.size else channel_stats([]),
            "pdc_tare_counts": float(m.pdc_tare_counts),
            "tared_electrodes": len(m.electrode_tare_counts),
            "channels": {
                "pac": channel_stats(pac, INVALID_COUNT),
                "pdc": channel_stats(pdc, INVALID_COUNT),
                "tac": channel_stats(m.tac, INVALID_COUNT),
                "tdc": channel_stats(m.tdc, INVALID_COUNT),
                **el_channels,
            },
            "invalid_samples": int(
                np.count_nonzero(pac == INVALID_COUNT) + np.count_nonzero(pdc == INVALID_COUNT)
                + np.count_nonzero(np.asarray(m.tac) == INVALID_COUNT)
                + np.count_nonzero(np.asarray(m.tdc) == INVALID_COUNT)
                + np.count_nonzero(electrodes == INVALID_COUNT)
            ),
            "lost_frames": lost,
            "stamp_gap_ns": stamp_gap,
            "problems": problems,
            "stream": self._health(s),
        }

    def _skin(self, topic: str, msgtype: str, m: Any, log_ns: int) -> dict[str, Any]:
        stamp = _stamp_ns(m.header.stamp)
        problems = []
        n_acc = len(m.accel_x)
        for name in ("accel_y", "accel_z", "accel_offset_ns"):
            if len(getattr(m, name)) != n_acc:
                problems.append(f"{name} has {len(getattr(m, name))} samples, accel_x has {n_acc}")
        force = np.asarray(m.force)
        n_f = len(m.force_offset_ns)
        channels = {
            "accel_x": channel_stats(m.accel_x, INVALID_ACCEL),
            "accel_y": channel_stats(m.accel_y, INVALID_ACCEL),
            "accel_z": channel_stats(m.accel_z, INVALID_ACCEL),
        }
        force_n: dict[str, Any] = channel_stats([])
        if force.size != 3 * n_f:
            problems.append(f"force has {force.size} samples, expected 3 x {n_f}")
        else:
            grid = force.reshape(n_f, 3)
            tare = np.asarray(m.force_tare_counts, dtype=np.float64)
            for k in range(3):
                channels[f"f{k + 1}"] = channel_stats(grid[:, k], INVALID_COUNT)
            ok = np.all(grid != INVALID_COUNT, axis=1)
            if ok.any():
                newtons = (grid[ok].astype(np.float64) - tare[None, :]) * float(m.force_n_per_count)
                force_n = channel_stats(newtons.mean(axis=1))
        channels["proximity"] = channel_stats(m.proximity, INVALID_COUNT)
        key = f"{topic}#cell{int(m.cell_id)}"
        s = self._stream(key, log_ns)
        lost = self._check_sequence(s, key, int(m.sequence), 1)
        acc_off = np.asarray(m.accel_offset_ns, dtype=np.int64)
        period = int(np.median(np.diff(acc_off))) if acc_off.size > 1 else None
        expected = stamp + n_acc * period if period else None
        stamp_gap = self._check_stamp(s, stamp, expected, (period or 1_000_000) // 2 + 1)
        invalid = sum(c["invalid"] for c in channels.values())
        return {
            "stamp_ns": stamp,
            "cell_id": int(m.cell_id),
            "body_part": m.body_part,
            "sequence": int(m.sequence),
            "accel_samples": n_acc,
            "force_samples": n_f,
            "accel_rate_hz": 1e9 / period if period else None,
            "force_n": force_n,
            "temperature_c": _num(m.temperature_c),
            "bad_frames": int(m.bad_frames),
            "channels": channels,
            "invalid_samples": int(invalid),
            "lost_messages": lost,
            "stamp_gap_ns": stamp_gap,
            "problems": problems,
            "stream": self._health(s),
        }

    def _skin_part(self, topic: str, msgtype: str, m: Any, log_ns: int) -> dict[str, Any]:
        from ..errors import SignalError
        from ..nodes.conversions import skin_part_from_msg
        from ..streams.skin_parts import skin_part_chunks

        stamp = _stamp_ns(m.header.stamp)
        problems: list[str] = []
        cell_ids = [int(c) for c in m.cell_ids]
        channels = {f"accel_{a}": channel_stats(getattr(m, f"accel_{a}"), INVALID_ACCEL) for a in "xyz"}
        force = np.asarray(m.force)
        if force.size % 3 == 0:
            grid = force.reshape(-1, 3)
            for k in range(3):
                channels[f"f{k + 1}"] = channel_stats(grid[:, k], INVALID_COUNT)
        channels["proximity"] = channel_stats(m.proximity, INVALID_COUNT)
        force_n: dict[str, Any] = channel_stats([])
        part = None
        try:
            part = skin_part_from_msg(m)
        except SignalError as exc:
            problems.append(str(exc))
        s = self._stream(topic, log_ns)
        lost = 0
        gaps: list[int] = []
        accel_rate = None
        if part is not None:
            chunks = skin_part_chunks(part)
            forces = np.concatenate([c.force_n for _, c in chunks]) if chunks else np.zeros(0)
            force_n = channel_stats(forces)
            for (cid, chunk), seq in zip(chunks, (int(q) for q in m.sequence)):
                cell_key = f"{topic}#cell{cid}"
                cs = self.streams.setdefault(cell_key, _Stream())
                cs.count += 1
                lost += self._check_sequence(cs, cell_key, seq, 1)
                t = chunk.vibration_t_ns
                period = int(np.median(np.diff(t))) if t.size > 1 else None
                if period and accel_rate is None:
                    accel_rate = 1e9 / period
                if t.size:
                    gap = self._check_stamp(cs, int(t[0]), int(t[-1]) + period if period else None,
                                            (period or 1_000_000) // 2 + 1)
                    if gap is not None:
                        gaps.append(gap)
            s.lost += lost
            s.sequence_gaps += int(lost > 0)
            s.stamp_gaps += sum(1 for g in gaps if g > 0)
            s.stamp_backwards += sum(1 for g in gaps if g < 0)
        invalid = sum(c["invalid"] for c in channels.values())
        return {
            "stamp_ns": stamp,
            "body_part": m.body_part,
            "runs": len(cell_ids),
            "cells": len(set(cell_ids)),
            "cell_ids": cell_ids,
            "accel_samples": len(m.accel_x),
            "force_samples": len(m.force_offset_ns),
            "accel_rate_hz": accel_rate,
            "force_n": force_n,
            "temperature_c": channel_stats(np.asarray(m.temperature_c, dtype=np.float64)),
            "bad_frames": int(np.sum(np.asarray(m.bad_frames, dtype=np.int64))),
            "channels": channels,
            "invalid_samples": int(invalid),
            "lost_messages": lost,
            "stamp_gaps_ns": gaps,
            "problems": problems,
            "stream": self._health(s),
        }

    def _descriptor(self, topic: str, msgtype: str, m: Any, log_ns: int) -> dict[str, Any]:
        consts = self.constants.get(msgtype, [])
        parts = list(m.body_parts)
        problems = []
        for name in ("contact", "cells_in_contact", "cells_total", "mean_force_n", "quality"):
            if len(getattr(m, name)) != len(parts):
                problems.append(f"{name} has {len(getattr(m, name))} entries for {len(parts)} body parts")
        values = np.asarray(m.values, dtype=np.float64)
        known = self.layouts.of(m)
        labels = list(known) if known is not None else [f"value_{k}" for k in range(values.size)]
        if known is None:
            problems.append(f"layout {getattr(m, 'layout_id', '')!r} not seen (its DescriptorLayout is on the "
                            "descriptor topic + '_layout'): values by index")
        elif len(labels) != values.size:
            problems.append(f"{len(labels)} labels for {values.size} values")
        per_part: dict[str, Any] = {}
        for i, part in enumerate(parts):
            q = int(m.quality[i]) if i < len(m.quality) else 0
            per_part[part] = {
                "contact": bool(m.contact[i]) if i < len(m.contact) else None,
                "cells_in_contact": int(m.cells_in_contact[i]) if i < len(m.cells_in_contact) else None,
                "cells_total": int(m.cells_total[i]) if i < len(m.cells_total) else None,
                "mean_force_n": _num(m.mean_force_n[i]) if i < len(m.mean_force_n) else None,
                "quality": q,
                "quality_flags": quality_names(q, consts),
                "values": {},
            }
        other: dict[str, Any] = {}
        for label, value in zip(labels, values.tolist()):
            part, sep, name = label.partition("/")
            target = per_part[part]["values"] if sep and part in per_part else other
            target[name if sep and part in per_part else label] = _num(value)
        n_nonfinite = int(np.count_nonzero(~np.isfinite(values)))
        if n_nonfinite:
            problems.append(f"{n_nonfinite} non-finite values")
        s = self._stream(topic, log_ns)
        w0, w1 = _stamp_ns(m.window_start), _stamp_ns(m.window_end)
        self._check_stamp(s, _stamp_ns(m.header.stamp), None, 0)
        out = {
            "stamp_ns": _stamp_ns(m.header.stamp),
            "robot": m.robot,
            "exploration_id": int(m.exploration_id),
            "window_start_ns": w0,
            "window_end_ns": w1,
            "window_s": (w1 - w0) / 1e9,
            "window_mode": m.window_mode,
            "layout_mode": m.layout_mode,
            "channel_mode": m.channel_mode,
            "frame_id": m.header.frame_id,
            "layout_id": getattr(m, "layout_id", ""),
            "n_values": int(values.size),
            "body_parts": per_part,
            "problems": problems,
            "stream": self._health(s),
        }
        if other:
            out["values"] = other
        return out

    def _layout(self, topic: str, msgtype: str, m: Any, log_ns: int) -> dict[str, Any]:
        """A ``DescriptorLayout``: learned, so the descriptors naming it show their labels."""
        self.layouts.add(m)
        problems = [] if m.layout_id in self.layouts.labels else ["layout_id is not the id of its labels"]
        self._stream(topic, log_ns)
        return {"layout_id": m.layout_id, "robot": m.robot, "layout_mode": m.layout_mode,
                "channel_mode": m.channel_mode, "frame_id": m.header.frame_id, "body_parts": list(m.body_parts),
                "n_labels": len(m.labels), "problems": problems}

    def _prediction(self, topic: str, msgtype: str, m: Any, log_ns: int) -> dict[str, Any]:
        names = list(m.class_names)
        scores = np.asarray(m.scores, dtype=np.float64)
        problems = []
        if len(names) != scores.size:
            problems.append(f"{len(names)} class names for {scores.size} scores")
        k = min(len(names), scores.size)
        order = np.argsort(-scores[:k], kind="stable")[: self.top_k]
        top = [{"class_name": names[i], "score": _num(scores[i])} for i in order]
        margin = _num(scores[order[0]] - scores[order[1]]) if len(order) > 1 else None
        s = self._stream(topic, log_ns)
        self._check_stamp(s, _stamp_ns(m.header.stamp), None, 0)
        return {
            "stamp_ns": _stamp_ns(m.header.stamp),
            "exploration_id": int(m.exploration_id),
            "has_model": bool(m.has_model),
            "class_name": m.class_name,
            "classes": len(names),
            "top": top,
            "margin": margin,
            "model_version": int(m.model_version),
            "updates": int(m.updates),
            "problems": problems,
            "stream": self._health(s),
        }

    def _label(self, topic: str, msgtype: str, m: Any, log_ns: int) -> dict[str, Any]:
        s = self._stream(topic, log_ns)
        return {
            "stamp_ns": _stamp_ns(m.header.stamp),
            "exploration_id": int(m.exploration_id),
            "class_name": m.class_name,
            "stream": self._health(s),
        }

    def _generic(self, topic: str, msgtype: str, m: Any, log_ns: int) -> dict[str, Any]:
        s = self._stream(topic, log_ns)
        return {"message": _shorten(message_to_dict(m)), "stream": self._health(s)}


def _shorten(data: Any, limit: int = 16) -> Any:
    """Long number lists become ``{n, min, max, mean}`` so a generic message stays readable."""
    if isinstance(data, dict):
        return {k: _shorten(v, limit) for k, v in data.items()}
    if isinstance(data, list):
        if len(data) > limit and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in data):
            return channel_stats(np.asarray(data))
        return [_shorten(x, limit) for x in data]
    return data


# ---------------------------------------------------------------------- text


def _f(x: Any, digits: int = 4) -> str:
    if x is None:
        return "-"
    if isinstance(x, float):
        return f"{x:.{digits}g}"
    return str(x)


def _skin_lines(s: dict, lost: str, gap: list[str]) -> list[str]:
    """The force line, the channel lines and the flags of a skin summary (one cell or one body part):
    ``lost`` is the loss flag's text (shown when ``s['lost_messages']``), ``gap`` the stamp-gap flags."""
    f = s["force_n"]
    lines = [f"  force_n    min {_f(f['min']):>8}  max {_f(f['max']):>8}  mean {_f(f['mean']):>9}"]
    lines += [_stats_line(name, st) for name, st in s["channels"].items()]
    flags = []
    if s["invalid_samples"]:
        flags.append(f"INVALID samples {s['invalid_samples']}")
    if s["bad_frames"]:
        flags.append(f"bad frames {s['bad_frames']}")
    if s["lost_messages"]:
        flags.append(lost)
    flags += gap
    if flags:
        lines.append("  !! " + "; ".join(flags))
    return lines


def _stats_line(name: str, st: Mapping[str, Any], width: int = 10) -> str:
    inv = f"  INVALID {st['invalid']}" if st.get("invalid") else ""
    return (f"  {name:<{width}} min {_f(st['min']):>8}  max {_f(st['max']):>8}  "
            f"mean {_f(st['mean']):>9}  n {st['n']}{inv}")


def _stream_line(st: Mapping[str, Any]) -> str:
    bits = [f"msg #{st['messages']}", f"rate {_f(st['rate_hz'])} Hz"]
    if st.get("lost"):
        bits.append(f"LOST {st['lost']} in {st['sequence_gaps']} gaps")
    if st.get("stamp_gaps"):
        bits.append(f"STAMP GAPS {st['stamp_gaps']}")
    if st.get("stamp_backwards"):
        bits.append(f"STAMP BACKWARDS {st['stamp_backwards']}")
    return "  stream: " + ", ".join(bits)


def format_summary(summary: Mapping[str, Any]) -> str:
    """Human-readable text of one summary from :meth:`EchoTracker.summarize`."""
    t = summary["type"]
    head = f"--- {summary['topic']} [{t.split('/')[-1]}] t={summary['log_time_ns'] / 1e9:.6f}"
    lines = [head]
    if t == _BATCH:
        s = summary
        lines.append(
            f"  {s['sensor_name']} ({s['body_part']}) serial={s['serial_number'] or '-'} cs={s['chip_select']} "
            f"frames {s['first_frame_sequence']}..+{s['frame_count']}  stamp {s['stamp_ns'] / 1e9:.6f}  "
            f"PAC {_f(s['pac_rate_hz'])} Hz, frames {_f(s['frame_rate_hz'])} Hz"
        )
        f = s["force_n"]
        lines.append(f"  force_n    min {_f(f['min']):>8}  max {_f(f['max']):>8}  mean {_f(f['mean']):>9}  "
                     f"(tare {s['pdc_tare_counts']:g} counts, {s['tared_electrodes']} electrode tares)")
        for name, st in s["channels"].items():
            lines.append(_stats_line(name, st))
        flags = []
        if s["invalid_samples"]:
            flags.append(f"INVALID_COUNT samples {s['invalid_samples']}")
        if s["bad_words"]:
            flags.append(f"bad words {s['bad_words']}")
        if s["lost_frames"]:
            flags.append(f"LOST {s['lost_frames']} frames before this batch")
        if s["stamp_gap_ns"] is not None:
            flags.append(f"stamp gap {s['stamp_gap_ns'] / 1e6:+.3f} ms")
        if flags:
            lines.append("  !! " + "; ".join(flags))
    elif t == _SKIN:
        s = summary
        lines.append(f"  cell {s['cell_id']} ({s['body_part']}) seq {s['sequence']}  stamp {s['stamp_ns'] / 1e9:.6f}  "
                     f"accel {s['accel_samples']} @ {_f(s['accel_rate_hz'])} Hz, force {s['force_samples']}  "
                     f"T {_f(s['temperature_c'])} C")
        gap = [] if s["stamp_gap_ns"] is None else [f"stamp gap {s['stamp_gap_ns'] / 1e6:+.3f} ms"]
        lines += _skin_lines(s, f"LOST {s['lost_messages']} messages before this one", gap)
    elif t == _SKIN_PART:
        s = summary
        temp = s["temperature_c"]
        lines.append(f"  {s['body_part']}: {s['cells']} cells in {s['runs']} runs  stamp {s['stamp_ns'] / 1e9:.6f}  "
                     f"accel {s['accel_samples']} @ {_f(s['accel_rate_hz'])} Hz, force {s['force_samples']}  "
                     f"T {_f(temp['min'])}..{_f(temp['max'])} C")
        gaps = s["stamp_gaps_ns"][:5]
        gap = [f"stamp gaps {', '.join(f'{g / 1e6:+.3f}' for g in gaps)} ms"] if gaps else []
        lines += _skin_lines(s, f"LOST {s['lost_messages']} cell batches before this message", gap)
    elif t == _DESCRIPTOR:
        s = summary
        lines.append(f"  {s['robot']} exploration {s['exploration_id']}  window {s['window_s']:.3f} s "
                     f"({s['window_mode']}, {s['layout_mode']}, {s['channel_mode']}), {s['n_values']} values")
        for part, p in s["body_parts"].items():
            flags = ",".join(p["quality_flags"]) or "OK"
            lines.append(f"  {part:<12} contact={'yes' if p['contact'] else 'no ':<3} "
                         f"cells {p['cells_in_contact']}/{p['cells_total']}  force {_f(p['mean_force_n'])} N  "
                         f"quality {flags}")
            vals = p["values"]
            if vals:
                items = [f"{k}={_f(v)}" for k, v in vals.items()]
                if len(items) > 12:
                    arr = np.asarray([v for v in vals.values() if v is not None], dtype=np.float64)
                    lines.append(f"      {len(items)} values, min {_f(arr.min() if arr.size else None)} "
                                 f"max {_f(arr.max() if arr.size else None)}; first: {' '.join(items[:6])}")
                else:
                    lines.append("      " + " ".join(items))
    elif t == _PREDICTION:
        s = summary
        if not s["has_model"]:
            lines.append(f"  no model yet (exploration {s['exploration_id']})")
        else:
            top = ", ".join(f"{x['class_name']} {_f(x['score'])}" for x in s["top"])
            lines.append(f"  -> {s['class_name']}  (exploration {s['exploration_id']}, margin {_f(s['margin'])}, "
                         f"{s['classes']} classes, model v{s['model_version']}, {s['updates']} updates)")
            lines.append(f"  top: {top}")
    elif t == _LABEL:
        lines.append(f"  label {summary['class_name']!r} for exploration {summary['exploration_id']}")
    else:
        body = yaml.dump(summary.get("message"), Dumper=_FlowDumper, sort_keys=False, width=100)
        lines.extend("  " + ln for ln in body.rstrip().splitlines())
    for p in summary.get("problems", []):
        lines.append(f"  !! {p}")
    if "stream" in summary:
        lines.append(_stream_line(summary["stream"]))
    return "\n".join(lines)
