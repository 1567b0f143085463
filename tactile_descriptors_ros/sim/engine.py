"""The scene simulator: timeline, per-cell sample streams, effects computed on demand.

:func:`simulate` turns a :class:`~tactile_descriptors_ros.sim.scene.Scene`
into integer ADC counts per cell and stream with int64 ns time stamps
(:class:`SimResult`), plus the ground truth (explorations with their onset
and release times, slip events, injected faults).  Only the effects the
scene declares are computed; each effect is one function in
:data:`EFFECT_FUNCTIONS`, called through :meth:`SimContext.apply`, which
counts the calls (``SimResult.effect_calls``) so a test can prove that an
undeclared effect cost nothing.

Streams per cell kind (rates from the robot description):

* BioTac: ``pac`` (1 channel, 2.2 kHz), and once per frame ``pdc``, ``tac``,
  ``tdc`` and ``electrodes`` (19 channels); 12-bit unsigned counts.
* skin cell: ``accel`` (x, y, z, 1 kHz, signed 10-bit), ``force`` (3
  channels, 250 Hz, 12-bit), ``proximity`` (250 Hz, 12-bit, 0 = far,
  4095 = touching) and ``temperature`` (centi-degrees Celsius, 10 Hz).

Every stream keeps ``seq`` (its sample index on the nominal grid, so a
dropped frame leaves a gap) and ``fault`` (per channel and sample: 0 ok,
:data:`FAULT_PARITY`, :data:`FAULT_CORRUPT`); the byte sources in
:mod:`tactile_descriptors_ros.sim.sources` turn those into real wire errors.
"""

from __future__ import annotations

import math
import zlib
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..core.cell_types import CellType
from ..core.robot import BodyPart
from ..errors import SceneError
from .scene import Exploration, Scene, sensor_defaults, sensor_kind
from .textures import MaterialModel, get_material, render_ar, rescale_ar

__all__ = [
    "Stream",
    "CellRecord",
    "ExplorationTiming",
    "SimResult",
    "SimContext",
    "simulate",
    "iter_simulate",
    "EFFECT_FUNCTIONS",
    "EFFECT_ORDER",
    "FAULT_OK",
    "FAULT_PARITY",
    "FAULT_CORRUPT",
]

FAULT_OK = 0
FAULT_PARITY = 1
FAULT_CORRUPT = 2

#: Time for a finger to reach sliding speed or stop (onset, reversal, end).
ACCEL_S = 0.05
#: Largest relative std of the texture modulation of a skin cell's force sensors
#: (the BioTac PDC statistics it is taken from include the recordings' slow force trend).
MAX_SKIN_FORCE_TEXTURE = 0.1


def _ar_var(dm: Any) -> float:
    from .textures import ar_process_variance

    return ar_process_variance(np.array(dm.pdc_ar), dm.pdc_sigma2)


@dataclass
class Stream:
    """Samples of one stream of one cell.

    Attributes
    ----------
    name : str
    rate_hz : float
    channels : tuple of str
    adc_bits : int
    signed : bool
    t_ns : numpy.ndarray of int64, shape (n,)
    counts : numpy.ndarray of int32, shape (n_channels, n)
    seq : numpy.ndarray of int64, shape (n,)
        Index on the nominal sample grid; gaps are dropped frames or unplugged time.
    fault : numpy.ndarray of int8, shape (n_channels, n)
        0 ok, FAULT_PARITY (the word's parity bit will be wrong on the wire),
        FAULT_CORRUPT (the frame carrying it is corrupt).
    """

    name: str
    rate_hz: float
    channels: tuple[str, ...]
    adc_bits: int
    signed: bool
    t_ns: np.ndarray
    counts: np.ndarray
    seq: np.ndarray
    fault: np.ndarray

    @property
    def valid(self) -> np.ndarray:
        """True where the sample would decode correctly."""
        return self.fault == FAULT_OK

    @property
    def adc_range(self) -> tuple[int, int]:
        if self.signed:
            half = 1 << (self.adc_bits - 1)
            return -half, half - 1
        return 0, (1 << self.adc_bits) - 1


@dataclass
class CellRecord:
    """All streams of one cell."""

    cell_id: int
    name: str
    body_part: str
    kind: str  # "biotac" or "skin"
    streams: dict[str, Stream]
    extra: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class ExplorationTiming:
    """When an exploration happens, in ns on the simulated clock.

    ``onset_ns``: the force ramp starts; ``slide_start_ns``/``slide_end_ns``:
    full force and sliding; ``release_ns``: force back to zero.
    """

    exploration: Exploration
    onset_ns: int
    slide_start_ns: int
    slide_end_ns: int
    release_ns: int

    def to_dict(self) -> dict[str, Any]:
        return {**self.exploration.to_dict(), "onset_ns": self.onset_ns, "slide_start_ns": self.slide_start_ns,
                "slide_end_ns": self.slide_end_ns, "release_ns": self.release_ns}


@dataclass
class SimResult:
    """Output of :func:`simulate`.

    Attributes
    ----------
    scene : Scene
    cells : dict of int to CellRecord
        By cell id, in the robot's order.
    explorations : list of ExplorationTiming
    slip_events : list of dict
        Stick-slip events (time, exploration, body part), when declared.
    faults : dict
        Injected faults: counts per kind and the unplug intervals.
    effect_calls : collections.Counter
        How often each effect function ran (0 for undeclared effects).
    end_ns : int
        Time of the end of the scene.
    stats : dict
        Clipped samples and other counters.
    contact_points : list of dict
        With the ``contact_patch`` effect, where each exploration pressed on
        each body part it touched (the ground truth of contact location):
        ``exploration``, ``body_part``, ``frame_id`` (the body part's link),
        ``xyz`` [m] and ``normal`` in that frame.
    """

    scene: Scene
    cells: dict[int, CellRecord]
    explorations: list[ExplorationTiming]
    slip_events: list[dict[str, Any]]
    faults: dict[str, Any]
    effect_calls: Counter
    end_ns: int
    stats: dict[str, Any]
    contact_points: list[dict[str, Any]] = field(default_factory=list)

    def labels(self) -> list[tuple[int, int, str]]:
        """``(onset_ns, release_ns, label)`` per exploration."""
        return [(e.onset_ns, e.release_ns, e.exploration.label) for e in self.explorations]

    def save_npz(self, path: str | Path) -> None:
        """Write every stream and the ground truth into one ``.npz`` file.

        Keys: ``cell<id>/<stream>/{t_ns,counts,seq,fault}`` and ``ground_truth``
        (a JSON string with the explorations, slip events and faults).
        """
        import json

        arrays: dict[str, Any] = {}
        for cid, cell in self.cells.items():
            for sname, st in cell.streams.items():
                for attr in ("t_ns", "counts", "seq", "fault"):
                    arrays[f"cell{cid}/{sname}/{attr}"] = getattr(st, attr)
        truth = {
            "scene": self.scene.name, "robot": self.scene.robot.name, "seed": self.scene.seed,
            "start_ns": self.scene.start_ns, "end_ns": self.end_ns,
            "explorations": [e.to_dict() for e in self.explorations], "slip_events": self.slip_events,
            "faults": self.faults, "effects": {k: dict(v) for k, v in self.scene.effects.items()},
            "contact_points": self.contact_points,
            "cells": {str(c.cell_id): {"name": c.name, "body_part": c.body_part, "kind": c.kind,
                                        "streams": {s: {"rate_hz": st.rate_hz, "channels": list(st.channels)}
                                                    for s, st in c.streams.items()}}
                      for c in self.cells.values()},
        }
        arrays["ground_truth"] = np.array(json.dumps(truth, default=float))
        np.savez_compressed(path, **arrays)


# --------------------------------------------------------------------------- context


@dataclass
class _Group:
    """Cells of one kind and cell type, rendered together (vectorised over cells)."""

    kind: str
    cell_type: CellType
    parts: list[BodyPart]
    cell_ids: np.ndarray  # (n_cells,)
    cell_part: list[str]  # body part of each cell
    cell_names: list[str]
    extras: list[Mapping[str, Any]]
    sensor: dict[str, float]
    # float working arrays: stream -> (n_cells, n_channels, n_samples)
    data: dict[str, np.ndarray] = field(default_factory=dict)
    rates: dict[str, float] = field(default_factory=dict)
    channels: dict[str, tuple[str, ...]] = field(default_factory=dict)
    bits: dict[str, tuple[int, bool]] = field(default_factory=dict)
    # per-stream per-cell interval of unplugged samples and fault marks, filled by fault effects
    fault: dict[str, np.ndarray] = field(default_factory=dict)
    keep: dict[str, np.ndarray] = field(default_factory=dict)
    # global index of the chunk's first sample, and the scene's sample count, per stream
    base: dict[str, int] = field(default_factory=dict)
    n_total: dict[str, int] = field(default_factory=dict)
    # shared intermediate results between effects: name -> (cell, exploration) -> array
    scratch: dict[str, dict[tuple[int, int], np.ndarray]] = field(default_factory=dict)

    def n_samples(self, stream: str) -> int:
        return self.data[stream].shape[-1]

    def cells_of(self, part: str) -> np.ndarray:
        return np.array([i for i, p in enumerate(self.cell_part) if p == part], dtype=np.intp)


class SimContext:
    """State shared by the effect functions during one :func:`simulate` call."""

    def __init__(self, scene: Scene, timings: list[ExplorationTiming], total_s: float,
                 chunk_t0: float = 0.0, chunk_t1: float | None = None) -> None:
        self.scene = scene
        self.timings = timings
        self.total_s = total_s
        self.chunk_t0 = chunk_t0
        self.chunk_t1 = total_s if chunk_t1 is None else chunk_t1
        self.groups: list[_Group] = []
        self.calls: Counter = Counter()
        self.slip_events: list[dict[str, Any]] = []
        self.faults: dict[str, Any] = {"parity_words": 0, "corrupt_frames": 0, "dropped_frames": 0, "unplugged": []}
        self.stats: dict[str, Any] = {"clipped_samples": 0}
        self._materials: dict[str, MaterialModel] = {}
        self.contact_points: dict[tuple[int, str], dict[str, Any]] = {}
        self._taxels: dict[str, Any] = {}

    def apply(self, name: str) -> None:
        """Run effect ``name`` (counted)."""
        self.calls[name] += 1
        EFFECT_FUNCTIONS[name](self, self.scene.effects[name])

    def rng(self, purpose: str, *keys: int) -> np.random.Generator:
        """A generator that depends only on the seed, the purpose and the keys (not on other effects)."""
        code = zlib.crc32(purpose.encode())
        return np.random.default_rng([self.scene.seed, code, *[int(k) for k in keys]])

    def material(self, name: str) -> MaterialModel:
        if name not in self._materials:
            # A material is its name: the same parametric material in a training scene and a test
            # scene (different scene seeds) must be the same texture, so its seed is fixed.
            self._materials[name] = get_material(name)
        return self._materials[name]

    # -- kinematics (not effects: every effect that needs them asks) ------------

    def taxels(self, part: str):
        """The sensing points of body part ``part`` (:meth:`~...core.geometry.RobotGeometry.taxels`)."""
        if part not in self._taxels:
            robot = self.scene.robot
            self._taxels[part] = robot.geometry.taxels(robot, part)
        return self._taxels[part]

    def contact_point(self, j: int, part: str) -> dict[str, Any]:
        """Where exploration ``j`` presses on body part ``part`` (``contact_patch``; fixed per exploration).

        A point on the segment from a random sensing point (cell or BioTac
        electrode) towards one of its three nearest, at most half way, with
        the normal interpolated alike: inside the skin, between the cells, as
        an object touches it.  The point stays where it is while the part
        slides (the object's surface moves under the skin, not the contact).
        """
        key = (j, part)
        if key not in self.contact_points:
            tax = self.taxels(part)
            r = self.rng("contact_point", j, zlib.crc32(part.encode()))
            k = int(r.integers(len(tax)))
            m, t = k, 0.0
            if len(tax) > 1:
                d = np.linalg.norm(tax.positions - tax.positions[k], axis=1)
                d[k] = np.inf
                nearest = np.argsort(d, kind="stable")[:3]
                m, t = int(nearest[r.integers(len(nearest))]), float(r.uniform(0.0, 0.5))
            xyz = tax.positions[k] + t * (tax.positions[m] - tax.positions[k])
            normal = tax.normals[k] + t * (tax.normals[m] - tax.normals[k])
            normal = normal / np.linalg.norm(normal)
            self.contact_points[key] = {"exploration": j, "body_part": part, "frame_id": tax.frame_id,
                                        "xyz": [float(v) for v in xyz], "normal": [float(v) for v in normal]}
        return self.contact_points[key]

    def patch_weights(self, j: int, part: str, radius_m: float) -> np.ndarray:
        """Gaussian weights (peak 1) of the part's sensing points around exploration ``j``'s contact point."""
        tax = self.taxels(part)
        centre = np.asarray(self.contact_point(j, part)["xyz"])
        d2 = np.sum((tax.positions - centre) ** 2, axis=1)
        return np.exp(-0.5 * d2 / radius_m**2)

    def force_profile(self, timing: ExplorationTiming, t_s: np.ndarray, ramp_s: float) -> np.ndarray:
        """Normalised force 0..1: ramp in, hold, ramp out (trapezoid)."""
        t0 = (timing.onset_ns - self.scene.start_ns) * 1e-9
        t1 = (timing.release_ns - self.scene.start_ns) * 1e-9
        x = np.interp(t_s, [t0, t0 + ramp_s, t1 - ramp_s, t1], [0.0, 1.0, 1.0, 0.0], left=0.0, right=0.0)
        return x

    def motion_profile(self, timing: ExplorationTiming, t_s: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[float]]:
        """Speed factor 0..1 and direction (dx, dy) at ``t_s``, and the slip event times (s).

        Lateral and medial motions go back and forth over ``stroke_m``
        (reversal every ``stroke_m / speed``); circular turns the direction
        once per ``circle_period_s``; a sequence splits the sliding time
        equally.  Speed ramps over :data:`ACCEL_S` at every start, reversal
        and change of motion, where stick-slip events happen.
        """
        e = timing.exploration
        s0 = (timing.slide_start_ns - self.scene.start_ns) * 1e-9
        s1 = (timing.slide_end_ns - self.scene.start_ns) * 1e-9
        speed = np.zeros_like(t_s)
        dx = np.zeros_like(t_s)
        dy = np.zeros_like(t_s)
        events: list[float] = []
        n_seg = len(e.motion)
        seg_len = (s1 - s0) / n_seg
        for k, m in enumerate(e.motion):
            a, b = s0 + k * seg_len, s0 + (k + 1) * seg_len
            sel = (t_s >= a) & (t_s < b)
            tt = t_s[sel] - a
            if m in ("lateral", "medial", "in_hand"):
                stroke = e.stroke_m if m != "in_hand" else min(e.stroke_m, 0.02)
                period = stroke / e.speed_m_s
                n_rev = int(math.floor((b - a) / period - 1e-9))
                reversals = [a + period * (j + 1) for j in range(n_rev)]
                events += [a] + reversals
                sign = np.where(np.floor(tt / period) % 2 == 0, 1.0, -1.0)
                edges = np.array([a, *reversals, b])
                dist = np.min(np.abs(t_s[sel][:, None] - edges[None, :]), axis=1)
                speed[sel] = np.minimum(1.0, dist / ACCEL_S)
                if m == "medial":
                    dy[sel] = sign
                else:
                    dx[sel] = sign
            elif m == "circular":
                events.append(a)
                w = 2.0 * math.pi / e.circle_period_s
                dist = np.minimum(tt, b - t_s[sel])
                speed[sel] = np.minimum(1.0, dist / ACCEL_S)
                dx[sel] = np.cos(w * tt)
                dy[sel] = np.sin(w * tt)
            else:  # rotating_stage, large_object: constant direction
                events.append(a)
                dist = np.minimum(tt, b - t_s[sel])
                speed[sel] = np.minimum(1.0, dist / ACCEL_S)
                if m == "large_object":
                    dy[sel] = 1.0
                else:
                    dx[sel] = 1.0
        return speed, dx, dy, events


# --------------------------------------------------------------------------- timeline


def _timeline(scene: Scene) -> tuple[list[ExplorationTiming], float]:
    ramp = float(scene.effects.get("normal_force", {}).get("ramp_s", 0.15))
    t = scene.lead_in_s
    out = []
    for e in scene.explorations:
        onset = t
        slide_start = onset + ramp
        slide_end = slide_start + e.duration_s
        release = slide_end + ramp
        ns = [scene.start_ns + int(round(x * 1e9)) for x in (onset, slide_start, slide_end, release)]
        out.append(ExplorationTiming(e, *ns))
        t = release + e.pause_s
    return out, t


def _grid_t_ns(start_ns: int, first: int, n: int, rate_hz: float) -> np.ndarray:
    k = np.arange(first, first + n, dtype=np.int64)
    period_ns = 1e9 / rate_hz
    if abs(period_ns - round(period_ns)) < 1e-9:
        return start_ns + k * np.int64(round(period_ns))
    return start_ns + np.floor(k * period_ns + 0.5).astype(np.int64)


def _chunk_index(t_s: float, rate_hz: float) -> int:
    """First sample index at or after ``t_s`` (tolerant to float rounding of the product)."""
    return int(math.ceil(t_s * rate_hz - 1e-6))


def _alloc(ctx: SimContext, g: _Group, name: str, n_total: int, n_channels: int, multiple: int) -> None:
    """Allocate the chunk's part of a stream; ``multiple`` samples per frame (PAC) keep frames whole."""
    rate = g.rates[name] / multiple
    b = min(n_total, _chunk_index(ctx.chunk_t0, rate) * multiple)
    e = min(n_total, _chunk_index(ctx.chunk_t1, rate) * multiple) if ctx.chunk_t1 < ctx.total_s else n_total
    g.base[name] = b
    g.n_total[name] = n_total
    g.data[name] = np.zeros((g.cell_ids.size, n_channels, max(0, e - b)))


def _build_groups(ctx: SimContext) -> None:
    scene = ctx.scene
    robot = scene.robot
    by_type: dict[str, list[BodyPart]] = {}
    for part in robot.body_parts:
        by_type.setdefault(part.cell_type, []).append(part)
    for ct_name, parts in by_type.items():
        kind = sensor_kind(robot, ct_name)
        if kind == "unsupported":
            raise SceneError(f"cell type {ct_name!r}: the simulator renders BioTac (pac + electrodes) and 3-axis skin "
                             "cells only", key="scene.robot", source=scene.source)
        ct = robot.cell_types[ct_name]
        sensor = sensor_defaults(kind)
        sensor.update({k: float(v) for k, v in scene.sensors.get(ct_name, {}).items()})
        cells = [(p.name, c) for p in parts for c in p.cells]
        g = _Group(kind, ct, parts, np.array([c.id for _, c in cells]), [p for p, _ in cells],
                   [c.name for _, c in cells], [c.extra for _, c in cells], sensor)
        n_cells = len(cells)
        if kind == "biotac":
            frame_rate = ct.deformation.rate_hz
            ppf = int(round(ct.vibration.rate_hz / frame_rate))
            if abs(ppf * frame_rate - ct.vibration.rate_hz) > 1e-6 * ct.vibration.rate_hz:
                raise SceneError("the PAC rate must be a whole multiple of the frame rate", key="scene.robot")
            n_frames = int(math.floor(ctx.total_s * frame_rate))
            specs = {
                "pac": (ct.vibration.rate_hz, ("pac",), ct.vibration.adc_bits, n_frames * ppf),
                "pdc": (frame_rate, ("pdc",), ct.deformation.adc_bits, n_frames),
                "tac": (frame_rate, ("tac",), ct.deformation.adc_bits, n_frames),
                "tdc": (frame_rate, ("tdc",), ct.deformation.adc_bits, n_frames),
                "electrodes": (frame_rate, ct.deformation.channels, ct.deformation.adc_bits, n_frames),
            }
            for name, (rate, chans, bits, n) in specs.items():
                g.rates[name], g.channels[name], g.bits[name] = rate, tuple(chans), (bits, False)
                _alloc(ctx, g, name, n, len(chans), ppf if name == "pac" else 1)
            rng = [ctx.rng("baseline", cid) for cid in g.cell_ids]
            spread = sensor["baseline_spread_counts"]
            for name, base in (("pac", "baseline_pac"), ("pdc", "baseline_pdc"), ("tac", "baseline_tac"),
                               ("tdc", "baseline_tdc"), ("electrodes", "baseline_electrode")):
                offs = np.array([r.normal(0.0, spread, len(g.channels[name])) for r in rng])
                g.data[name] += (sensor[base] + offs)[:, :, None]
        else:
            acc, frc = ct.vibration, ct.deformation
            n_acc = int(math.floor(ctx.total_s * acc.rate_hz))
            n_frc = int(math.floor(ctx.total_s * frc.rate_hz))
            t_rate = sensor["temperature_rate_hz"]
            n_tmp = int(math.floor(ctx.total_s * t_rate)) if t_rate > 0 else 0
            specs = {
                "accel": (acc.rate_hz, acc.channels, acc.adc_bits, acc.signed, n_acc),
                "force": (frc.rate_hz, frc.channels, frc.adc_bits, frc.signed, n_frc),
                "proximity": (frc.rate_hz, ("proximity",), 12, False, n_frc),
                "temperature": (t_rate, ("temperature",), 16, True, n_tmp),
            }
            for name, (rate, chans, bits, signed, n) in specs.items():
                g.rates[name], g.channels[name], g.bits[name] = rate, tuple(chans), (bits, signed)
                _alloc(ctx, g, name, n, len(chans), 1)
            grav = np.empty((n_cells, 3))
            for i, cid in enumerate(g.cell_ids):
                r = ctx.rng("baseline", cid)
                v = r.normal(size=3)
                v[2] = abs(v[2]) + 1.0  # cells face mostly outward and up
                grav[i] = v / np.linalg.norm(v) * sensor["gravity_counts"]
                g.data["force"][i] += sensor["baseline_force"] + r.normal(0.0, sensor["baseline_spread_counts"], 3)[:, None]
            g.data["accel"] += grav[:, :, None]
            g.data["temperature"] += sensor["temperature_c"] * 100.0
        for name in g.data:
            g.fault[name] = np.zeros(g.data[name].shape, dtype=np.int8)
            g.keep[name] = np.ones((n_cells, g.data[name].shape[-1]), dtype=bool)
        ctx.groups.append(g)


def _sample_range(ctx: SimContext, timing: ExplorationTiming, rate: float, n_total: int,
                  margin_s: float = 0.0) -> tuple[int, int]:
    """Global sample range [g0, g1) of a contact on a stream's grid (not clipped to the chunk)."""
    t0 = (timing.onset_ns - ctx.scene.start_ns) * 1e-9 - margin_s
    t1 = (timing.release_ns - ctx.scene.start_ns) * 1e-9 + margin_s
    return max(0, int(math.ceil(t0 * rate))), min(n_total, int(math.floor(t1 * rate)) + 1)


def _times(g0: int, g1: int, rate: float) -> np.ndarray:
    return np.arange(g0, g1, dtype=np.float64) / rate


def _add(g: _Group, name: str, idx: Any, g0: int, values: np.ndarray, channel: int | None = None) -> None:
    """Add ``values`` (last axis = global samples g0..) into the chunk's part of stream ``name``.

    ``idx`` selects cells (an index array or one int); ``channel`` one channel (else all).
    """
    base = g.base[name]
    n = g.data[name].shape[-1]
    lo, hi = max(g0, base), min(g0 + values.shape[-1], base + n)
    if hi <= lo:
        return
    if channel is None:
        g.data[name][idx, :, lo - base : hi - base] += values[..., lo - g0 : hi - g0]
    else:
        g.data[name][idx, channel, lo - base : hi - base] += values[..., lo - g0 : hi - g0]


def _contacts(ctx: SimContext, g: _Group, margin_s: float = 0.5):
    """Yield (exploration index, timing, body part, cell indices, force_n, sliding) overlapping this chunk."""
    for j, timing in enumerate(ctx.timings):
        t0 = (timing.onset_ns - ctx.scene.start_ns) * 1e-9
        t1 = (timing.release_ns - ctx.scene.start_ns) * 1e-9
        if t1 + margin_s < ctx.chunk_t0 or t0 - margin_s > ctx.chunk_t1:
            continue
        e = timing.exploration
        for part, force in e.part_force_n.items():
            idx = g.cells_of(part)
            if idx.size:
                yield j, timing, part, idx, force, part in e.body_parts


# --------------------------------------------------------------------------- effects


def _ramp(ctx: SimContext) -> float:
    return float(ctx.scene.effects.get("normal_force", {}).get("ramp_s", 0.15))


def _load_factors(ctx: SimContext, g: _Group, j: int, idx: np.ndarray, spread: float) -> np.ndarray:
    """Per-cell share of a body part's force (mean 1), fixed per exploration.

    With the ``contact_patch`` effect a skin body part's force is the total
    pressed at the exploration's contact point, shared among the cells by a
    Gaussian of their distance from it (``radius_m``); otherwise it is every
    cell's mean force, shared by random load factors (spread ``spread``).
    """
    if idx.size == 1:
        return np.ones(1)
    if ctx.scene.has("contact_patch") and g.kind == "skin":
        part = g.cell_part[int(idx[0])]
        w = ctx.patch_weights(j, part, float(ctx.scene.effects["contact_patch"]["radius_m"]))
        return w / w.sum()
    r = ctx.rng("load", j, int(g.cell_ids[idx[0]]))
    f = np.clip(1.0 + spread * r.standard_normal(idx.size), 0.2, None)
    return f / f.mean()


def effect_normal_force(ctx: SimContext, p: Mapping[str, Any]) -> None:
    """Normal force ramped in and out (contact onset and release): PDC, or the skin cell's three force sensors.

    BioTac PDC rises by ``F / n_per_count`` counts plus the material's
    fitted PDC fluctuation (AR(2), scaled with the force); a skin body part's
    force is shared among its cells (load factors, mean 1, spread
    ``load_spread``) and among each cell's three sensors.
    """
    ramp = float(p["ramp_s"])
    for g in ctx.groups:
        n_per = g.cell_type.force.n_per_count
        key = "pdc" if g.kind == "biotac" else "force"
        rate = g.rates[key]
        fluct = g.scratch.setdefault("pdc_fluct", {})
        shares = g.scratch.setdefault("force_share", {})
        for j, timing, part, idx, force, _sliding in _contacts(ctx, g):
            g0, g1 = _sample_range(ctx, timing, rate, g.n_total[key])
            if g1 <= g0:
                continue
            env = ctx.force_profile(timing, _times(g0, g1, rate), ramp)
            loads = _load_factors(ctx, g, j, idx, float(p["load_spread"]))
            if g.kind == "biotac":
                mat = ctx.material(timing.exploration.material)
                dm = mat.deformation
                a, s2 = rescale_ar(np.array(dm.pdc_ar), dm.pdc_sigma2, dm.fs_hz / rate)
                r = ctx.rng("pdc", j, int(g.cell_ids[idx[0]]))
                fl = render_ar(a, s2, g1 - g0, r, rows=idx.size) * (force / mat.reference_force_n) * env
                _add(g, key, idx, g0, (force * loads[:, None] * env) / n_per + fl, channel=0)
                for k, ci in enumerate(idx):
                    fluct[(int(ci), j)] = (g0, fl[k])
                shares[(part, j)] = loads[:, None]
            else:
                r = ctx.rng("sensor_share", j, int(g.cell_ids[idx[0]]))
                share = np.clip(1.0 + 0.15 * r.standard_normal((idx.size, 3)), 0.3, None)
                share /= share.mean(axis=1, keepdims=True)
                share *= loads[:, None]
                _add(g, key, idx, g0, (force * share[:, :, None] * env[None, None, :]) / n_per)
                shares[(part, j)] = share


def effect_texture_vibration(ctx: SimContext, p: Mapping[str, Any]) -> None:
    """Texture vibration while sliding: the material's AR model at the exploration's speed and the sensor's rate.

    BioTac PAC gets the AR process plus the material's mean PAC level; a skin
    cell's accelerometer gets it on every axis (``accel_gain`` counts per PAC
    count), the tangential axes weighted by the sliding direction (30 % floor).
    The amplitude follows ``(F/F_ref)**force_exponent (v/v_ref)**speed_exponent``
    with the instantaneous force and speed, so it is zero in static contact.
    Holding (non-sliding) contacts get none.
    """
    ramp = _ramp(ctx)
    for g in ctx.groups:
        key = "pac" if g.kind == "biotac" else "accel"
        rate = g.rates[key]
        frame_means = g.scratch.setdefault("pac_frame_mean", {})
        for j, timing, _part, idx, force, sliding in _contacts(ctx, g):
            if not sliding:
                continue
            g0, g1 = _sample_range(ctx, timing, rate, g.n_total[key])
            if g1 <= g0:
                continue
            e = timing.exploration
            mat = ctx.material(e.material)
            vib = mat.vibration
            t_s = _times(g0, g1, rate)
            env = ctx.force_profile(timing, t_s, ramp)
            speed, dx, dy, _ = ctx.motion_profile(timing, t_s)
            gain = ((force * env / mat.reference_force_n) ** vib.force_exponent
                    * (speed * e.speed_m_s / mat.reference_speed_m_s) ** vib.speed_exponent) * float(p["gain"])
            a, s2 = vib.at(rate, e.speed_m_s, mat.reference_speed_m_s)
            r = ctx.rng("texture", j, int(g.cell_ids[idx[0]]))
            if g.kind == "biotac":
                x = render_ar(a, s2, g1 - g0, r, rows=idx.size)
                sig = (x + vib.mean_counts) * gain[None, :]
                _add(g, key, idx, g0, sig, channel=0)
                ppf = int(round(rate / g.rates["pdc"]))
                f0 = -(-g0 // ppf)
                f1 = g1 // ppf
                if f1 > f0:
                    fm = sig[:, f0 * ppf - g0 : f1 * ppf - g0].reshape(idx.size, -1, ppf).mean(axis=2)
                    for k, ci in enumerate(idx):
                        frame_means[(int(ci), j)] = (f0, fm[k])
            else:
                x = render_ar(a, s2, g1 - g0, r, rows=idx.size * 3).reshape(idx.size, 3, -1)
                axis_gain = np.stack([0.3 + 0.7 * np.abs(dx), 0.3 + 0.7 * np.abs(dy), np.ones_like(dx)])
                x *= (gain * g.sensor["accel_gain"])[None, None, :] * axis_gain[None]
                _add(g, key, idx, g0, x)


def effect_electrode_deformation(ctx: SimContext, p: Mapping[str, Any]) -> None:
    """Slow deformation: BioTac electrodes (fitted mean, coupling to PAC and PDC, AR(2) residual), skin force texture.

    A BioTac electrode ``e`` moves by ``mean_e F/F_ref + c_e (P - P_mean) +
    s_e dPDC + r_e`` in contact (``P`` the PAC frame mean, when texture
    vibration is simulated; ``dPDC`` the PDC fluctuation, when normal force
    is).  A skin cell's force sensors get the material's relative PDC
    fluctuation as a multiplicative texture while sliding.
    """
    ramp = _ramp(ctx)
    gain_all = float(p["gain"])
    for g in ctx.groups:
        if g.kind == "biotac":
            rate = g.rates["electrodes"]
            fm = g.scratch.get("pac_frame_mean", {})
            fl = g.scratch.get("pdc_fluct", {})
            n_el = len(g.channels["electrodes"])
            for j, timing, _part, idx, force, _sliding in _contacts(ctx, g):
                g0, g1 = _sample_range(ctx, timing, rate, g.n_total["electrodes"])
                if g1 <= g0:
                    continue
                mat = ctx.material(timing.exploration.material)
                dm = mat.deformation
                if dm.n_electrodes < n_el:
                    raise SceneError(f"material {mat.name!r} models {dm.n_electrodes} electrodes, the robot has {n_el}",
                                     key="explorations.material")
                env = ctx.force_profile(timing, _times(g0, g1, rate), ramp)
                rel = force / mat.reference_force_n
                mean = np.array(dm.electrode_mean[:n_el])[:, None] * rel * env[None, :]
                for ci in idx:
                    r = ctx.rng("electrodes", j, int(g.cell_ids[ci]))
                    resid = np.stack([render_ar(np.array(dm.electrode_ar[k]), dm.electrode_sigma2[k], g1 - g0, r)[0]
                                      for k in range(n_el)])
                    val = mean + resid * math.sqrt(rel) * env[None, :]
                    if (int(ci), j) in fm:
                        f0, pm = fm[(int(ci), j)]
                        full = np.zeros(g1 - g0)
                        lo, hi = max(f0, g0), min(f0 + pm.size, g1)
                        if hi > lo:
                            seg = pm[lo - f0 : hi - f0]
                            full[lo - g0 : hi - g0] = seg - seg.mean()
                        val += np.array(dm.electrode_pac_coupling[:n_el])[:, None] * full[None, :]
                    if (int(ci), j) in fl:
                        q0, pf = fl[(int(ci), j)]
                        full = np.zeros(g1 - g0)
                        lo, hi = max(q0, g0), min(q0 + pf.size, g1)
                        if hi > lo:
                            full[lo - g0 : hi - g0] = pf[lo - q0 : hi - q0]
                        val += np.array(dm.electrode_pdc_slope[:n_el])[:, None] * full[None, :]
                    _add(g, "electrodes", int(ci), g0, gain_all * val)
        else:
            rate = g.rates["force"]
            n_per = g.cell_type.force.n_per_count
            for j, timing, part, idx, force, sliding in _contacts(ctx, g):
                if not sliding:
                    continue
                g0, g1 = _sample_range(ctx, timing, rate, g.n_total["force"])
                if g1 <= g0:
                    continue
                e = timing.exploration
                mat = ctx.material(e.material)
                dm = mat.deformation
                a, s2 = rescale_ar(np.array(dm.pdc_ar), dm.pdc_sigma2, (e.speed_m_s / mat.reference_speed_m_s) * dm.fs_hz / rate)
                r = ctx.rng("skin_deformation", j, int(g.cell_ids[idx[0]]))
                rel_std = math.sqrt(_ar_var(dm)) / max(dm.pdc_mean_counts, 1.0)
                cap = min(1.0, MAX_SKIN_FORCE_TEXTURE / rel_std) if rel_std > 0 else 1.0
                relfl = render_ar(a, s2, g1 - g0, r, rows=idx.size * 3).reshape(idx.size, 3, -1)
                relfl *= cap / max(dm.pdc_mean_counts, 1.0)
                t_s = _times(g0, g1, rate)
                env = ctx.force_profile(timing, t_s, ramp)
                speed, _, _, _ = ctx.motion_profile(timing, t_s)
                # relative to each cell's force: every cell's mean force is F by default, its share of F
                # with contact_patch (untouched cells feel no texture)
                scale = force if not ctx.scene.has("contact_patch") else \
                    force * g.scratch.get("force_share", {}).get((part, j), np.ones((idx.size, 3)))[:, :, None]
                _add(g, "force", idx, g0, gain_all * relfl * (scale / n_per) * (env * speed)[None, None, :])


def effect_stick_slip(ctx: SimContext, p: Mapping[str, Any]) -> None:
    """Stick-slip at motion onset and reversal: a decaying burst in the vibration, a dip in the force.

    The strength is ``gain (mu_s/mu_k - 1) F`` with the material's friction
    ratio; the burst is a ``frequency_hz`` sine decaying over ``decay_s``
    (400 PAC counts or 60 accelerometer counts per unit strength), the force
    dips by up to 30 % of the friction excess (only where normal force is
    simulated).  Every event is listed in ``SimResult.slip_events``.
    """
    gain = float(p["gain"])
    decay = float(p["decay_s"])
    f_hz = float(p["frequency_hz"])
    for g in ctx.groups:
        vkey = "pac" if g.kind == "biotac" else "accel"
        fkey = "pdc" if g.kind == "biotac" else "force"
        shares = g.scratch.get("force_share", {})
        n_per = g.cell_type.force.n_per_count
        for j, timing, part, idx, force, sliding in _contacts(ctx, g):
            if not sliding:
                continue
            mat = ctx.material(timing.exploration.material)
            excess = max(mat.stick_slip_ratio - 1.0, 0.0)
            strength = gain * excess * force
            if strength <= 0:
                continue
            t_first = np.array([(timing.slide_start_ns - ctx.scene.start_ns) * 1e-9])
            _, _, _, events = ctx.motion_profile(timing, t_first)
            for t_ev in events:
                if ctx.chunk_t0 <= t_ev < ctx.chunk_t1:
                    ctx.slip_events.append({"exploration": j, "body_part": part,
                                            "t_ns": ctx.scene.start_ns + int(round(t_ev * 1e9)), "strength": strength})
                rate = g.rates[vkey]
                g0 = int(math.ceil(t_ev * rate))
                tt = _times(g0, g0 + int(math.ceil(6 * decay * rate)), rate) - t_ev
                amp = 400.0 if g.kind == "biotac" else 60.0
                burst = amp * strength * np.exp(-tt / decay) * np.sin(2 * math.pi * f_hz * tt)
                _add(g, vkey, idx, g0, np.broadcast_to(burst, (idx.size, g.data[vkey].shape[1], burst.size)).copy())
                if (part, j) in shares:
                    rate = g.rates[fkey]
                    g0 = int(math.ceil(t_ev * rate))
                    tt = _times(g0, g0 + int(math.ceil(6 * decay * rate)), rate) - t_ev
                    shape = -0.3 * excess * gain * force / n_per * np.exp(1.0 - tt / decay) * (tt / decay)
                    share = shares[(part, j)]  # (cells, channels)
                    _add(g, fkey, idx, g0, share[:, :, None] * shape[None, None, :])


def effect_proximity(ctx: SimContext, p: Mapping[str, Any]) -> None:
    """Skin proximity: 0 (far) to full scale (touching), ``lead_s`` before contact to ``lead_s`` after release."""
    lead = float(p["lead_s"])
    for g in ctx.groups:
        if g.kind != "skin":
            continue
        rate = g.rates["proximity"]
        full = float((1 << g.bits["proximity"][0]) - 1)
        base, n = g.base["proximity"], g.data["proximity"].shape[-1]
        for _j, timing, _part, idx, _force, _sliding in _contacts(ctx, g, margin_s=lead + 0.5):
            g0, g1 = _sample_range(ctx, timing, rate, g.n_total["proximity"], margin_s=lead)
            lo, hi = max(g0, base), min(g1, base + n)
            if hi <= lo:
                continue
            t0 = (timing.onset_ns - ctx.scene.start_ns) * 1e-9
            t1 = (timing.release_ns - ctx.scene.start_ns) * 1e-9
            env = np.interp(_times(lo, hi, rate), [t0 - lead, t0, t1, t1 + lead], [0.0, 1.0, 1.0, 0.0])
            cur = g.data["proximity"][idx, 0, lo - base : hi - base]
            g.data["proximity"][idx, 0, lo - base : hi - base] = np.maximum(cur, full * env[None, :])


def effect_contact_patch(ctx: SimContext, p: Mapping[str, Any]) -> None:
    """Press at a place: the ground truth of contact location (``SimResult.contact_points``).

    Each exploration presses each body part it touches at one point
    (:meth:`SimContext.contact_point`).  A skin body part's force is shared
    among its cells by their distance from that point (see
    :func:`_load_factors`, applied by ``normal_force``); a BioTac's
    electrodes near it rise by ``electrode_counts_per_n`` counts per newton
    times a Gaussian of their distance (``biotac_radius_m``), on top of the
    fitted electrode response, following the force ramp.
    """
    gain = float(p["electrode_counts_per_n"])
    radius = float(p["biotac_radius_m"])
    ramp = _ramp(ctx)
    for g in ctx.groups:
        for j, timing, part, idx, force, _sliding in _contacts(ctx, g):
            ctx.contact_point(j, part)
            if g.kind != "biotac":
                continue
            rate = g.rates["electrodes"]
            g0, g1 = _sample_range(ctx, timing, rate, g.n_total["electrodes"])
            if g1 <= g0:
                continue
            tax = ctx.taxels(part)
            w = ctx.patch_weights(j, part, radius)
            env = ctx.force_profile(timing, _times(g0, g1, rate), ramp)
            rise = np.zeros((len(g.channels["electrodes"]), g1 - g0))
            for k, channels in enumerate(tax.channels):
                for ch in channels:
                    rise[ch] += gain * force * w[k] * env
            _add(g, "electrodes", int(idx[0]), g0, rise)


def effect_bias_drift(ctx: SimContext, p: Mapping[str, Any]) -> None:
    """Slow bias drift: per channel a linear drift of random slope (std ``counts_per_s``) from the scene start."""
    rate_cps = float(p["counts_per_s"])
    for g in ctx.groups:
        for name, arr in g.data.items():
            if name in ("temperature", "proximity"):
                continue
            t = _times(g.base[name], g.base[name] + arr.shape[-1], g.rates[name])
            slope = np.stack([ctx.rng("drift", int(cid), zlib.crc32(name.encode())).normal(0.0, rate_cps, arr.shape[1])
                              for cid in g.cell_ids])
            arr += slope[:, :, None] * t[None, None, :]


#: Streams that get sensor noise unless ``per_stream`` says otherwise.
_NOISY = ("pac", "pdc", "tac", "tdc", "electrodes", "accel", "force")


def effect_sensor_noise(ctx: SimContext, p: Mapping[str, Any]) -> None:
    """White Gaussian noise of ``std_counts`` counts.

    ``per_stream[name]`` overrides it; proximity and temperature get noise only when named.
    """
    default = float(p["std_counts"])
    per = p.get("per_stream", {}) or {}
    for g in ctx.groups:
        for name, arr in g.data.items():
            std = float(per.get(name, default if name in _NOISY else 0.0))
            if std <= 0:
                continue
            r = ctx.rng("noise", int(g.cell_ids[0]), zlib.crc32(name.encode()), g.base[name])
            arr += r.standard_normal(arr.shape, dtype=np.float32) * np.float32(std)


def effect_adc(ctx: SimContext, p: Mapping[str, Any]) -> None:
    """ADC quantisation (round to counts) and clipping to the converter's range; clipped samples are counted."""
    for g in ctx.groups:
        for name, arr in g.data.items():
            bits, signed = g.bits[name]
            lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
            np.rint(arr, out=arr)
            clipped = int(np.count_nonzero(arr < lo) + np.count_nonzero(arr > hi))
            ctx.stats["clipped_samples"] += clipped
            if clipped:
                ctx.stats.setdefault("clipped_by_stream", Counter())[name] += clipped
            np.clip(arr, lo, hi, out=arr)


def _frame_keys(g: _Group) -> list[list[str]]:
    """Streams that travel in one frame: BioTac: all (one SPI frame); skin: each stream its own frames."""
    if g.kind == "biotac":
        return [["pdc", "tac", "tdc", "electrodes", "pac"]]
    return [[name] for name in g.data]


def _frames_to_samples(g: _Group, name: str, frame_mask: np.ndarray) -> np.ndarray:
    """Expand a per-frame mask (cells, frames) to the samples of stream ``name``."""
    if g.kind == "biotac" and name == "pac":
        ppf = int(round(g.rates["pac"] / g.rates["pdc"]))
        return np.repeat(frame_mask, ppf, axis=-1)
    return frame_mask


def _frame_draws(ctx: SimContext, g: _Group, purpose: str, key: str, prob: float) -> np.ndarray:
    n = g.data[key].shape[-1]
    r = ctx.rng(purpose, int(g.cell_ids[0]), zlib.crc32(key.encode()), g.base[key])
    return r.random((g.cell_ids.size, n)) < prob


def effect_dropped_frames(ctx: SimContext, p: Mapping[str, Any]) -> None:
    """Frames lost on the bus with probability ``probability``: their samples are missing (gaps in ``seq``)."""
    prob = float(p["probability"])
    for g in ctx.groups:
        for keys in _frame_keys(g):
            drop = _frame_draws(ctx, g, "drop", keys[0], prob)
            ctx.faults["dropped_frames"] += int(drop.sum())
            for name in keys:
                g.keep[name] &= ~_frames_to_samples(g, name, drop)


def effect_bad_parity(ctx: SimContext, p: Mapping[str, Any]) -> None:
    """BioTac words whose parity bit is wrong on the wire (probability per word)."""
    prob = float(p["probability"])
    for g in ctx.groups:
        if g.kind != "biotac":
            continue
        for name, f in g.fault.items():
            r = ctx.rng("parity", int(g.cell_ids[0]), zlib.crc32(name.encode()), g.base[name])
            bad = r.random(f.shape) < prob
            f[bad & (f == FAULT_OK)] = FAULT_PARITY
            ctx.faults["parity_words"] += int(bad.sum())


def effect_corrupt_frames(ctx: SimContext, p: Mapping[str, Any]) -> None:
    """Whole frames corrupted on the wire (probability per frame): every sample in them is marked."""
    prob = float(p["probability"])
    for g in ctx.groups:
        for keys in _frame_keys(g):
            bad = _frame_draws(ctx, g, "corrupt", keys[0], prob)
            ctx.faults["corrupt_frames"] += int(bad.sum())
            for name in keys:
                m = _frames_to_samples(g, name, bad)
                g.fault[name][np.broadcast_to(m[:, None, :], g.fault[name].shape)] = FAULT_CORRUPT


def effect_unplug(ctx: SimContext, p: Mapping[str, Any]) -> None:
    """A cell unplugged at ``at_s`` for ``for_s``: no samples; plugged back with its baseline shifted by ``rebias_counts``."""
    for ev in p["events"]:
        t0, t1 = ev["at_s"], ev["at_s"] + ev["for_s"]
        for g in ctx.groups:
            hit = np.nonzero(g.cell_ids == ev["cell"])[0]
            if not hit.size:
                continue
            i = int(hit[0])
            for name, arr in g.data.items():
                t = _times(g.base[name], g.base[name] + arr.shape[-1], g.rates[name])
                g.keep[name][i] &= ~((t >= t0) & (t < t1))
                if ev["rebias_counts"] and name not in ("temperature", "proximity"):
                    sign = ctx.rng("rebias", ev["cell"], zlib.crc32(name.encode())).choice([-1.0, 1.0], arr.shape[1])
                    arr[i][:, t >= t1] += sign[:, None] * ev["rebias_counts"]
        if t1 > ctx.chunk_t0 and t0 < ctx.chunk_t1:
            ctx.faults["unplugged"].append({"cell": ev["cell"], "from_ns": ctx.scene.start_ns + int(round(t0 * 1e9)),
                                             "to_ns": ctx.scene.start_ns + int(round(t1 * 1e9))})


#: Effect functions by name; :meth:`SimContext.apply` calls (and counts) them.
EFFECT_FUNCTIONS: dict[str, Callable[[SimContext, Mapping[str, Any]], None]] = {
    "normal_force": effect_normal_force,
    "texture_vibration": effect_texture_vibration,
    "electrode_deformation": effect_electrode_deformation,
    "contact_patch": effect_contact_patch,
    "stick_slip": effect_stick_slip,
    "proximity": effect_proximity,
    "bias_drift": effect_bias_drift,
    "unplug": effect_unplug,
    "sensor_noise": effect_sensor_noise,
    "adc": effect_adc,
    "dropped_frames": effect_dropped_frames,
    "bad_parity": effect_bad_parity,
    "corrupt_frames": effect_corrupt_frames,
}

#: Order in which declared effects are applied (signal first, then the converter, then the bus).
EFFECT_ORDER: tuple[str, ...] = tuple(EFFECT_FUNCTIONS)


# --------------------------------------------------------------------------- entry point


def simulate(scene: Scene, explorations: range | None = None) -> SimResult:
    """Render a scene (or a chunk of it) into per-cell integer sample streams and ground truth.

    Parameters
    ----------
    scene : Scene
        From :func:`~tactile_descriptors_ros.sim.scene.load_scene`.
    explorations : range, optional
        Only the time span of these explorations (from the first one's onset,
        or the scene start for the first, to the next one's onset, or the
        scene end): a chunk.  Chunks of consecutive ranges join seamlessly
        (see :func:`iter_simulate`).  Default: the whole scene.

    Returns
    -------
    SimResult

    Raises
    ------
    SceneError
        If a value falls outside the ADC range while the scene does not
        declare the ``adc`` effect (nothing is clipped silently), or for an
        unknown material.

    Notes
    -----
    Deterministic: every random draw comes from a generator keyed by the
    scene's seed, a purpose, and the cell and exploration (texture, force,
    electrodes) or the chunk's first sample (noise, bus faults), so the same
    scene, seed and chunking give identical output, and declaring one more
    effect does not change what the others draw.
    """
    timings, total_s = _timeline(scene)
    n_exp = len(timings)
    rng_ = explorations if explorations is not None else range(n_exp)
    if rng_.step != 1 or rng_.start < 0 or rng_.stop > n_exp or rng_.start >= rng_.stop:
        raise SceneError(f"explorations must be a non-empty range within 0..{n_exp}", key="explorations")
    t0 = 0.0 if rng_.start == 0 else (timings[rng_.start].onset_ns - scene.start_ns) * 1e-9
    t1 = total_s if rng_.stop == n_exp else (timings[rng_.stop].onset_ns - scene.start_ns) * 1e-9
    ctx = SimContext(scene, timings, total_s, t0, t1)
    for j in rng_:  # fail early on unknown materials
        ctx.material(timings[j].exploration.material)
    _build_groups(ctx)
    for name in EFFECT_ORDER:
        if name in scene.effects:
            ctx.apply(name)
    if "adc" not in scene.effects:
        for g in ctx.groups:
            for name, arr in g.data.items():
                bits, signed = g.bits[name]
                lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
                np.rint(arr, out=arr)
                if arr.size and (arr.min() < lo or arr.max() > hi):
                    raise SceneError(f"stream {name!r} leaves the {bits}-bit ADC range [{lo}, {hi}] "
                                     f"(values {arr.min():.0f}..{arr.max():.0f}); declare the 'adc' effect to clip",
                                     key="effects.adc", source=scene.source)
    cells: dict[int, CellRecord] = {}
    for g in ctx.groups:
        stamps: dict[str, np.ndarray] = {}
        for name, arr in g.data.items():
            b, n = g.base[name], arr.shape[-1]
            if g.kind == "biotac" and name == "pac":
                ppf = int(round(g.rates["pac"] / g.rates["pdc"]))
                stamps[name] = _pac_times(scene.start_ns, b // ppf, n // ppf, g.rates["pdc"], ppf)
            else:
                stamps[name] = _grid_t_ns(scene.start_ns, b, n, g.rates[name])
        counts = {name: arr.astype(np.int32) for name, arr in g.data.items()}
        for i, cid in enumerate(g.cell_ids):
            streams = {}
            for name, arr in counts.items():
                b, n = g.base[name], arr.shape[-1]
                keep = g.keep[name][i]
                full = bool(keep.all())
                seq = np.arange(b, b + n, dtype=np.int64)
                bits, signed = g.bits[name]
                streams[name] = Stream(
                    name, g.rates[name], g.channels[name], bits, signed,
                    stamps[name] if full else stamps[name][keep],
                    arr[i] if full else arr[i][:, keep],
                    seq if full else seq[keep],
                    g.fault[name][i] if full else g.fault[name][i][:, keep],
                )
            cells[int(cid)] = CellRecord(int(cid), g.cell_names[i], g.cell_part[i], g.kind, streams, g.extras[i])
    order = {c.id: k for k, c in enumerate(c for p in scene.robot.body_parts for c in p.cells)}
    cells = dict(sorted(cells.items(), key=lambda kv: order[kv[0]]))
    chunk_timings = [timings[j] for j in rng_]
    end_ns = scene.start_ns + int(round(t1 * 1e9))
    stats = dict(ctx.stats)
    stats["chunk_start_ns"] = scene.start_ns + int(round(t0 * 1e9))
    points = [v for (j, _), v in sorted(ctx.contact_points.items()) if j in rng_]
    return SimResult(scene, cells, chunk_timings, ctx.slip_events, ctx.faults, ctx.calls, end_ns, stats, points)


def iter_simulate(scene: Scene, max_chunk_s: float = 30.0):
    """Simulate a long scene chunk by chunk (whole explorations, about ``max_chunk_s`` each).

    Yields :class:`SimResult` objects whose streams follow each other
    without gap or overlap; memory stays bounded for protocol scenes of
    thousands of explorations.
    """
    timings, total_s = _timeline(scene)
    start = 0
    while start < len(timings):
        stop = start + 1
        t_begin = 0.0 if start == 0 else (timings[start].onset_ns - scene.start_ns) * 1e-9
        while stop < len(timings) and (timings[stop].onset_ns - scene.start_ns) * 1e-9 - t_begin < max_chunk_s:
            stop += 1
        yield simulate(scene, range(start, stop))
        start = stop


def _pac_times(start_ns: int, first_frame: int, n_frames: int, frame_rate_hz: float, ppf: int) -> np.ndarray:
    """PAC sample times: spread evenly over each frame, frames on the frame grid."""
    frames = _grid_t_ns(start_ns, first_frame, n_frames, frame_rate_hz)
    period = 1e9 / frame_rate_hz
    offsets = np.floor(np.arange(ppf) * period / ppf + 0.5).astype(np.int64)
    return (frames[:, None] + offsets[None, :]).ravel()
