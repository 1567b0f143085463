"""From one window of cell signals to the robot's descriptor.

Pipeline (Kaboli et al. 2018, section III):

1. per cell: Hjorth Activity, Mobility, Complexity of every vibration (S) and
   deformation (V) channel (eq. 1-3), and the linear (Pearson, eq. 4) and
   nonlinear (Spearman, eq. 5) correlation of every S channel with every V
   channel, V held onto S's time base (:mod:`.alignment`);
2. contact gate lambda (eq. 13, 16, 27): a cell counts only if its mean normal
   force over the window is at least F_t;
3. per body part: the average over the cells in contact and, in the paper's
   ``averaged`` mode, over the channels of each axis (eq. 6-10, 14-15,
   19-26), giving eq. 11's layout
   ``[A_S, A_V, M_S, M_V, C_S, C_V, L_SV, N_SV]`` -- 8 values for a BioTac
   finger (eq. 17), 18 for a skin body part (eq. 28), 24 for two 3-axis
   modalities (eq. 11); in ``per_channel`` mode each channel is kept (98
   values per BioTac);
4. whole robot: body parts concatenated in the configured order (eq. 12, 18,
   29), or ``pooled``: the mean over the body parts in contact of one cell
   type, which transfers across hands and finger subsets.

A body part with no cell in contact yields zeros, ``contact = False`` and the
``NO_CONTACT`` flag.
"""

from __future__ import annotations

import functools
import threading
import weakref
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from ..errors import SignalError
from .cell_types import CellType
from .descriptors import Quality
from .fast import cell_bounds, cell_quantities, cell_quantities_bounded, exact_integer_ok, scratch
from .features import (
    band_hjorth,
    level_values,
    plain_values,
    power_spectrum,
    rocket_values,
    spectral_length,
    statistics_values,
)
from .groups import (
    KERNEL_GROUPS,
    body_part_layout,
    check_groups,
    groups_of_channels,
    selection_labels,
    selection_name,
)
from .robot import BodyPart, Cell, RobotDescription

__all__ = [
    "CellSignals",
    "CellStacks",
    "stack_cells",
    "CellFeatures",
    "BodyPartDescriptor",
    "RobotDescriptor",
    "cell_features",
    "contact_gate",
    "reduce_body_part",
    "describe_window",
    "pool_body_parts",
    "resolve_groups",
    "RobotPlan",
    "robot_plan",
]

_GAP = int(Quality.GAP)
_INVALID = int(Quality.INVALID)
_NO_CONTACT = int(Quality.NO_CONTACT)
_SATURATED = int(Quality.SATURATED)


@dataclass
class CellSignals:
    """One cell's samples in one window.

    Attributes
    ----------
    vibration : numpy.ndarray, shape (n_vibration_channels, n_fast)
        Vibration samples S (counts or SI; integer counts are ranked exactly).
    vibration_t_ns : numpy.ndarray of int64, shape (n_fast,)
        Their time stamps.
    deformation : numpy.ndarray, shape (n_deformation_channels, n_slow)
        Deformation samples V.
    deformation_t_ns : numpy.ndarray of int64, shape (n_slow,)
        Their time stamps.  S samples before the first V sample are not
        paired; every V sample given here enters V's Hjorth parameters, so
        give only the window's own samples.
    force_n : numpy.ndarray, shape (n_force,)
        Normal force samples in newtons over the window (for the gate).
    valid : bool
        False when the window holds invalid samples (parity errors, lost
        frames) for this cell: the cell is left out and flagged ``INVALID``.
    gap : bool
        True when the cell's samples have a hole in time inside the window
        (a sensor unplugged, frames dropped): the body part is flagged ``GAP``.
    invalid_samples : int
        Invalid samples already removed from this window's arrays: the body
        part is flagged ``INVALID`` but the cell still counts.
    extra : numpy.ndarray, shape (n_extra_channels, n_slow), optional
        The cell type's extra channels (:attr:`.cell_types.CellType.extra_channels`:
        BioTac PDC, TDC, TAC; skin proximity, temperature), one value per
        deformation sample (float, NaN where missing).  Only the feature
        groups that use them read them (``levels``); ``None`` reads as all
        missing.
    deformation_tare : numpy.ndarray, shape (n_deformation_channels,), optional
        Tare of each deformation channel in counts, subtracted by the
        ``levels`` group only (the paper's quantities do not depend on it).
    """

    vibration: np.ndarray
    vibration_t_ns: np.ndarray
    deformation: np.ndarray
    deformation_t_ns: np.ndarray
    force_n: np.ndarray
    valid: bool = True
    gap: bool = False
    invalid_samples: int = 0
    extra: np.ndarray | None = None
    deformation_tare: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class CellStacks:
    """Cells whose signals are the rows of shared arrays: row ``k`` of each array is ``cells[k]``'s.

    The windower cuts a window so (:class:`.windowing.Window`'s ``stacks``,
    when every cell of the robot is in it, clean, with as many samples as
    the others); :func:`describe_window` then reads these arrays instead of
    stacking the cells' arrays again.  It does so only for cells that are
    these objects, in this order, each still holding the arrays it was made
    with (:meth:`holds`): a mapping built otherwise is stacked as usual.

    Attributes
    ----------
    cells : tuple of CellSignals
        The cells, in the order of the arrays' rows.
    vibration, deformation : numpy.ndarray, shape (n_cells, channels, samples)
    vibration_t_ns, deformation_t_ns : numpy.ndarray of int64, shape (n_cells, samples)
    force_n : numpy.ndarray, shape (n_cells, n_force)
    extra : numpy.ndarray, shape (n_cells, n_extra, n_slow), optional
    """

    cells: tuple[CellSignals, ...]
    vibration: np.ndarray
    vibration_t_ns: np.ndarray
    deformation: np.ndarray
    deformation_t_ns: np.ndarray
    force_n: np.ndarray
    extra: np.ndarray | None = None
    #: per cell, the arrays it was made with (identity, in the order of :data:`_STACKED_FIELDS`)
    _arrays: tuple[tuple, ...] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_arrays", tuple(tuple(getattr(c, f) for f in _STACKED_FIELDS) for c in self.cells))

    def holds(self, sigs: list[CellSignals], *fields: str) -> bool:
        """Whether ``sigs`` are :attr:`cells` in order, each holding its rows of ``fields`` still."""
        if len(sigs) != len(self.cells):
            return False
        at = [_STACKED_FIELDS.index(f) for f in fields]
        for sig, own, arrays in zip(sigs, self.cells, self._arrays):
            if sig is not own:
                return False
            for k in at:
                if getattr(sig, _STACKED_FIELDS[k]) is not arrays[k]:
                    return False
        return True


_STACKED_FIELDS = ("vibration", "vibration_t_ns", "deformation", "deformation_t_ns", "force_n", "extra")


def stack_cells(robot: RobotDescription, cells: Mapping[int, CellSignals]
                ) -> tuple[dict[int, CellSignals], CellStacks] | None:
    """Copies of a window's cells laid out as the windower cuts a clean window: rows of one :class:`CellStacks`.

    For describing offline windows the way the window node describes its own
    (``describe_window(robot, copies, stacks=stacks)``; the same values as
    describing ``cells``).  Rows in the robot's order of body parts and cells.

    Returns
    -------
    tuple of (dict, CellStacks) or None
        None when the windower would not stack them either: a cell of the
        robot missing, several cell types, or arrays of different shapes or
        dtypes.
    """
    if len({p.cell_type for p in robot.body_parts}) != 1:
        return None
    ids = [c.id for p in robot.body_parts for c in p.cells]
    if not ids or any(cid not in cells for cid in ids):
        return None
    sigs = [cells[cid] for cid in ids]
    arrays = {}
    for name in _STACKED_FIELDS:
        values = [getattr(s, name) for s in sigs]
        if name == "extra" and all(v is None for v in values):
            arrays[name] = None
            continue
        if any(not isinstance(v, np.ndarray) for v in values) or len({(v.shape, v.dtype) for v in values}) != 1:
            return None
        arrays[name] = np.stack(values)
    copies = {}
    for k, (cid, sig) in enumerate(zip(ids, sigs)):
        copies[cid] = CellSignals(*(arrays[name][k] if arrays[name] is not None else None for name in _STACKED_FIELDS[:5]),
                                  sig.valid, sig.gap, sig.invalid_samples,
                                  arrays["extra"][k] if arrays["extra"] is not None else None, sig.deformation_tare)
    return copies, CellStacks(tuple(copies[cid] for cid in ids), *(arrays[name] for name in _STACKED_FIELDS))


@dataclass
class CellFeatures:
    """Per-channel quantities of a batch of cells (before any averaging).

    Arrays are indexed ``[cell, channel]`` (``[cell, s_channel, v_channel]``
    for the correlations); ``quality`` is the per-cell OR of every flag.
    """

    act_s: np.ndarray
    mob_s: np.ndarray
    com_s: np.ndarray
    act_v: np.ndarray
    mob_v: np.ndarray
    com_v: np.ndarray
    lin: np.ndarray
    nonlin: np.ndarray
    quality: np.ndarray


@dataclass
class BodyPartDescriptor:
    """Descriptor of one body part in one window (eq. 11, 17, 28)."""

    name: str
    cell_type: str
    values: np.ndarray
    labels: tuple[str, ...]
    contact: bool
    cells_in_contact: int
    cells_total: int
    mean_force_n: float
    quality: int


@dataclass
class RobotDescriptor:
    """Whole-robot descriptor of one window (eq. 12, 18, 29, or pooled).

    ``channels`` names the feature-group selection (``"paper"``,
    ``"per_channel+bands+levels+statistics"``; :func:`.groups.selection_name`).
    """

    robot: str
    layout: str
    channels: str
    body_parts: tuple[BodyPartDescriptor, ...]
    values: np.ndarray
    labels: tuple[str, ...]
    extra: dict = field(default_factory=dict)

    @property
    def contact(self) -> bool:
        """True when any body part was in contact."""
        return any(bp.contact for bp in self.body_parts)


def _stack_times(times: list[np.ndarray]) -> np.ndarray:
    return np.stack([np.asarray(t, dtype=np.int64) for t in times])


def cell_features(
    vibration: np.ndarray,
    vibration_t_ns: np.ndarray,
    deformation: np.ndarray,
    deformation_t_ns: np.ndarray,
    vibration_rate_hz: float,
    deformation_rate_hz: float,
) -> CellFeatures:
    """Hjorth parameters and correlations of a batch of cells (eq. 1-5).

    Parameters
    ----------
    vibration : array_like, shape (n_cells, n_s, n_fast)
        S samples of each cell.
    vibration_t_ns : array_like of int64, shape (n_fast,) or (n_cells, n_fast)
        S sample times (shared by all cells, or per cell).
    deformation : array_like, shape (n_cells, n_v, n_slow)
        V samples of each cell.
    deformation_t_ns : array_like of int64, shape (n_slow,) or (n_cells, n_slow)
        V sample times.
    vibration_rate_hz, deformation_rate_hz : float
        Sampling rates, for the derivative per second (Mobility in rad/s).

    Returns
    -------
    CellFeatures
    """
    s = np.asarray(vibration)
    v = np.asarray(deformation)
    if s.ndim != 3 or v.ndim != 3 or s.shape[0] != v.shape[0]:
        raise SignalError(
            f"vibration and deformation must be (n_cells, channels, samples) with the same n_cells; "
            f"got {s.shape} and {v.shape}"
        )
    return CellFeatures(*cell_quantities(s, vibration_t_ns, v, deformation_t_ns,
                                         vibration_rate_hz, deformation_rate_hz))


def contact_gate(force_n: np.ndarray, threshold_n: float) -> np.ndarray:
    """Contact gate lambda of eq. 13/16/27: mean force over the window >= F_t.

    Parameters
    ----------
    force_n : array_like, shape (n_cells, n_samples) or a list of 1-D arrays
        Normal force per cell in newtons.  Non-finite samples are ignored; a
        cell without finite samples is not in contact.
    threshold_n : float
        F_t in newtons (0.2 N in the paper).

    Returns
    -------
    numpy.ndarray of bool, shape (n_cells,)
    """
    return _mean_forces(force_n) >= threshold_n  # NaN (no finite sample) compares False


def _mean_forces(force_n) -> np.ndarray:
    """Mean of each cell's finite force samples; NaN for a cell with none."""
    out = np.full(len(force_n), np.nan)
    for k, f in enumerate(force_n):
        f = np.asarray(f, dtype=np.float64)
        f = f[np.isfinite(f)]
        if f.size:
            out[k] = f.mean()
    return out


def _channel_slices(axes: tuple[tuple[str, ...], ...]) -> list[slice]:
    out, start = [], 0
    for axis in axes:
        out.append(slice(start, start + len(axis)))
        start += len(axis)
    return out


def reduce_body_part(features: CellFeatures, in_contact: np.ndarray, cell_type: CellType,
                     channels: str = "averaged") -> np.ndarray:
    """Average per-cell quantities over the cells in contact (eq. 6-10, 14-15, 19-26).

    Parameters
    ----------
    features : CellFeatures
        Quantities of the body part's cells.
    in_contact : array_like of bool, shape (n_cells,)
        The gate lambda per cell.
    cell_type : CellType
        Gives the axes (channels averaged within an axis) and correlation pairs.
    channels : {"averaged", "per_channel"}

    Returns
    -------
    numpy.ndarray
        Values in the order of :func:`body_part_layout`; zeros when no cell is
        in contact.
    """
    labels = body_part_layout(cell_type, channels)
    mask = np.asarray(in_contact, dtype=bool)
    if not mask.any():
        return np.zeros(len(labels))
    s_axes = _channel_slices(cell_type.vibration.axes)
    v_axes = _channel_slices(cell_type.deformation.axes)
    pairs = cell_type.correlation_pairs()

    def cells_mean(a: np.ndarray) -> np.ndarray:
        return _finite_mean(a[mask], axis=0)

    parts: list[np.ndarray] = []
    for s_arr, v_arr in ((features.act_s, features.act_v), (features.mob_s, features.mob_v),
                         (features.com_s, features.com_v)):
        s_m, v_m = cells_mean(s_arr), cells_mean(v_arr)
        if channels == "averaged":
            parts.append(np.array([_finite_mean(s_m[sl]) for sl in s_axes]))
            parts.append(np.array([_finite_mean(v_m[sl]) for sl in v_axes]))
        else:
            parts += [s_m, v_m]
    for corr in (features.lin, features.nonlin):
        c_m = cells_mean(corr)
        if channels == "averaged":
            parts.append(np.array([_finite_mean(c_m[s_axes[i], v_axes[j]]) for i, j in pairs]))
        else:
            parts.append(np.concatenate([c_m[s_axes[i], v_axes[j]].ravel() for i, j in pairs]))
    values = np.concatenate(parts)
    assert values.shape[0] == len(labels)
    return values


def _body_part_descriptor(part: BodyPart, cell_type: CellType, cells: Mapping[int, CellSignals],
                          threshold_n: float, channels: str) -> BodyPartDescriptor:
    labels = body_part_layout(cell_type, channels)
    present = [c for c in part.cells if c.id in cells]
    quality = 0
    if len(present) < len(part.cells):
        quality |= int(Quality.GAP)
    if any(cells[c.id].gap for c in present):
        quality |= int(Quality.GAP)
    usable = [c for c in present if cells[c.id].valid]
    if len(usable) < len(present) or any(cells[c.id].invalid_samples for c in present):
        quality |= int(Quality.INVALID)
    means = _mean_forces([cells[c.id].force_n for c in usable])
    gate = means >= threshold_n  # eq. 13, as contact_gate
    touching = [c for c, g in zip(usable, gate) if g]
    if not touching:
        return BodyPartDescriptor(part.name, part.cell_type, np.zeros(len(labels)), labels, False, 0,
                                  len(part.cells), 0.0, quality | int(Quality.NO_CONTACT))
    group_values: list[np.ndarray] = []
    group_sizes: list[int] = []
    # Batch cells whose windows have identical shapes (the common case).
    groups: dict[tuple, list[int]] = {}
    for c in touching:
        sig = cells[c.id]
        key = (np.shape(sig.vibration), np.shape(sig.deformation))
        groups.setdefault(key, []).append(c.id)
    for ids in groups.values():
        sigs = [cells[i] for i in ids]
        _check_channels(sigs, cell_type, ids)
        vib = np.stack([sg.vibration for sg in sigs])
        dfm = np.stack([sg.deformation for sg in sigs])
        feats = cell_features(
            vib, _stack_times([sg.vibration_t_ns for sg in sigs]),
            dfm, _stack_times([sg.deformation_t_ns for sg in sigs]),
            cell_type.vibration.rate_hz, cell_type.deformation.rate_hz,
        )
        group_values.append(reduce_body_part(feats, np.ones(len(ids), bool), cell_type, channels))
        group_sizes.append(len(ids))
        quality |= int(np.bitwise_or.reduce(feats.quality)) if len(ids) else 0
        quality |= _saturation(vib, dfm, cell_type)
    weights = np.asarray(group_sizes, dtype=np.float64) / sum(group_sizes)
    values = np.sum([v * w for v, w in zip(group_values, weights)], axis=0)
    return BodyPartDescriptor(part.name, part.cell_type, values, labels, True, len(touching),
                              len(part.cells), float(means[gate].mean()), quality)


def _check_channels(sigs: list[CellSignals], cell_type: CellType, ids: list[int]) -> None:
    n_s, n_v = len(cell_type.vibration.channels), len(cell_type.deformation.channels)
    for sig, cid in zip(sigs, ids):
        if np.shape(sig.vibration)[0] != n_s or np.shape(sig.deformation)[0] != n_v:
            raise SignalError(
                f"cell {cid}: expected {n_s} vibration and {n_v} deformation channels for cell type "
                f"{cell_type.name!r}, got {np.shape(sig.vibration)[0]} and {np.shape(sig.deformation)[0]}"
            )


def _saturation(vib: np.ndarray, dfm: np.ndarray, cell_type: CellType) -> int:
    """SATURATED when a cell's integer signal touches its ADC limits in over 1 % of its samples.

    ``vib`` and ``dfm`` are a group of cells stacked as (cell, channel, sample).
    """
    for a, mod in ((vib, cell_type.vibration), (dfm, cell_type.deformation)):
        if a.size and np.issubdtype(a.dtype, np.integer):
            lo, hi = mod.adc_range
            at_limit = np.count_nonzero((a <= lo) | (a >= hi), axis=(1, 2))
            if np.any(at_limit > 0.01 * a.shape[1] * a.shape[2]):
                return int(Quality.SATURATED)
    return 0


def _finite_mean(a: np.ndarray, axis: int | None = None) -> np.ndarray:
    """Mean as a sum of ``a / n``: values up to the float64 maximum (clipped
    Activity, flagged OVERFLOW) average without overflowing to inf."""
    a = np.asarray(a, dtype=np.float64)
    n = a.size if axis is None else a.shape[axis]
    if n == 0:
        return np.zeros(()) if axis is None else np.zeros(np.delete(a.shape, axis))
    return np.sum(a / n, axis=axis)


# ------------------------------------------------------------ batched path
class RobotPlan(NamedTuple):
    """What :func:`describe_window` needs of a robot, computed once per robot object (:func:`robot_plan`).

    Attributes
    ----------
    index : dict of int to (BodyPart, Cell)
        Every cell id's body part and cell (:meth:`.robot.RobotDescription.cell_index`).
    types : tuple
        Per cell type, in the order of its first body part: the cell type and
        its ``(position, body part)`` pairs.
    part_ids : tuple
        Per cell type as in ``types``: the cell ids of each of its body parts.
    concat_labels : dict
        The ``concat`` labels per group selection, filled on first use
        (descriptions are immutable).
    """

    index: dict[int, tuple[BodyPart, Cell]]
    # per cell type, in the order of its first body part: (cell type, [(position, body part)])
    types: tuple[tuple[CellType, tuple[tuple[int, BodyPart], ...]], ...]
    # per cell type as in ``types``: the cell ids of each of its body parts
    part_ids: tuple[tuple[tuple[int, ...], ...], ...]
    # concat labels per group selection (filled on first use; descriptions are immutable)
    concat_labels: dict[tuple[str, ...], tuple[str, ...]]


_PLANS: dict[int, tuple[weakref.ref, RobotPlan]] = {}
_PLANS_LOCK = threading.Lock()


def robot_plan(robot: RobotDescription) -> RobotPlan:
    """The robot's cell index and body parts by cell type (:class:`RobotPlan`).

    Cached per robot object (descriptions are immutable) while the object
    lives; :func:`describe_window` and :func:`.blocks.describe_blocks` share it.
    """
    hit = _PLANS.get(id(robot))
    if hit is not None and hit[0]() is robot:
        return hit[1]
    by_type: dict[str, list[tuple[int, BodyPart]]] = {}
    for pos, part in enumerate(robot.body_parts):
        by_type.setdefault(part.cell_type, []).append((pos, part))
    types = tuple((robot.cell_types[name], tuple(parts)) for name, parts in by_type.items())
    plan = RobotPlan(robot.cell_index(), types,
                      tuple(tuple(tuple(c.id for c in part.cells) for _, part in parts) for _, parts in types),
                      {})
    with _PLANS_LOCK:
        for key in [k for k, (ref, _) in _PLANS.items() if ref() is None]:
            del _PLANS[key]
        _PLANS[id(robot)] = (weakref.ref(robot), plan)
    return plan


def _force_means(forces: list) -> np.ndarray:
    """:func:`_mean_forces` of a list of force arrays, one pass when they are all finite and equally long."""
    if not forces:
        return np.zeros(0)
    try:
        shapes = {f.shape for f in forces}
    except AttributeError:
        shapes = {np.shape(f) for f in forces}
    n = next(iter(shapes))
    if len(shapes) == 1 and len(n) == 1 and n[0]:
        return _row_means(np.concatenate(forces).reshape(len(forces), n[0]).astype(np.float64, copy=False))
    return _mean_forces(forces)


def _row_means(f2: np.ndarray) -> np.ndarray:
    """:func:`_mean_forces` of the rows of ``f2`` (n_cells, n >= 1), float64."""
    out = np.add.reduce(f2, axis=1)  # the sum of each row, as ndarray.mean takes it
    out /= f2.shape[1]
    # a finite sum means finite samples; the other rows (NaN or inf samples, or an overflowing
    # sum) are taken one by one, as _mean_forces takes them
    finite = np.isfinite(out)
    if not finite.all():
        redo = (~finite).nonzero()[0]
        out[redo] = _mean_forces([f2[k] for k in redo.tolist()])
    return out


def _segment_sums(y: np.ndarray, starts: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Row sums of each segment ``y[starts[p]:starts[p] + counts[p]]`` (contiguous, in order), added row after row.

    The order of the additions is that of ``numpy.sum(segment, axis=0)``
    on a segment with two or more columns (row 0 + row 1 + ..., which is
    what this takes), plus ``0.0`` (``numpy.add.at`` onto zeros, the
    previous form, gave a zero's sign so; the sum is ``-0.0`` only when every
    term is).  ``numpy.add.reduceat`` sums in another order.
    """
    out = np.empty((starts.size, y.shape[1]))
    for p, (s0, n) in enumerate(zip(starts.tolist(), counts.tolist())):
        np.add.reduce(y[s0:s0 + n], axis=0, out=out[p])
    out += 0.0
    return out


class _Reduction(NamedTuple):
    """How :func:`_reduce_parts` turns per-body-part column sums into values (per cell type and ``channels``).

    The per-cell quantities are laid out as the columns of one matrix
    ``[A_S, A_V, M_S, M_V, C_S, C_V, L, N]`` (``L`` and ``N`` flattened
    ``(n_s, n_v)``).  Every output value is the mean of a set of ``k`` such
    columns (one axis of channels, or one correlation pair's block;
    ``k == 1`` per channel): ``groups`` holds, per ``k``, the columns
    ``(n_outputs, k)`` and the output positions.
    """

    n_s: int
    n_v: int
    n_out: int
    single_cols: tuple[int, ...]
    groups: tuple[tuple[int, np.ndarray, np.ndarray], ...]


@functools.lru_cache(maxsize=256)
def _reduction(cell_type: CellType, channels: str) -> _Reduction:
    n_s, n_v = len(cell_type.vibration.channels), len(cell_type.deformation.channels)
    widths = [n_s, n_v] * 3 + [n_s * n_v] * 2
    edges = np.concatenate(([0], np.cumsum(widths))).tolist()
    s_axes = _channel_slices(cell_type.vibration.axes)
    v_axes = _channel_slices(cell_type.deformation.axes)
    pairs = cell_type.correlation_pairs()
    outputs: list[list[int]] = []  # the columns averaged into each output value, in layout order
    for q in range(3):
        s0, v0 = edges[2 * q], edges[2 * q + 1]
        if channels == "averaged":
            outputs += [list(range(s0 + sl.start, s0 + sl.stop)) for sl in s_axes]
            outputs += [list(range(v0 + sl.start, v0 + sl.stop)) for sl in v_axes]
        else:
            outputs += [[s0 + c] for c in range(n_s)] + [[v0 + c] for c in range(n_v)]
    for c in (6, 7):
        for i, j in pairs:
            block = [edges[c] + s * n_v + v for s in range(s_axes[i].start, s_axes[i].stop)
                     for v in range(v_axes[j].start, v_axes[j].stop)]
            outputs += [block] if channels == "averaged" else [[col] for col in block]
    by_k: dict[int, list[int]] = {}
    for pos, cols in enumerate(outputs):
        by_k.setdefault(len(cols), []).append(pos)
    groups = tuple((k, np.array([outputs[pos] for pos in pos_k], dtype=np.intp).reshape(len(pos_k), k),
                    np.array(pos_k, dtype=np.intp))
                   for k, pos_k in sorted(by_k.items()) if k)  # k == 0 (an empty axis): stays zero
    single_cols = tuple(int(edges[b]) for b, w in enumerate(widths) if w == 1)
    return _Reduction(n_s, n_v, len(outputs), single_cols, groups)


def _reduce_parts(feats: CellFeatures, starts: np.ndarray, counts: np.ndarray, cell_type: CellType,
                  channels: str, red: _Reduction | None = None) -> np.ndarray:
    """:func:`reduce_body_part` of several body parts at once, identical values.

    ``feats`` holds the cells in contact of every body part, each body
    part's cells contiguous (``starts``, ``counts``).  Returns one row of
    values per body part.  The same floating-point operations in the same
    order as :func:`reduce_body_part` (``a / n`` summed row after row over
    the cells, then each axis' ``a / k`` summed), batched over body parts and
    outputs by the cached :func:`_reduction`.
    """
    red = _reduction(cell_type, channels) if red is None else red
    n_rows = feats.act_s.shape[0]
    y = np.concatenate([feats.act_s, feats.act_v, feats.mob_s, feats.mob_v, feats.com_s, feats.com_v,
                        feats.lin.reshape(n_rows, -1), feats.nonlin.reshape(n_rows, -1)], axis=1,
                       dtype=np.float64)
    if counts.size == n_rows:  # one cell per body part: y / 1 summed onto zeros
        m = np.add(y, 0.0, out=y)
    else:
        y /= np.repeat(counts.astype(np.float64), counts)[:, None]  # a / n per cell, as _finite_mean
        m = _segment_sums(y, starts, counts)
        # numpy sums a single column pairwise, not row after row: take those sums as reduce_body_part does
        if red.single_cols:
            for p in np.flatnonzero(counts >= 8).tolist():
                seg = y[starts[p]:starts[p] + counts[p]]
                for col in red.single_cols:
                    m[p, col] = np.sum(seg[:, col:col + 1], axis=0)[0]
    out = np.zeros((m.shape[0], red.n_out))
    for k, cols, pos in red.groups:
        if k == 1:
            out[:, pos] = m[:, cols[:, 0]]
        else:
            # np.take gives C order (m[:, cols] would not): each mean is then summed along a contiguous
            # row of k values, as reduce_body_part sums it
            out[:, pos] = np.add.reduce(np.take(m, cols, axis=1) / k, axis=2)
    return out


def _describe_type(cell_type: CellType, parts: tuple[tuple[int, BodyPart], ...], cells: Mapping[int, CellSignals],
                   threshold_n: float, channels: str,
                   part_ids: tuple[tuple[int, ...], ...] | None = None,
                   stacked: dict | None = None, stacks: CellStacks | None = None) -> list[BodyPartDescriptor]:
    """The descriptors of every body part of one cell type: one kernel call for all their cells.

    Gate, saturation check and per-cell quantities run once on the cells in
    contact of all these body parts stacked; the averages per body part are
    then taken together (:func:`_reduce_parts`).  Values and flags are
    identical to :func:`_body_part_descriptor` per body part: cells of
    different window shapes or dtypes, float data and integer data too large
    for exact moments take that path.  ``part_ids``: each body part's cell
    ids (from the robot's cached plan).  ``stacked``: filled as
    :func:`_type_features` says, for the groups computed after.
    ``stacks``: the window's cells as rows of shared arrays, read instead of
    stacking them where they are the cells described (:class:`CellStacks`).
    """
    labels = body_part_layout(cell_type, channels)
    red = _reduction(cell_type, channels)
    if part_ids is None:
        part_ids = tuple(tuple(c.id for c in part.cells) for _, part in parts)
    flags: list[int] = []
    n_usable: list[int] = []
    usable_ids: list[int] = []
    sigs: list[CellSignals] = []
    get = cells.get
    for ids in part_ids:
        quality = 0
        n_present = 0
        n_valid = len(sigs)
        bad = False
        for cid in ids:
            sig = get(cid)
            if sig is None:
                continue
            n_present += 1
            if sig.gap:
                quality |= _GAP
            if sig.invalid_samples:
                bad = True
            if sig.valid:
                usable_ids.append(cid)
                sigs.append(sig)
        n_valid = len(sigs) - n_valid
        if n_present < len(ids):
            quality |= _GAP
        if bad or n_valid < n_present:
            quality |= _INVALID
        flags.append(quality)
        n_usable.append(n_valid)
    if stacks is not None and stacks.force_n.shape[1] and stacks.force_n.dtype == np.float64 \
            and stacks.holds(sigs, "force_n"):
        means = _row_means(stacks.force_n)
    else:
        means = _force_means([s.force_n for s in sigs])
    gate = means >= threshold_n
    if gate.all():
        touching_sigs, touching_ids = sigs, usable_ids
        counts = np.array(n_usable, dtype=np.intp)
        touching_means = means
    else:
        on_k = np.flatnonzero(gate)
        touching_sigs = [sigs[k] for k in on_k.tolist()]
        touching_ids = [usable_ids[k] for k in on_k.tolist()]
        counts = np.bincount(np.repeat(np.arange(len(part_ids)), n_usable)[on_k],
                             minlength=len(part_ids)).astype(np.intp)
        touching_means = means[on_k]
    if not touching_sigs:
        return [BodyPartDescriptor(part.name, part.cell_type, np.zeros(len(labels)), labels, False, 0,
                                   len(part.cells), 0.0, quality | _NO_CONTACT)
                for (_, part), quality in zip(parts, flags)]
    if not _uniform_integers(touching_sigs):
        _check_channels(touching_sigs, cell_type, touching_ids)
        return [_body_part_descriptor(part, cell_type, cells, threshold_n, channels) for _, part in parts]
    if touching_sigs[0].vibration.shape[0] != red.n_s or touching_sigs[0].deformation.shape[0] != red.n_v:
        _check_channels(touching_sigs[:1], cell_type, touching_ids[:1])  # all have the first one's shape
    out: list[BodyPartDescriptor] = []
    feats = _type_features(touching_sigs, cell_type, stacked, stacks)
    if feats is None:
        # the kernel would take float paths whose rounding depends on the batch: keep the body-part batches
        return [_body_part_descriptor(part, cell_type, cells, threshold_n, channels) for _, part in parts]
    feats, saturated = feats
    counts_l = counts.tolist()
    on = counts.nonzero()[0]
    starts_all = np.zeros(len(counts_l), dtype=np.intp)
    counts[:-1].cumsum(out=starts_all[1:])
    starts_on = starts_all[on]
    values = _reduce_parts(feats, starts_on, counts[on], cell_type, channels, red)
    cell_q = feats.quality | np.where(saturated, np.uint32(_SATURATED), np.uint32(0)) if saturated.any() \
        else feats.quality
    part_q = np.bitwise_or.reduceat(cell_q, starts_on).tolist()
    starts_l = starts_all.tolist()
    single = touching_means.tolist()
    row = 0
    for p, ((_, part), quality) in enumerate(zip(parts, flags)):
        n = counts_l[p]
        if n == 0:
            out.append(BodyPartDescriptor(part.name, part.cell_type, np.zeros(len(labels)), labels, False, 0,
                                          len(part.cells), 0.0, quality | _NO_CONTACT))
            continue
        s0 = starts_l[p]
        out.append(BodyPartDescriptor(part.name, part.cell_type, values[row], labels, True, n,
                                      len(part.cells),
                                      single[s0] if n == 1 else float(np.add.reduce(touching_means[s0:s0 + n]) / n),
                                      quality | part_q[row]))
        row += 1
    return out


#: Cells are stacked and computed in chunks of about this many fast samples
#: (reused buffers that stay in the cache between stacking and the kernel;
#: bounds the memory of 10,000-cell skins).
STACK_CHUNK_SAMPLES = 1 << 20


def _type_features(sigs: list[CellSignals], cell_type: CellType, stacked: dict | None = None,
                   stacks: CellStacks | None = None) -> tuple[CellFeatures, np.ndarray] | None:
    """Per-cell quantities and saturation of integer cells of one shape, in chunks of cells.

    Returns None when the data are too large for exact integer moments (the
    kernel's results would then depend on how cells are batched).  Chunks
    are stacked into reused buffers; with exact moments every cell's
    quantities are the same whatever the chunk, so chunking changes nothing.
    When all cells fit one chunk and ``stacked`` is a dict, it receives
    ``sigs`` and that chunk's ``vibration`` and ``deformation`` stacks
    (valid until this function's next call), which the other feature
    groups then read instead of stacking the same cells again.  ``stacks``:
    when the cells are its cells (:meth:`CellStacks.holds`), its arrays are
    the stacks (no copy).
    """
    s0, v0 = sigs[0].vibration, sigs[0].deformation
    n_fast, n_slow = s0.shape[1], v0.shape[1]
    n_max = max(n_fast, n_slow)
    if float(n_max) ** 3 >= 2.0**52:
        return None
    step = max(1, STACK_CHUNK_SAMPLES // max(1, s0.size))
    parts: list[CellFeatures] = []
    saturated = np.zeros(len(sigs), dtype=bool)
    own = step >= len(sigs) and stacks is not None and stacks.vibration.dtype == s0.dtype \
        and stacks.deformation.dtype == v0.dtype and stacks.holds(sigs, *_STACKED_FIELDS[:4])
    for c0 in range(0, len(sigs), step):
        chunk = sigs[c0:c0 + step]
        if own:  # the window's own stacks (the cells are their rows)
            vib, dfm = stacks.vibration, stacks.deformation
            ts, tv = stacks.vibration_t_ns, stacks.deformation_t_ns
        else:
            # np.stack, without its per-array expand_dims: the rows of all cells concatenated into the buffer
            vib = scratch("agg.vib", (len(chunk),) + s0.shape, s0.dtype)
            np.concatenate([s.vibration for s in chunk], out=vib.reshape(len(chunk) * s0.shape[0], n_fast))
            dfm = scratch("agg.dfm", (len(chunk),) + v0.shape, v0.dtype)
            np.concatenate([s.deformation for s in chunk], out=dfm.reshape(len(chunk) * v0.shape[0], n_slow))
            ts = _shared_or_stacked([s.vibration_t_ns for s in chunk])
            tv = _shared_or_stacked([s.deformation_t_ns for s in chunk])
        fs_s, fs_v = cell_type.vibration.rate_hz, cell_type.deformation.rate_hz
        # the compiled kernel computes exact quantities (batch-independent) and each cell's bounds in one pass
        if stacked is not None and step >= len(sigs):
            stacked.update(sigs=sigs, vibration=vib, deformation=dfm)
        done = cell_quantities_bounded(vib, ts, dfm, tv, fs_s, fs_v)
        if done is not None:
            quantities, bounds = done
            lo, hi = bounds.min(axis=0).tolist(), bounds.max(axis=0).tolist()
            (lo_s, hi_s), (lo_v, hi_v) = cell_type.vibration.adc_range, cell_type.deformation.adc_range
            # _saturated's own first test, for both modalities and every cell at once (two reductions of
            # ``bounds``, not four plus two property reads): in most windows no cell reaches a limit
            if lo[0] <= lo_s or hi[1] >= hi_s or lo[2] <= lo_v or hi[3] >= hi_v:
                saturated[c0:c0 + len(chunk)] = (_saturated(vib, bounds[:, 0], bounds[:, 1], cell_type.vibration)
                                                 | _saturated(dfm, bounds[:, 2], bounds[:, 3], cell_type.deformation))
            parts.append(CellFeatures(*quantities))
            continue
        peaks, sat = _peaks_and_saturation(vib, dfm, cell_type)
        if not exact_integer_ok(n_max, *peaks):
            return None
        saturated[c0:c0 + len(chunk)] = sat
        # cell_features without its float checks (integer data)
        parts.append(CellFeatures(*cell_quantities(vib, ts, dfm, tv, fs_s, fs_v)))
    if len(parts) == 1:
        return parts[0], saturated
    return CellFeatures(*(np.concatenate([getattr(f, name) for f in parts])
                          for name in CellFeatures.__dataclass_fields__)), saturated


def _uniform_integers(sigs: list[CellSignals]) -> bool:
    """All cells' vibration and deformation are integer ndarrays of the first cell's shapes and dtypes."""
    s0, v0 = sigs[0].vibration, sigs[0].deformation
    if not (isinstance(s0, np.ndarray) and isinstance(v0, np.ndarray)) or s0.ndim != 2 or v0.ndim != 2 \
            or s0.dtype.kind not in "iu" or v0.dtype.kind not in "iu":
        return False
    shape_s, shape_v, dt_s, dt_v = s0.shape, v0.shape, s0.dtype, v0.dtype
    nd = np.ndarray
    for sig in sigs:
        s, v = sig.vibration, sig.deformation
        if not ((s.__class__ is nd or isinstance(s, nd)) and (v.__class__ is nd or isinstance(v, nd))) \
                or s.shape != shape_s or v.shape != shape_v or not (s.dtype is dt_s or s.dtype == dt_s) \
                or not (v.dtype is dt_v or v.dtype == dt_v):
            return False
    return True


def _shared_or_stacked(times: list) -> np.ndarray:
    """The cells' time stamps: one row when every cell holds the same array, else stacked (n_cells, n).

    (Equal stamps in different arrays are found by the kernel, which groups
    cells sharing time bases.)
    """
    t0 = times[0]
    if len(set(map(id, times))) == 1:
        return np.asarray(t0, dtype=np.int64)
    return _stack_times(times)


def _peaks_and_saturation(vib: np.ndarray, dfm: np.ndarray, cell_type: CellType
                          ) -> tuple[tuple[float, float], np.ndarray]:
    """Largest magnitudes of the stacked integer cells, and per cell whether it is
    saturated as :func:`_saturation` judges it (over 1 % of a modality's samples at its ADC limits)."""
    saturated = np.zeros(vib.shape[0], dtype=bool)
    peaks = []
    for a, mod in ((vib, cell_type.vibration), (dfm, cell_type.deformation)):
        if a.size == 0:
            peaks.append(0.0)
            continue
        a_min, a_max = cell_bounds(a)
        peaks.append(float(max(abs(int(a_min.min())), abs(int(a_max.max())))))
        saturated |= _saturated(a, a_min, a_max, mod)
    return (peaks[0], peaks[1]), saturated


def _saturated(a: np.ndarray, a_min: np.ndarray, a_max: np.ndarray, mod) -> np.ndarray:
    """Per cell of ``a`` (cell, channel, sample) with bounds ``a_min``, ``a_max``: over 1 % of its samples at the
    modality's ADC limits (:func:`_saturation`)."""
    out = np.zeros(a.shape[0], dtype=bool)
    lo, hi = mod.adc_range
    if a.size == 0 or (int(a_min.min()) > lo and int(a_max.max()) < hi):
        return out  # no cell reaches the limits
    near = np.flatnonzero((a_min <= lo) | (a_max >= hi))
    if near.size:
        sub = a[near]
        at_limit = np.count_nonzero((sub <= lo) | (sub >= hi), axis=(1, 2))
        out[near] = at_limit > 0.01 * a.shape[1] * a.shape[2]
    return out


def pool_body_parts(robot: RobotDescription, parts: tuple[BodyPartDescriptor, ...]
                    ) -> tuple[np.ndarray, tuple[str, ...]]:
    """Pooled descriptor: per cell type, the mean over its body parts in contact.

    Cell types appear in the order of their first body part; a cell type
    with no body part in contact contributes zeros.
    """
    values, labels = [], []
    order: list[str] = []
    for p in robot.body_parts:
        if p.cell_type not in order:
            order.append(p.cell_type)
    for ct in order:
        mine = [bp for bp in parts if bp.cell_type == ct]
        touching = [bp.values for bp in mine if bp.contact]
        values.append(_finite_mean(np.asarray(touching), axis=0) if touching else np.zeros(len(mine[0].labels)))
        labels += [f"{ct}/{lab}" for lab in mine[0].labels]
    return np.concatenate(values), tuple(labels)


def resolve_groups(robot: RobotDescription, channels: str | None = None,
                   groups: tuple[str, ...] | None = None) -> tuple[str, ...]:
    """The feature-group selection a description asks for: ``groups`` when given, else the groups of the
    legacy ``channels`` mode (:func:`.groups.groups_of_channels`), else the robot description's
    ``descriptor.groups`` (as :func:`describe_window` resolves its arguments)."""
    if groups is not None:
        return tuple(groups)
    if channels is not None:
        return groups_of_channels(channels)
    return robot.descriptor.groups


def _touching(part_ids: tuple[tuple[int, ...], ...], cells: Mapping[int, CellSignals],
              threshold_n: float) -> list[list[int]]:
    """Per body part, the ids of its valid cells in contact (eq. 13; the gate of :func:`_describe_type`)."""
    usable = [[cid for cid in ids if cid in cells and cells[cid].valid] for ids in part_ids]
    means = _force_means([cells[cid].force_n for ids in usable for cid in ids]).tolist()  # as _describe_type
    out, k = [], 0
    for ids in usable:
        out.append([cid for cid, m in zip(ids, means[k:k + len(ids)]) if m >= threshold_n])
        k += len(ids)
    return out


def _stack(arrays: list[np.ndarray], slot: str | None = None) -> np.ndarray:
    """``numpy.stack`` of the arrays; into the reused buffer ``slot`` (:func:`.fast.scratch`) when they are
    ndarrays of one shape and dtype (valid until that slot's next use)."""
    a0 = arrays[0] if arrays else None
    if slot is None or not isinstance(a0, np.ndarray) or a0.ndim == 0 \
            or not all(isinstance(a, np.ndarray) and a.shape == a0.shape and a.dtype == a0.dtype for a in arrays):
        return np.stack([np.asarray(a) for a in arrays])
    out = scratch(slot, (len(arrays),) + a0.shape, a0.dtype)
    np.concatenate(arrays, out=out.reshape((len(arrays) * a0.shape[0],) + a0.shape[1:]))
    return out


def _extra_of(sig: CellSignals, cell_type: CellType, cid: int) -> np.ndarray:
    n_x, n_slow = len(cell_type.extra_channels), np.shape(sig.deformation)[1]
    if sig.extra is None:
        return np.full((n_x, n_slow), np.nan)
    extra = np.asarray(sig.extra, dtype=np.float64)
    if extra.shape != (n_x, n_slow):
        raise SignalError(f"cell {cid}: expected extra channels of shape ({n_x}, {n_slow}) "
                          f"({', '.join(cell_type.extra_channels) or 'none'}, one value per deformation sample) "
                          f"for cell type {cell_type.name!r}, got {extra.shape}")
    return extra


def _extras_of(sigs: list[CellSignals], cell_type: CellType, ids: list[int]) -> np.ndarray:
    """The cells' extra channels stacked, shape (n_cells, n_extra, n_slow) (:func:`_extra_of` per cell)."""
    n_x, n_slow = len(cell_type.extra_channels), np.shape(sigs[0].deformation)[1]
    out = _float64_stack([s.extra for s in sigs], (n_x, n_slow))
    return out if out is not None else _stack([_extra_of(s, cell_type, cid) for s, cid in zip(sigs, ids)])


def _tares_of(sigs: list[CellSignals], n_v: int, ids: list[int]) -> np.ndarray:
    """The cells' deformation tares stacked, shape (n_cells, n_v): zeros at once when no cell has one."""
    tares = [s.deformation_tare for s in sigs]
    if all(t is None for t in tares):
        return np.zeros((len(sigs), n_v))
    out = _float64_stack(tares, (n_v,))
    return out if out is not None else _stack([_tare_of(s, n_v, cid) for s, cid in zip(sigs, ids)])


def _float64_stack(arrays: list, shape: tuple[int, ...]) -> np.ndarray | None:
    """The arrays stacked with one concatenation when all are float64 ndarrays of ``shape`` (a window cut by
    the windower), else None (the caller then checks and converts cell by cell)."""
    nd = np.ndarray
    if not all(a.__class__ is nd and a.dtype == np.float64 and a.shape == shape for a in arrays):
        return None
    out = np.empty((len(arrays),) + shape)
    if out.size:
        np.concatenate(arrays, out=out.reshape((len(arrays) * shape[0],) + shape[1:]))
    return out


def _tare_of(sig: CellSignals, n_v: int, cid: int) -> np.ndarray:
    if sig.deformation_tare is None:
        return np.zeros(n_v)
    tare = np.asarray(sig.deformation_tare, dtype=np.float64)
    if tare.shape != (n_v,):
        raise SignalError(f"cell {cid}: deformation_tare must hold {n_v} values, got shape {tare.shape}")
    return tare


def _group_rows(cell_type: CellType, groups: list[str], sigs: list[CellSignals], ids: list[int],
                stacked: dict | None = None, stacks: CellStacks | None = None) -> dict[str, np.ndarray]:
    """Per-cell values of the non-kernel groups, cells of one window shape stacked and computed together.

    ``stacked``: the kernel's stacks of these same cells (:func:`_type_features`), read as they are;
    ``stacks``: the window's (:class:`CellStacks`), whose extra channels are read when they are these cells'.
    """
    fs_s, fs_v = cell_type.vibration.rate_hz, cell_type.deformation.rate_hz
    n_v = len(cell_type.deformation.channels)
    out: dict[str, list | np.ndarray] = {g: [None] * len(sigs) for g in groups}
    shared = bool(stacked) and len(stacked["sigs"]) == len(sigs) and all(a is b for a, b in zip(stacked["sigs"], sigs))
    batches: dict[tuple, list[int]] = {}
    if shared:  # the kernel stacked these cells, all of one shape
        batches[()] = list(range(len(sigs)))
    else:
        for k, sig in enumerate(sigs):
            batches.setdefault((np.shape(sig.vibration), np.shape(sig.deformation)), []).append(k)
    for rows in batches.values():
        row_sigs, row_ids = [sigs[k] for k in rows], [ids[k] for k in rows]
        if shared:
            vib, dfm = stacked["vibration"], stacked["deformation"]
        else:
            vib = _stack([s.vibration for s in row_sigs], "groups.vib")
            dfm = _stack([s.deformation for s in row_sigs], "groups.dfm")
        spectrum = None  # the vibration's power spectrum, shared by bands and statistics
        tares = extras = None  # the cells' tares and extra channels, stacked once for the groups that read them
        for g in groups:
            with np.errstate(all="ignore"):  # non-finite samples give non-finite values: _cells_mean drops them
                if g in ("bands", "statistics") and spectrum is None:
                    n_bins = spectral_length(vib.shape[-1]) // 2 + 1
                    spectrum = power_spectrum(vib, out=scratch("groups.spectrum", vib.shape[:-1] + (n_bins,),
                                                               np.float64))
                if g == "bands":
                    vals = band_hjorth(vib, fs_s, spectrum)
                elif g == "statistics":
                    vals = statistics_values(vib, fs_s, dfm, fs_v, spectrum)
                else:
                    if extras is None:
                        extras = (stacks.extra if shared and stacks is not None and stacks.extra is not None
                                  and stacks.extra.dtype == np.float64 and stacks.holds(row_sigs, "extra")
                                  else _extras_of(row_sigs, cell_type, row_ids))
                    if g == "plain":
                        vals = plain_values(vib, dfm, extras)
                    else:
                        if tares is None:
                            tares = _tares_of(row_sigs, n_v, row_ids)
                        vals = (rocket_values(cell_type, vib, dfm, tares, extras) if g == "rocket"
                                else level_values(cell_type, g, dfm, tares, extras))
            if len(batches) == 1:  # one window shape (the common case): the rows are the cells, in order
                out[g] = vals
                continue
            for r, k in enumerate(rows):
                out[g][k] = vals[r]
    return {g: v if isinstance(v, np.ndarray) else np.stack(v) for g, v in out.items()}


def _cells_mean(rows: np.ndarray) -> tuple[np.ndarray, bool]:
    """Mean over cells (rows) of each column's finite values; a column without any is 0 (and reported)."""
    ok = np.isfinite(rows)
    if ok.all():
        return _finite_mean(rows, axis=0), False
    cnt = ok.sum(axis=0)
    vals = np.sum(np.where(ok, rows, 0.0) / np.maximum(cnt, 1), axis=0)
    return np.where(cnt > 0, vals, 0.0), bool((cnt == 0).any() or not ok.all())


def _describe_groups(cell_type: CellType, parts: tuple[tuple[int, BodyPart], ...],
                     cells: Mapping[int, CellSignals], threshold_n: float, groups: tuple[str, ...],
                     part_ids: tuple[tuple[int, ...], ...], stacks: CellStacks | None = None
                     ) -> list[BodyPartDescriptor]:
    """The body parts of one cell type described by a group selection (:mod:`.groups`, :mod:`.features`).

    The kernel groups (``paper``, ``per_channel``) come from
    :func:`_describe_type`, which also decides contact, cell counts, mean
    force and quality; the other groups are computed per cell in contact
    and averaged over a body part's cells.  Missing extra channels (no finite
    sample in the window) give 0 and flag the body part ``INVALID``;
    non-finite values of the other groups give 0 and flag ``NONFINITE``.
    """
    labels = selection_labels(cell_type, groups)
    modes = [KERNEL_GROUPS[g] for g in groups if g in KERNEL_GROUPS] or ["averaged"]
    stacked: dict = {}  # the last kernel call's stacks of the cells in contact, for the other groups
    base = {m: _describe_type(cell_type, parts, cells, threshold_n, m, part_ids, stacked, stacks) for m in modes}
    first = base[modes[0]]
    if len(groups) == 1 and groups[0] in KERNEL_GROUPS:  # one kernel group: the kernel's values as they are
        for bp in first:  # made by this call: relabelled in place
            bp.labels = labels
        return first
    others = [g for g in groups if g not in KERNEL_GROUPS]
    per_part: list[dict[str, np.ndarray]] = [{} for _ in parts]
    flags = [0] * len(parts)
    if others and any(bp.contact for bp in first):
        touching = _touching(part_ids, cells, threshold_n)
        ids = [cid for t in touching for cid in t]
        rows = _group_rows(cell_type, others, [cells[cid] for cid in ids], ids, stacked, stacks)
        for p, t in enumerate(touching):
            if len(t) != first[p].cells_in_contact:
                raise SignalError(f"body part {first[p].name}: contact gate disagreement ({len(t)} vs "
                                  f"{first[p].cells_in_contact} cells)")
        counts = [len(t) for t in touching]
        for g in others:
            r = rows[g]
            if all(c <= 1 for c in counts) and np.isfinite(r).all():  # one cell per body part (a hand)
                k = 0
                for p, c in enumerate(counts):
                    if c:
                        per_part[p][g] = r[k]
                        k += 1
                continue
            start = 0
            for p, c in enumerate(counts):
                if c:
                    vals, bad = _cells_mean(r[start:start + c])
                    per_part[p][g] = vals
                    if bad:
                        flags[p] |= _INVALID if g.startswith(("levels", "plain", "rocket")) else int(Quality.NONFINITE)
                start += c
    out = []
    for p, bp in enumerate(first):
        if not bp.contact:
            out.append(BodyPartDescriptor(bp.name, bp.cell_type, np.zeros(len(labels)), labels, False, 0,
                                          bp.cells_total, bp.mean_force_n, bp.quality))
            continue
        values = np.concatenate([base[KERNEL_GROUPS[g]][p].values if g in KERNEL_GROUPS else per_part[p][g]
                                 for g in groups])
        quality = bp.quality | flags[p]
        for m in modes[1:]:
            quality |= base[m][p].quality
        out.append(BodyPartDescriptor(bp.name, bp.cell_type, values, labels, True, bp.cells_in_contact,
                                      bp.cells_total, bp.mean_force_n, quality))
    return out


def describe_window(robot: RobotDescription, cells: Mapping[int, CellSignals], *,
                    layout: str | None = None, channels: str | None = None,
                    groups: tuple[str, ...] | None = None,
                    force_threshold_n: float | None = None, stacks: CellStacks | None = None) -> RobotDescriptor:
    """Compute the robot's descriptor of one window.

    Parameters
    ----------
    robot : RobotDescription
        Body parts, cells and cell types.
    cells : mapping of cell id to CellSignals
        The window's data; a configured cell missing here is treated as not
        in contact and flags its body part ``GAP``.
    layout : {"concat", "pooled"}, optional
        Defaults to the robot description's.
    channels : {"averaged", "per_channel"}, optional
        The legacy channel mode: ``averaged`` is the groups ``("paper",)``,
        ``per_channel`` the groups ``("per_channel",)``.
    groups : tuple of str, optional
        Feature groups in descriptor order (:mod:`.groups`); defaults to
        ``channels``' groups when that is given, else the robot
        description's ``descriptor.groups``.
    force_threshold_n : float, optional
        F_t; defaults to the robot description's contact threshold.
    stacks : CellStacks, optional
        The window's cells as rows of shared arrays (a window the windower
        cut, :class:`.windowing.Window`): read instead of stacking the cells
        again where they are the cells described; the values are the same.

    Returns
    -------
    RobotDescriptor
        Labels ``<body part>/<group>/<label>`` (``<cell type>/<group>/<label>``
        when pooled); ``channels`` names the selection.

    Raises
    ------
    SignalError
        For a cell id not in the robot description, or channel counts that do
        not match the cell type.
    ConfigError
        For a group selection a cell type cannot feed (:func:`.groups.check_groups`).
    """
    layout = layout or robot.descriptor.layout
    groups = resolve_groups(robot, channels, groups)
    threshold = robot.contact.force_threshold_n if force_threshold_n is None else float(force_threshold_n)
    plan = robot_plan(robot)
    unknown = cells.keys() - plan.index.keys()
    if unknown:
        unknown = sorted(unknown)
        raise SignalError(f"cells {unknown} are not in robot description {robot.name!r}")
    # One batch per cell type (gate, saturation, kernel), then the averages per body part.
    by_pos: dict[int, BodyPartDescriptor] = {}
    for (cell_type, parts_of_type), part_ids in zip(plan.types, plan.part_ids):
        check_groups(cell_type, groups)
        descs = _describe_groups(cell_type, parts_of_type, cells, threshold, groups, part_ids, stacks)
        by_pos.update(zip((pos for pos, _ in parts_of_type), descs))
    parts = tuple(by_pos[pos] for pos in range(len(robot.body_parts)))
    if layout == "concat":
        values = np.concatenate([bp.values for bp in parts])
        labels = plan.concat_labels.get(groups)
        if labels is None:
            labels = plan.concat_labels[groups] = tuple(f"{bp.name}/{lab}" for bp in parts for lab in bp.labels)
    elif layout == "pooled":
        values, labels = pool_body_parts(robot, parts)
    else:
        raise SignalError(f"layout must be 'concat' or 'pooled', got {layout!r}")
    return RobotDescriptor(robot.name, layout, selection_name(groups), parts, values, labels)
