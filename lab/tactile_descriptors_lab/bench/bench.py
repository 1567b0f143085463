"""Timing the descriptor path against a naive per-signal baseline (``tactile bench``).

What is timed:

* **package** -- :func:`~tactile_descriptors_ros.core.aggregation.describe_window`
  on one window (contact gate, per-cell quantities through the compiled
  kernel of :mod:`tactile_descriptors_ros.core.fast`, per-body-part
  averages, whole-robot layout);
* **kernel** -- the per-cell quantities alone
  (:func:`~tactile_descriptors_ros.core.fast.cell_quantities`);
* **reference** -- the same quantities computed as the paper states them
  (V expanded by zero-order hold, broadcast pairs, ranks of the expanded
  series; :func:`~tactile_descriptors_ros.core.descriptors.cell_quantities`),
  checked against the kernel before anything is timed;
* **baseline** -- what usual code does: per cell and per signal, a plain
  numpy Hjorth, and ``scipy.stats.pearsonr`` / ``spearmanr`` of every S
  channel with every V channel held onto S's time base; the same contact
  gate and averages.

The compiled backend (:func:`~tactile_descriptors_ros.core.fast.backend`)
is loaded or compiled before any timing, and that time is reported.  ``BenchReport.targets`` says
which targets are met; the shipped feature groups (the best mode) are
checked against the evaluation's per-cell, per-group values and timed too.

Before anything is timed, the package's descriptor is checked against the
baseline's on the same window (:class:`BenchMismatch` otherwise).  Times are
medians over repeats of wall-clock time (``perf_counter``) and of the
thread's CPU time (``thread_time``); on a shared machine CPU time is the
better estimate of "one core", wall time is what a user waits.  BLAS and
OpenMP pools are limited to one thread (threadpoolctl) for the whole run.
"""

from __future__ import annotations

import dataclasses
import gc
import math
import os
import platform
import statistics
import time
import warnings
from collections.abc import Callable, Iterable, Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from scipy import stats

from tactile_descriptors_ros.core import descriptors, fast
from tactile_descriptors_ros.core.aggregation import (
    CellFeatures,
    CellSignals,
    RobotDescriptor,
    contact_gate,
    describe_window,
    reduce_body_part,
    stack_cells,
)
from tactile_descriptors_ros.core.alignment import zero_order_hold
from tactile_descriptors_ros.core.blocks import describe_blocks
from tactile_descriptors_ros.core.groups import body_part_layout
from tactile_descriptors_ros.core.robot import RobotDescription, load_robot
from tactile_descriptors_ros.core.windowing import CellChunk, Windower, first_fixed_start, grid_margin_ns
from tactile_descriptors_ros.errors import TactileError
from tactile_descriptors_ros.sim.synthetic import biotac_window, skin_robot, skin_window

from .latency import DESIGN_WAIT_TARGET_MS
from .latency import TARGET_MS as LATENCY_TARGET_MS

__all__ = [
    "BenchMismatch",
    "Timing",
    "CaseResult",
    "BenchReport",
    "naive_describe",
    "check_agreement",
    "check_kernel_against_reference",
    "time_call",
    "bench_case",
    "bench_windowing",
    "run_bench",
    "format_report",
    "one_core",
    "targets",
    "DEFAULT_LENGTHS_S",
    "TARGETS",
    "BEST_MODE_TARGETS",
    "BestModeResult",
    "check_against_evaluation",
    "bench_best_mode",
]

#: Window lengths of the scaling table (seconds).
DEFAULT_LENGTHS_S = (0.5, 1.0, 2.0, 5.0, 10.0)

#: Targets on one core (CPU time per window): case key -> (limit in ms, minimum speedup).
TARGETS = {
    "shadow_hand": (0.3, None),
    "nao": (2.0, 200.0),
    "skin_10000": (500.0, None),  # 2 s windows, 0.5 s hop: a window every 500 ms keeps up
}
#: The shipped feature groups (the best measured mode) on the live path: case key -> limit in ms CPU per window.
BEST_MODE_TARGETS = {"shadow_hand": 2.0, "nao": 10.0}



class BenchMismatch(TactileError):
    """The package's descriptor disagrees with the naive baseline: timings would be meaningless."""


# ----------------------------------------------------------------- baseline
def _hjorth_plain(x: np.ndarray, fs_hz: float) -> tuple[float, float, float]:
    """Hjorth parameters of one signal in plain numpy (eq. 1-3, derivative per second)."""
    x = np.asarray(x, dtype=np.float64)
    d = np.diff(x) * fs_hz
    dd = np.diff(d) * fs_hz
    var_x, var_d, var_dd = np.var(x), np.var(d), np.var(dd)
    mob = math.sqrt(var_d / var_x) if var_x > 0 else 0.0
    mob_d = math.sqrt(var_dd / var_d) if var_d > 0 else 0.0
    return float(var_x), mob, (mob_d / mob if mob > 0 else 0.0)


def _naive_cell(sig: CellSignals, fs_s: float, fs_v: float) -> tuple[np.ndarray, ...]:
    s = np.asarray(sig.vibration)
    v = np.asarray(sig.deformation)
    hs = np.array([_hjorth_plain(ch, fs_s) for ch in s]).T
    hv = np.array([_hjorth_plain(ch, fs_v) for ch in v]).T
    held, valid = zero_order_hold(sig.deformation_t_ns, v, sig.vibration_t_ns)
    lin = np.zeros((s.shape[0], v.shape[0]))
    nonlin = np.zeros_like(lin)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # constant input: scipy warns and returns NaN
        for i in range(s.shape[0]):
            for j in range(v.shape[0]):
                a, b = s[i, valid], held[j, valid]
                lin[i, j] = np.nan_to_num(stats.pearsonr(a, b)[0])
                nonlin[i, j] = np.nan_to_num(stats.spearmanr(a, b)[0])
    return hs[0], hs[1], hs[2], hv[0], hv[1], hv[2], lin, nonlin


def naive_describe(robot: RobotDescription, cells: Mapping[int, CellSignals], *,
                   channels: str | None = None, force_threshold_n: float | None = None) -> np.ndarray:
    """The paper's robot descriptor (concatenated body parts) computed signal by signal.

    The naive baseline: a Python loop over cells and signals, a plain numpy
    Hjorth per signal and ``scipy.stats.pearsonr``/``spearmanr`` per (S, V)
    pair on the zero-order-hold-expanded series; then the same contact gate
    and averages as the package (:func:`~.aggregation.reduce_body_part`).
    """
    channels = channels or "averaged"  # the paper's descriptor (the kernel's cases time it)
    threshold = robot.contact.force_threshold_n if force_threshold_n is None else force_threshold_n
    values = []
    for part in robot.body_parts:
        cell_type = robot.cell_types[part.cell_type]
        present = [c.id for c in part.cells if c.id in cells and cells[c.id].valid]
        gate = contact_gate([cells[i].force_n for i in present], threshold) if present else np.zeros(0, bool)
        touching = [i for i, g in zip(present, gate) if g]
        if not touching:
            values.append(np.zeros(len(body_part_layout(cell_type, channels))))
            continue
        per_cell = [_naive_cell(cells[i], cell_type.vibration.rate_hz, cell_type.deformation.rate_hz)
                    for i in touching]
        feats = CellFeatures(*(np.stack(q) for q in zip(*per_cell)), np.zeros(len(touching), np.uint32))
        values.append(reduce_body_part(feats, np.ones(len(touching), bool), cell_type, channels))
    return np.concatenate(values)


def check_agreement(robot: RobotDescription, cells: Mapping[int, CellSignals], *,
                    rtol: float = 1e-7, atol: float = 1e-9) -> float:
    """Assert that the package's descriptor equals the naive baseline's.

    Returns the largest absolute difference; raises :class:`BenchMismatch`
    (naming the worst label) when they differ beyond the tolerance.
    """
    got: RobotDescriptor = describe_window(robot, cells, layout="concat", channels="averaged")
    want = naive_describe(robot, cells, channels="averaged")
    if got.values.shape != want.shape:
        raise BenchMismatch(f"descriptor sizes differ: package {got.values.shape}, baseline {want.shape}")
    diff = np.abs(got.values - want)
    bad = diff > atol + rtol * np.abs(want)
    if bad.any():
        k = int(np.argmax(np.where(bad, diff, -1)))
        raise BenchMismatch(
            f"{robot.name}: package and baseline disagree at {got.labels[k]}: {got.values[k]!r} vs {want[k]!r} "
            f"({int(bad.sum())} of {bad.size} values differ); not timing")
    return float(diff.max()) if diff.size else 0.0


# ------------------------------------------------------------------- timing
@dataclass
class Timing:
    """Median (and spread) of repeated calls, in milliseconds."""

    wall_ms: float
    cpu_ms: float
    wall_min_ms: float
    cpu_min_ms: float
    repeats: int

    @property
    def per_second(self) -> float:
        return 1000.0 / self.wall_ms if self.wall_ms > 0 else math.inf


def time_call(fn: Callable[[], Any], repeat: int = 5, warmup: int = 1) -> Timing:
    """Time ``fn()``: medians of wall-clock and thread CPU time over ``repeat`` calls."""
    for _ in range(max(0, warmup)):
        fn()
    wall, cpu = [], []
    gc_was = gc.isenabled()
    gc.disable()
    try:
        for _ in range(max(1, repeat)):
            c0, w0 = time.thread_time(), time.perf_counter()
            fn()
            wall.append((time.perf_counter() - w0) * 1e3)
            cpu.append((time.thread_time() - c0) * 1e3)
    finally:
        if gc_was:
            gc.enable()
    return Timing(statistics.median(wall), statistics.median(cpu), min(wall), min(cpu), len(wall))


@dataclass
class CaseResult:
    """One benchmark case (a robot window)."""

    name: str
    n_cells: int
    length_s: float
    samples: int
    package: Timing
    kernel: Timing
    baseline: Timing
    baseline_extrapolated_from: int | None = None
    reference: Timing | None = None
    max_abs_diff: float = 0.0
    target_ms: float | None = None
    key: str = ""
    accelerator: str = fast.REFERENCE
    max_abs_diff_reference: float | None = None
    #: the package as the window node runs it: the window's cells as rows of one set of stacks
    #: (:func:`~tactile_descriptors_ros.core.aggregation.stack_cells`), None where a window is not stacked so
    package_node: Timing | None = None

    @property
    def speedup_wall(self) -> float:
        return self.baseline.wall_ms / self.package.wall_ms

    @property
    def speedup_cpu(self) -> float:
        return self.baseline.cpu_ms / self.package.cpu_ms

    @property
    def speedup_kernel_cpu(self) -> float:
        """Baseline over the per-cell kernel alone (what the fast paths replace)."""
        return self.baseline.cpu_ms / self.kernel.cpu_ms

    def to_dict(self) -> dict:
        d = asdict(self)
        d["speedup_wall"] = self.speedup_wall
        d["speedup_cpu"] = self.speedup_cpu
        d["speedup_kernel_cpu"] = self.speedup_kernel_cpu
        d["package_windows_per_s"] = self.package.per_second
        d["package_windows_per_s_cpu"] = 1000.0 / self.package.cpu_ms if self.package.cpu_ms > 0 else math.inf
        d["target_met"] = None if self.target_ms is None else self.package.cpu_ms <= self.target_ms
        return d


def _stack_batch(cells: Mapping[int, CellSignals]) -> tuple[np.ndarray, ...]:
    ids = sorted(cells)
    first = cells[ids[0]]
    return (np.stack([cells[i].vibration for i in ids]), first.vibration_t_ns,
            np.stack([cells[i].deformation for i in ids]), first.deformation_t_ns)


def _subset(robot: RobotDescription, cells: Mapping[int, CellSignals], n: int
            ) -> tuple[RobotDescription, dict[int, CellSignals]]:
    """The first ``n`` cells as a robot of their own (for an extrapolated baseline)."""
    sub = skin_robot(n) if n != 116 else skin_robot(116)
    ids = sorted(cells)[:n]
    sub_ids = sorted(sub.cell_index())
    return sub, {new: cells[old] for new, old in zip(sub_ids, ids)}


def check_kernel_against_reference(s: np.ndarray, ts: np.ndarray, v: np.ndarray, tv: np.ndarray, fs_s: float,
                                   fs_v: float, *, rtol: float = 1e-9, atol: float = 1e-9) -> float:
    """Assert that the kernel's per-cell quantities equal the reference's; return the largest difference.

    Raises
    ------
    BenchMismatch
        Naming the quantity that differs (or the quality flags).
    """
    got = fast.cell_quantities(s, ts, v, tv, fs_s, fs_v)
    want = descriptors.cell_quantities(s, ts, v, tv, fs_s, fs_v)
    worst = 0.0
    for name, a, b in zip(("act_s", "mob_s", "com_s", "act_v", "mob_v", "com_v", "lin", "nonlin"), got, want):
        diff = np.abs(a - b)
        if a.shape != b.shape or np.any(diff > atol + rtol * np.abs(b)):
            raise BenchMismatch(f"kernel and reference disagree on {name}: max |difference| {float(diff.max()):.3g}; "
                                "not timing")
        worst = max(worst, float(diff.max()) if diff.size else 0.0)
    if not np.array_equal(got[8], want[8]):
        raise BenchMismatch("kernel and reference disagree on the quality flags; not timing")
    return worst


def bench_case(name: str, robot: RobotDescription, cells: Mapping[int, CellSignals], *, repeat: int = 5,
               baseline_repeat: int = 3, baseline_cells: int | None = None, with_reference: bool = False,
               target_ms: float | None = None, check: bool = True, key: str = "") -> CaseResult:
    """Check agreement, then time the package, the kernel and the baseline on one window.

    ``baseline_cells``: time the baseline on that many cells and scale the
    time linearly to all cells (the baseline is a per-cell loop).
    ``with_reference``: also check the kernel against the reference
    (:func:`~tactile_descriptors_ros.core.descriptors.cell_quantities`) and
    time the reference.
    """
    n_cells = len(cells)
    if baseline_cells is not None and baseline_cells < n_cells:
        b_robot, b_cells = _subset(robot, cells, baseline_cells)
        scale = n_cells / baseline_cells
    else:
        b_robot, b_cells, scale = robot, cells, 1.0
    accel = fast.backend()
    s, ts, v, tv = _stack_batch(cells)
    ct = next(iter(robot.cell_types.values()))
    fs_s, fs_v = ct.vibration.rate_hz, ct.deformation.rate_hz
    diff_ref = check_kernel_against_reference(s, ts, v, tv, fs_s, fs_v) if with_reference else None
    diff = check_agreement(b_robot, b_cells) if check else float("nan")
    package = time_call(lambda: describe_window(robot, cells, channels="averaged"), repeat)
    package_node = None
    if (stacked := stack_cells(robot, own_clocks(cells))) is not None:
        node_cells, stacks = stacked
        if not _same_descriptor(describe_window(robot, node_cells, channels="averaged", stacks=stacks),
                                describe_window(robot, cells, channels="averaged")):
            raise BenchMismatch(f"{name}: describing the window's stacks differs from describing its cells; not timing")
        package_node = time_call(lambda: describe_window(robot, node_cells, channels="averaged", stacks=stacks), repeat)
    kernel = time_call(lambda: fast.cell_quantities(s, ts, v, tv, fs_s, fs_v), repeat)
    # a warm-up call only when the baseline runs on a small subset (it is slow)
    base = time_call(lambda: naive_describe(b_robot, b_cells), baseline_repeat, warmup=int(scale != 1.0))
    if scale != 1.0:
        base = Timing(base.wall_ms * scale, base.cpu_ms * scale, base.wall_min_ms * scale,
                      base.cpu_min_ms * scale, base.repeats)
    reference = None
    if with_reference:
        reference = time_call(lambda: descriptors.cell_quantities(s, ts, v, tv, fs_s, fs_v), baseline_repeat, warmup=0)
    length_s = (int(ts[-1]) - int(ts[0])) / 1e9 + 1.0 / fs_s if ts.size else 0.0
    return CaseResult(name, n_cells, round(length_s, 3), int(s.size + v.size), package, kernel, base,
                      baseline_cells if scale != 1.0 else None, reference, diff, target_ms, key, accel, diff_ref,
                      package_node)


#: The clock offset between one cell's stamps and the next one's in :func:`own_clocks` [ns].
CELL_CLOCK_STEP_NS = 1_000


def own_clocks(cells: Mapping[int, CellSignals]) -> dict[int, CellSignals]:
    """The cells with stamps as the window node holds them: each cell on its own clock.

    The node stamps every cell from its own clock offset, so no two cells of
    a window share a stamp row; the simulator's offline windows do.  Cell
    ``k`` (in id order) is shifted by ``k * CELL_CLOCK_STEP_NS``, its fast and
    slow stamps alike: its hold runs, hence every value, stay those of
    ``cells``, while the kernel finds every row different from the one before.
    """
    out = {}
    for k, cid in enumerate(sorted(cells)):
        sig = cells[cid]
        shift = np.int64(k * CELL_CLOCK_STEP_NS)
        out[cid] = dataclasses.replace(sig, vibration_t_ns=np.asarray(sig.vibration_t_ns, np.int64) + shift,
                                       deformation_t_ns=np.asarray(sig.deformation_t_ns, np.int64) + shift)
    return out


def _same_descriptor(a: RobotDescriptor, b: RobotDescriptor) -> bool:
    """Values (NaN equal to NaN), labels and every body part's flags, contact and mean force alike."""
    return (np.array_equal(a.values, b.values, equal_nan=True) and a.labels == b.labels
            and [(p.quality, p.contact, p.cells_in_contact, p.mean_force_n) for p in a.body_parts]
            == [(p.quality, p.contact, p.cells_in_contact, p.mean_force_n) for p in b.body_parts])


# --------------------------------------------------------------- best mode
@dataclass
class BestModeResult:
    """The shipped feature groups on one robot window: checked, then timed."""

    key: str
    name: str
    groups: tuple[str, ...]
    n_values: int
    package: Timing
    paper: Timing
    target_ms: float
    max_abs_diff: float
    checked_against: str
    block_s: float = 0.0
    block_hop_s: float = 0.0
    blocks: Timing | None = None  # the window node's path with the shipped block averaging (None: off)

    @property
    def shipped(self) -> Timing:
        """The path the window node runs with the shipped description: blocks when they are on."""
        return self.blocks if self.blocks is not None else self.package

    def to_dict(self) -> dict:
        d = asdict(self)
        d["met"] = bool(self.shipped.cpu_ms <= self.target_ms)
        d["ratio_to_paper_cpu"] = self.package.cpu_ms / self.paper.cpu_ms if self.paper.cpu_ms > 0 else math.inf
        d["ratio_blocks_to_single_cpu"] = (None if self.blocks is None or self.package.cpu_ms <= 0
                                           else self.blocks.cpu_ms / self.package.cpu_ms)
        return d


def check_against_evaluation(robot: RobotDescription, cells: Mapping[int, CellSignals],
                             groups: tuple[str, ...], *, rtol: float = 1e-9, atol: float = 1e-9) -> float:
    """Assert that the live call (all cells, all groups at once) equals the evaluation's computation.

    The evaluation describes one cell at a time, one group at a time
    (:func:`~tactile_descriptors_lab.evaluation.bank.window_bank`); the
    window node describes the whole robot with all groups in one call, cells
    stacked.  Every group is a mean over a body part's cells in contact of
    per-cell values, so each body part must equal the mean of its cells'
    one-cell descriptions.  Returns the largest difference; raises
    :class:`BenchMismatch` (naming the label) otherwise.
    """
    got = describe_window(robot, cells, layout="concat", groups=groups)
    threshold = robot.contact.force_threshold_n
    worst = 0.0
    for part, bp in zip(robot.body_parts, got.body_parts):
        touching = [c for c in part.cells if c.id in cells and cells[c.id].valid
                    and np.nanmean(np.asarray(cells[c.id].force_n, dtype=np.float64)) >= threshold]
        if len(touching) != bp.cells_in_contact:
            raise BenchMismatch(f"{robot.name} {part.name}: {bp.cells_in_contact} cells in contact, expected "
                                f"{len(touching)}; not timing")
        if not touching:
            continue
        rows = []
        for c in touching:
            one = dataclasses.replace(robot, body_parts=(dataclasses.replace(part, cells=(c,)),))
            rows.append(np.concatenate([describe_window(one, {c.id: cells[c.id]}, groups=(g,)).values
                                        for g in groups]))
        want = np.mean(rows, axis=0)
        diff = np.abs(bp.values - want)
        bad = diff > atol + rtol * np.abs(want)
        if bad.any():
            k = int(np.argmax(np.where(bad, diff, -1)))
            raise BenchMismatch(f"{robot.name} {part.name}: live call and evaluation disagree at {bp.labels[k]}: "
                                f"{bp.values[k]!r} vs {want[k]!r}; not timing")
        worst = max(worst, float(diff.max()) if diff.size else 0.0)
    return worst


def bench_best_mode(key: str, name: str, robot: RobotDescription, cells: Mapping[int, CellSignals], *,
                    repeat: int = 5) -> BestModeResult:
    """Check the shipped groups against the evaluation's values, then time them and the paper's descriptor."""
    groups = robot.descriptor.groups
    diff = check_against_evaluation(robot, cells, groups)
    package = time_call(lambda: describe_window(robot, cells, groups=groups), repeat)
    paper = time_call(lambda: describe_window(robot, cells, groups=("paper",)), repeat)
    n_values = describe_window(robot, cells, groups=groups).values.size
    d = robot.descriptor
    blocks = (time_call(lambda: describe_blocks(robot, cells, block_s=d.block_s, block_hop_s=d.block_hop_s,
                                                groups=groups), repeat) if d.block_s else None)
    return BestModeResult(key, name, tuple(groups), int(n_values), package, paper, BEST_MODE_TARGETS[key], diff,
                          "per cell and per group, as tactile evaluate computes them", d.block_s, d.block_hop_s,
                          blocks)


# ---------------------------------------------------------------- windowing
@dataclass
class WindowingResult:
    """Cost of :class:`~.windowing.Windower` input + ``poll`` per message: ``add`` vs ``add_many``."""

    n_cells: int
    message_ms: float
    messages: int
    stream_s: float
    windows: int
    us_per_message: float
    us_per_message_cpu: float
    messages_per_s_needed: float
    core_fraction: float
    us_per_message_many: float = 0.0
    us_per_message_many_cpu: float = 0.0
    core_fraction_many: float = 0.0
    many_batch: int = 0
    same_windows: bool = True


def bench_windowing(robot: RobotDescription | None = None, *, stream_s: float = 6.0, message_ms: float = 50.0,
                    length_s: float = 2.0, hop_s: float = 0.5, seed: int = 0) -> WindowingResult:
    """Feed ``stream_s`` seconds of NAO skin data at full rate through a fixed-mode Windower.

    Every cell sends one message per ``message_ms`` (accelerometer 1 kHz,
    force 250 Hz, as ``SkinCellFrame`` chunks converted by the window node;
    the skin driver's default ``batch_s`` is 50 ms); the time of the input
    calls + ``poll`` (including cutting the windows, not describing them) is
    divided by the number of messages.  Twice: one ``add`` per message, and
    one ``add_many`` per round of messages (every cell's message of one
    ``message_ms`` tick), both polling once per round; the two must cut the
    same windows.
    """
    robot = robot or load_robot("nao")
    rng = np.random.default_rng(seed)
    ids = sorted(robot.cell_index())
    n_msgs = int(round(stream_s * 1000 / message_ms))
    n_a = int(round(message_ms))  # 1 kHz
    accel = rng.integers(-40, 40, (3, n_a)).astype(np.int32)
    rounds = []  # built before timing: the node's message conversion is not part of the windower
    # from the start of a window on the windows' grid, so the stream's first window starts with it
    start_ns = first_fixed_start(0, int(round(length_s * 1e9)), int(round(hop_s * 1e9)), grid_margin_ns(robot))
    for m in range(n_msgs):
        t0 = start_ns + int(m * message_ms * 1e6)
        t_a = t0 + np.arange(n_a, dtype=np.int64) * 1_000_000
        t_f = t0 + np.arange(0, n_a, 4, dtype=np.int64) * 1_000_000
        force = rng.integers(300, 600, (3, t_f.size)).astype(np.int32)
        chunk = CellChunk(accel, t_a, force, t_f, force.mean(axis=0) * 0.002442, t_f)
        rounds.append([(cid, chunk) for cid in ids])

    def run(many: bool) -> tuple[float, float, list]:
        windower = Windower(robot, mode="fixed", length_s=length_s, hop_s=hop_s)
        windows: list = []
        gc_was = gc.isenabled()
        gc.disable()
        try:
            c0, w0 = time.thread_time(), time.perf_counter()
            for batch in rounds:
                if many:
                    windower.add_many(batch)
                else:
                    for cid, chunk in batch:
                        windower.add(cid, chunk)
                windows += windower.poll()
            wall = time.perf_counter() - w0
            cpu = time.thread_time() - c0
        finally:
            if gc_was:
                gc.enable()
        return wall, cpu, windows

    wall, cpu, w_one = run(False)
    wall_m, cpu_m, w_many = run(True)
    same = len(w_one) == len(w_many) and all(
        a.start_ns == b.start_ns and a.cells.keys() == b.cells.keys()
        and all(np.array_equal(a.cells[c].vibration, b.cells[c].vibration) for c in a.cells)
        for a, b in zip(w_one, w_many))
    total = n_msgs * len(ids)
    per_s = len(ids) * 1000.0 / message_ms
    return WindowingResult(len(ids), message_ms, total, stream_s, len(w_one), wall / total * 1e6,
                           cpu / total * 1e6, per_s, per_s * cpu / total, wall_m / total * 1e6,
                           cpu_m / total * 1e6, per_s * cpu_m / total, len(ids), same)


# --------------------------------------------------------------------- run
@dataclass
class BenchReport:
    """Everything ``tactile bench`` measured."""

    cases: list[CaseResult]
    scaling: list[CaseResult]
    windowing: WindowingResult | None
    environment: dict
    notes: list[str] = field(default_factory=list)
    latency: dict | None = None
    accelerator: dict = field(default_factory=dict)
    latency_exploration: dict | None = None
    best: list[BestModeResult] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {
            "accelerator": self.accelerator,
            "targets": targets(self),
            "best_mode": [b.to_dict() for b in self.best],
            "cases": [c.to_dict() for c in self.cases],
            "scaling": [c.to_dict() for c in self.scaling],
            "windowing": asdict(self.windowing) if self.windowing else None,
            "latency": self.latency,
            "latency_exploration": self.latency_exploration,
            "environment": self.environment,
            "notes": self.notes,
        }


def targets(report: BenchReport) -> dict:
    """The targets, each with the measured value and ``met`` (None: not measured).

    Times are the package's median CPU time per window on one core (the
    descriptor path the window node runs), after the agreement check.
    """
    by_key = {c.key: c for c in report.cases}
    out: dict[str, dict] = {}
    for key, (limit_ms, min_speedup) in TARGETS.items():
        c = by_key.get(key)
        entry: dict = {"target": f"<= {limit_ms:g} ms CPU per window" if key != "skin_10000" else
                       f"< {limit_ms:g} ms CPU per 2 s window (real time at a 0.5 s hop)",
                       "cpu_ms": None if c is None else c.package.cpu_ms,
                       "wall_ms": None if c is None else c.package.wall_ms,
                       "met": None if c is None else bool(c.package.cpu_ms <= limit_ms),
                       # the same window described as the window node describes its own (from its stacks, a clock
                       # per cell)
                       "node_path_cpu_ms": None if c is None or c.package_node is None else c.package_node.cpu_ms}
        if key == "skin_10000" and c is not None:
            entry["met"] = bool(c.package.cpu_ms < limit_ms)
        out[f"{key}_time"] = entry
        if min_speedup is not None:
            out[f"{key}_speedup"] = {"target": f">= {min_speedup:g}x the naive baseline (CPU)",
                                    "speedup_cpu": None if c is None else c.speedup_cpu,
                                    "met": None if c is None else bool(c.speedup_cpu >= min_speedup)}
    best = {b.key: b for b in report.best}
    for key, limit_ms in BEST_MODE_TARGETS.items():
        b = best.get(key)
        out[f"{key}_best_mode_time"] = {
            "target": f"<= {limit_ms:g} ms CPU per window, shipped feature groups and block averaging",
            "groups": None if b is None else list(b.groups),
            "block_s": None if b is None else b.block_s,
            "cpu_ms": None if b is None else b.shipped.cpu_ms,
            "wall_ms": None if b is None else b.shipped.wall_ms,
            "single_window_cpu_ms": None if b is None else b.package.cpu_ms,
            "checked_max_abs_diff": None if b is None else b.max_abs_diff,
            "met": None if b is None else bool(b.shipped.cpu_ms <= limit_ms)}
    for key, lat, what in (("latency", report.latency, "window end stamp"),
                           ("latency_exploration", report.latency_exploration, "release decision")):
        e2e = (lat or {}).get("e2e") or {}
        p95 = e2e.get("p95_ms")
        out[key] = {"target": f"{what} -> prediction <= {LATENCY_TARGET_MS:g} ms p95 at NAO full rate through "
                              "the node graph (tactile bench --latency)",
                    "median_ms": e2e.get("median_ms"), "p95_ms": p95, "max_ms": e2e.get("max_ms"),
                    "parts_ms": (lat or {}).get("parts_ms"),
                    "met": None if p95 is None else bool(p95 <= LATENCY_TARGET_MS)}
    waits = [lat["design_wait_ms"] for lat in (report.latency, report.latency_exploration)
             if lat and lat.get("design_wait_ms") is not None]
    out["latency_design_wait"] = {
        "target": f"window end (or release) to the end of the batch that closes it <= {DESIGN_WAIT_TARGET_MS:g} ms "
                  "in the shipped NAO graph",
        "design_wait_ms": max(waits) if waits else None,
        "met": None if not waits else bool(max(waits) <= DESIGN_WAIT_TARGET_MS)}
    # 10,000 cells through drivers and window nodes in their own processes: a run of minutes and dozens of
    # processes, measured on its own (lab/docs/performance.md, section Scale); its report carries the same entry with ``met``
    out["skin_10000_graph"] = {
        "target": "10000 skin cells through drivers and one window node per body part in real time (2 s windows, "
                  "0.5 s hop), zero lost frames (tactile bench --scale-graph --cells 10000)",
        "met": None}
    out["skin_10000_graph_2_hosts"] = {
        "target": "10000 skin cells, each body part's driver and window node on one of 2 hosts, the classifier on "
                  "another, in real time: zero lost frames, every descriptor at the classifier, every prediction "
                  "back (tactile bench --scale-graph --cells 10000 --hosts 2)",
        "met": None}
    # the views against the graph without them: runs of the whole NAO graph, measured on their own (docs/view.md)
    out["view_overhead"] = {
        "target": "the views (rviz2 markers and images, tactile view with one page) on the NAO graph at full rate "
                  "< 10 % of one core (tactile bench --view-overhead)",
        "met": None}
    return out


def one_core():
    """Context manager limiting BLAS/OpenMP thread pools to one thread (threadpoolctl)."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1)


def _environment() -> dict:
    return {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "accelerator": fast.backend(),
        "machine": platform.machine(),
        "cpus": os.cpu_count(),
        "load_average": [round(x, 2) for x in os.getloadavg()],
        "threads": 1,
    }


def run_bench(*, repeat: int = 5, sizes: Iterable[int] = (1000, 10000), lengths_s: Iterable[float] = DEFAULT_LENGTHS_S,
              baseline_cells: int = 116, windowing: bool = True, windowing_s: float = 6.0,
              progress: Callable[[str], None] | None = None) -> BenchReport:
    """Run the whole benchmark (see the module docstring); one core.

    Parameters
    ----------
    repeat : int
        Timed repeats of the package path per case (medians reported).
    sizes : iterable of int
        Skins of that many cells (2 s windows) besides the Shadow Hand and NAO.
    lengths_s : iterable of float
        NAO window lengths for the scaling table.
    baseline_cells : int
        The baseline of a larger skin is measured on this many cells and
        extrapolated linearly (it is a per-cell loop); below 116 the NAO
        baseline is extrapolated too.
    windowing, windowing_s : bool, float
        Measure the windowing cost on this many seconds of NAO stream.
    progress : callable, optional
        Called with a short message before each step.
    """
    say = progress or (lambda msg: None)
    notes: list[str] = []
    with one_core():
        accel = fast.warm_up()  # load or compile the accelerator before any timing
        if accel.get("error"):
            notes.append(f"compiled backend unavailable ({accel['error']}): the reference computes everything")
        cases = []
        say("Shadow Hand window")
        hand = load_robot("shadow_hand")
        cases.append(bench_case("shadow_hand (5 BioTacs, 2 s)", hand, biotac_window(hand), repeat=repeat,
                                baseline_repeat=max(1, min(repeat, 3)), with_reference=True,
                                target_ms=TARGETS["shadow_hand"][0], key="shadow_hand"))
        say("NAO window")
        nao = load_robot("nao")
        nao_base = min(116, baseline_cells)
        cases.append(bench_case("nao (116 skin cells, 2 s)", nao, skin_window(nao), repeat=repeat,
                                baseline_repeat=max(1, min(repeat, 3)), with_reference=True,
                                target_ms=TARGETS["nao"][0], baseline_cells=nao_base, key="nao"))
        if nao_base < 116:
            notes.append(f"NAO baseline extrapolated linearly from {nao_base} measured cells")
        say("shipped feature groups")
        best = [bench_best_mode("shadow_hand", "shadow_hand (5 BioTacs, 2 s)", hand, biotac_window(hand),
                                repeat=repeat),
                bench_best_mode("nao", "nao (116 skin cells, 2 s)", nao, skin_window(nao), repeat=repeat)]
        for n in sizes:
            say(f"{n} cells")
            robot = skin_robot(n)
            cells = skin_window(robot, seed=n)
            b_cells = min(n, baseline_cells)
            key = f"skin_{n}"
            cases.append(bench_case(f"skin ({n} cells, 2 s)", robot, cells, repeat=max(1, min(repeat, 3)),
                                    baseline_repeat=1, baseline_cells=b_cells,
                                    target_ms=TARGETS[key][0] if key in TARGETS else None, key=key))
            if b_cells < n:
                notes.append(f"baseline for {n} cells extrapolated linearly from {b_cells} measured cells")
            del cells
        scaling = []
        b_cells = min(16, baseline_cells)
        for length in lengths_s:
            say(f"NAO window of {length} s")
            scaling.append(bench_case(f"nao {length:g} s", nao, skin_window(nao, length), repeat=repeat,
                                      baseline_repeat=1, baseline_cells=b_cells, key=f"nao_{length:g}s"))
        if scaling:
            notes.append(f"scaling baselines extrapolated from {b_cells} cells")
        wres = None
        if windowing:
            say("windowing")
            wres = bench_windowing(nao, stream_s=windowing_s)
            if not wres.same_windows:
                raise BenchMismatch("Windower.add_many cut other windows than repeated Windower.add")
    fast.release_buffers()
    return BenchReport(cases, scaling, wres, _environment(), notes, accelerator=accel, best=best)


def _fmt_ms(x: float) -> str:
    return f"{x:9.2f}" if x < 1000 else f"{x:9.0f}"


def _latency_lines(lat: dict) -> list[str]:
    """The text of one ``tactile bench --latency`` run (fixed or exploration windows)."""
    mode = lat.get("mode", "fixed")
    ref = "window end stamp" if mode == "fixed" else "release decision"
    lines = ["", f"latency through window_node + classifier_node, {mode} windows ({lat.get('nodes')}, "
                 f"{lat.get('cells')} cells, one message per body part per {1000 * lat.get('batch_s', 0.0):g} ms, "
                 f"lateness {1000 * lat.get('lateness_s', 0.0):g} ms, {lat.get('predictions')} predictions; "
                 "lab/docs/performance.md, section Latency):"]
    rows = [("e2e", f"{ref} -> Prediction received"),
            ("wait", "waiting for the closing batch (design)"),
            ("processing", "closing batch published -> Prediction received"),
            ("complete", f"{ref} -> last Prediction of that window"),
            ("publish_lag", "probe publishing behind acquisition")]
    for key, what in rows:
        sm = lat.get(key) or {}
        if sm.get("n"):
            lines.append(f"  {what:50s} median {sm['median_ms']:8.1f}  p95 {sm['p95_ms']:8.1f}  "
                         f"max {sm['max_ms']:8.1f} ms")
    parts = lat.get("parts_ms") or {}
    if parts:
        lines.append("  what each part costs:")
        for key, what in (("design_wait", "design wait (to the closing batch's end)"),
                          ("frames_age_at_window_node", "frames age when taken by the window node"),
                          ("window_node", "closing batch published -> Descriptor received"),
                          ("describe", "window cut -> Descriptor published (in the node)"),
                          ("classifier", "Descriptor received -> Prediction received")):
            sm = parts.get(key) or {}
            if sm.get("n"):
                lines.append(f"    {what:48s} median {sm['median_ms']:8.1f}  p95 {sm['p95_ms']:8.1f}  "
                             f"max {sm['max_ms']:8.1f} ms")
    if lat.get("window_cpu_us_per_message") is not None:
        lines.append(f"  window node CPU per message {lat['window_cpu_us_per_message']:.0f} us "
                     f"({100 * (lat.get('window_cpu_fraction_of_core') or 0.0):.0f} % of one core), "
                     f"frames per callback {lat.get('frames_per_callback') or 0.0:.1f}")
    if lat.get("window_faults"):
        lines.append(f"  window node faults: {lat['window_faults']}")
    per = (lat.get("per_message") or {}).get("us_per_message")
    if per:
        lines.append("  per-message CPU (micro benchmark, us): " + ", ".join(f"{k} {v:.0f}" for k, v in per.items()))
    if "target_met" in lat:
        lines.append(f"  latency target <= {lat.get('target_ms')} ms (p95): {'met' if lat['target_met'] else 'NOT met'}"
                     f"; design wait {lat.get('design_wait_ms', 0.0):g} ms (target <= "
                     f"{lat.get('design_wait_target_ms', DESIGN_WAIT_TARGET_MS):g} ms)")
    return lines


def format_report(report: BenchReport) -> str:
    """The report as a plain-text table."""
    env = report.environment
    acc = report.accelerator or {}
    lines = [
        f"tactile bench: one core (BLAS/OpenMP threads = 1), numpy {env['numpy']}, {env['cpus']} CPUs, "
        f"load average {env['load_average']}",
        f"accelerator: {acc.get('accelerator', env.get('accelerator'))} (import {acc.get('import_s', 0.0):.2f} s, "
        f"first calls / compile {acc.get('first_call_s', 0.0):.2f} s, before timing; cache {acc.get('cache_dir')})",
        "ms per window, median of repeats; cpu = this thread's CPU time (robust to other load), "
        "wall = elapsed; x = baseline / package (CPU)",
        "",
        f"{'case':32s} {'pkg wall':>9s} {'pkg cpu':>9s} {'kernel':>9s} "
        f"{'win/s':>8s} {'base cpu':>10s} {'x cpu':>7s} {'target':>10s}",
    ]
    for c in report.cases + report.scaling:
        tgt = "" if c.target_ms is None else f"<={c.target_ms:g} " + ("ok" if c.package.cpu_ms <= c.target_ms else "NO")
        base_mark = "*" if c.baseline_extrapolated_from else " "
        per_s = 1000.0 / c.package.cpu_ms if c.package.cpu_ms > 0 else math.inf
        lines.append(
            f"{c.name:32s} {_fmt_ms(c.package.wall_ms)} {_fmt_ms(c.package.cpu_ms)} "
            f"{_fmt_ms(c.kernel.cpu_ms)} {per_s:8.1f} {_fmt_ms(c.baseline.cpu_ms)}{base_mark} "
            f"{c.speedup_cpu:7.0f} {tgt:>10s}")
    for c in report.cases:
        if c.reference is not None:
            lines.append(f"  {c.name}: reference (descriptors.cell_quantities) {c.reference.cpu_ms:.1f} ms cpu "
                         f"vs kernel {c.kernel.cpu_ms:.2f} ms cpu ({c.reference.cpu_ms / c.kernel.cpu_ms:.0f}x); "
                         f"max |difference| {c.max_abs_diff_reference:.1e}, checked before timing")
    for c in report.cases:
        if c.package_node is not None:
            lines.append(f"  {c.name}: as the window node describes it (from the window's stacks, a clock per cell) "
                         f"{c.package_node.cpu_ms:.2f} ms cpu, {c.package_node.wall_ms:.2f} ms wall; the same values")
    lines.append("  * baseline extrapolated linearly from a measured subset of cells; win/s from CPU time")
    lines.append("  agreement with the baseline checked before timing: max |difference| "
                 + ", ".join(f"{c.max_abs_diff:.1e}" for c in report.cases))
    w = report.windowing
    if w:
        lines += ["", f"windowing (fixed 2 s / 0.5 s hop, {w.n_cells} cells, one message per cell per "
                      f"{w.message_ms:g} ms = {w.messages_per_s_needed:.0f} messages/s, poll per round):",
                  f"  Windower.add per message:            {w.us_per_message:7.1f} us wall, "
                  f"{w.us_per_message_cpu:7.1f} us cpu = {100 * w.core_fraction:5.1f} % of one core",
                  f"  Windower.add_many per round of {w.many_batch:3d}:   {w.us_per_message_many:7.1f} us wall, "
                  f"{w.us_per_message_many_cpu:7.1f} us cpu per message = {100 * w.core_fraction_many:5.1f} % "
                  f"of one core (same windows: {'yes' if w.same_windows else 'NO'})"]
    for lat in (report.latency, report.latency_exploration):
        if lat:
            lines += _latency_lines(lat)
    if report.best:
        lines += ["", "shipped feature groups (the best measured mode; checked against the evaluation's values "
                      "per cell and group before timing):"]
        for b in report.best:
            lines.append(f"  {b.name:32s} {'+'.join(b.groups)} ({b.n_values} values): {b.package.cpu_ms:.2f} ms cpu, "
                         f"{b.package.wall_ms:.2f} ms wall (paper's descriptor {b.paper.cpu_ms:.2f} ms cpu); "
                         f"target <= {b.target_ms:g} ms {'met' if b.package.cpu_ms <= b.target_ms else 'NOT met'}; "
                         f"max |difference| {b.max_abs_diff:.1e}")
            if b.blocks is not None:
                lines.append(f"  {'':32s} with the shipped block averaging ({b.block_s:g} s blocks, "
                             f"{b.block_hop_s:g} s hop), as the window node runs it: {b.blocks.cpu_ms:.2f} ms cpu, "
                             f"{b.blocks.cpu_ms / b.package.cpu_ms:.2f} x one descriptor of the window")
    lines += ["", "targets (one core, CPU time per window):"]
    for key, t in targets(report).items():
        value = next((f"{t[k]:.2f}" + (" x" if k == "speedup_cpu" else " ms") + (" p95" if k == "p95_ms" else "")
                      for k in ("cpu_ms", "speedup_cpu", "p95_ms", "design_wait_ms") if t.get(k) is not None),
                     "not measured")
        met = {True: "met", False: "NOT met", None: "-"}[t["met"]]
        lines.append(f"  {key:24s} {t['target']:62s} {value:>12s}  {met}")
    for note in report.notes:
        lines.append(f"note: {note}")
    return "\n".join(lines)
