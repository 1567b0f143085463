"""Contact a controller can use: per body part and window of frames, pure numpy (no ROS).

For a window of frames of one body part (a frames message, or a display
period) :class:`ContactWindow` keeps, per cell, the mean force, the mean
deformation change from the driver's tare and the vibration's power, and
:func:`locate_contact` turns them into

* ``in_contact``: some cell's mean force is at or above ``F_t`` (the contact
  gate of eq. 13, 16, 27);
* ``force_n``: the body part's total normal force, the sum of its cells'
  forces at or above ``floor_n`` (the noise of untouched cells left out);
* the centre of pressure and the contact normal in the body part's frame:
  the force-weighted mean of the sensing points' positions and unit normals
  (:class:`~.geometry.Taxels`);
* the active cells (force at or above ``F_t``).

A skin body part's sensing points are its cells, weighted by their force.
A BioTac is one cell whose force comes from its pressure (PDC); its
electrodes locate the contact: each electrode's weight is the square of how
far its mean change from the tare departs from the median electrode's (the
rise every electrode shows under load is common mode; the electrodes nearest
the contact depart from it), and the BioTac's force is shared among the
electrodes in proportion (``taxel_force_n``), so a view colours them by the
force they carry.  The sign of the departure is not used: an electrode whose
impedance falls near the contact locates it as one that rises.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import ModuleType

import numpy as np

from ..errors import SignalError
from ..markers import INVALID_ACCEL, INVALID_COUNT
from .geometry import Taxels

__all__ = ["CellReduction", "reduce_chunk", "RunReductions", "reduce_skin_runs", "load_compiled", "ContactEstimate",
           "ContactWindow", "locate_contact", "site_weights", "contact_wrench"]


@dataclass(frozen=True)
class CellReduction:
    """What a contact needs of one cell's samples in one message.

    Attributes
    ----------
    force_sum_n, force_count : float, int
        Sum and number of the valid force samples [N].
    deformation_sum, deformation_count : numpy.ndarray, int
        Sum over the valid deformation samples of (sample - tare), per
        deformation channel [counts]; zeros and 0 when the driver reported no tare.
    vibration_sumsq, vibration_count : float, int
        Sum of squares of the valid vibration samples minus each channel's
        mean over the message, in the modality's unit, and their number.
    newest_ns, oldest_ns : int
        Stamps of the newest and the oldest valid force sample (-1 when none).
    """

    force_sum_n: float
    force_count: int
    deformation_sum: np.ndarray
    deformation_count: int
    vibration_sumsq: float
    vibration_count: int
    newest_ns: int
    oldest_ns: int = -1


def reduce_chunk(chunk, vibration_si_per_count: float = 1.0) -> CellReduction:
    """Reduce one :class:`~.windowing.CellChunk` (a cell's samples of one message) to a :class:`CellReduction`.

    Invalid samples (NaN force, ``vibration_valid``/``deformation_valid``
    False) are left out, never replaced.
    """
    force = np.asarray(chunk.force_n, dtype=float)
    ok = np.isfinite(force)
    n_f = int(ok.sum())
    newest = int(np.asarray(chunk.force_t_ns)[ok].max()) if n_f else -1
    oldest = int(np.asarray(chunk.force_t_ns)[ok].min()) if n_f else -1
    dfm = np.asarray(chunk.deformation, dtype=float)
    tare = chunk.deformation_tare
    d_ok = np.ones(dfm.shape[1], bool) if chunk.deformation_valid is None else np.asarray(chunk.deformation_valid)
    if tare is not None and np.size(tare) == dfm.shape[0] and d_ok.any():
        d_sum = (dfm[:, d_ok] - np.asarray(tare, dtype=float)[:, None]).sum(axis=1)
        d_n = int(d_ok.sum())
    else:
        d_sum, d_n = np.zeros(dfm.shape[0]), 0
    vib = np.asarray(chunk.vibration, dtype=float)
    v_ok = np.ones(vib.shape[1], bool) if chunk.vibration_valid is None else np.asarray(chunk.vibration_valid)
    v = vib[:, v_ok]
    if v.shape[1] >= 2:
        ac = (v - v.mean(axis=1, keepdims=True)) * float(vibration_si_per_count)
        sumsq, n_v = float(np.sum(ac * ac)), int(ac.size)
    else:
        sumsq, n_v = 0.0, 0
    return CellReduction(float(force[ok].sum()), n_f, d_sum, d_n, sumsq, n_v, newest, oldest)


@dataclass(frozen=True)
class RunReductions:
    """:class:`CellReduction` of several cell runs at once (arrays over runs), for a body part's message."""

    cell_ids: np.ndarray
    force_sum_n: np.ndarray
    force_count: np.ndarray
    deformation_sum: np.ndarray  # (runs, n_deformation)
    deformation_count: np.ndarray
    vibration_sumsq: np.ndarray
    vibration_count: np.ndarray
    newest_ns: np.ndarray
    oldest_ns: np.ndarray


def _run_starts(counts: np.ndarray) -> np.ndarray:
    return np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.intp)


def _sum_runs(values: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Sum of ``values`` (last axis: samples) over consecutive runs of ``counts`` samples (empty runs give 0)."""
    out = np.zeros(values.shape[:-1] + (counts.size,))
    if values.shape[-1]:
        run = np.repeat(np.arange(counts.size), counts)
        for idx in np.ndindex(values.shape[:-1]):
            out[idx] = np.bincount(run, weights=values[idx], minlength=counts.size)
    return out


def _run_sums(fc: np.ndarray, f: np.ndarray, tare: np.ndarray, off: np.ndarray, stamp_ns: int, ac: np.ndarray,
              a: np.ndarray, a_scale: float, invalid_count: int, invalid_accel: int) -> tuple[np.ndarray, ...]:
    """Each run's sums for :func:`reduce_skin_runs` with numpy: the sensors' tared sums (3, runs), the valid
    force samples (float), the accelerometer's sums and sums of squares (3, runs), its valid samples (float),
    the newest and oldest valid force stamps (-1 without one)."""
    run_of_f = np.repeat(np.arange(fc.size), fc)
    f_ok = np.all(f != invalid_count, axis=1)
    dev = f.astype(float) - tare[run_of_f]  # (k, 3) counts from the tare
    dev_ok = np.where(f_ok[:, None], dev, 0.0)
    d_sum = _sum_runs(dev_ok.T, fc)  # (3, runs)
    n_ok = _sum_runs(f_ok.astype(float)[None, :], fc)[0]
    newest = np.full(fc.size, -1, dtype=np.int64)
    oldest = np.full(fc.size, np.iinfo(np.int64).max, dtype=np.int64)
    if f.shape[0]:
        t = off + stamp_ns
        np.maximum.at(newest, run_of_f, np.where(f_ok, t, -1))
        np.minimum.at(oldest, run_of_f, np.where(f_ok, t, np.iinfo(np.int64).max))
    oldest[newest < 0] = -1
    a_ok = np.all(a != invalid_accel, axis=0)
    x = np.where(a_ok[None, :], a.astype(float), 0.0) * a_scale
    na = _sum_runs(a_ok.astype(float)[None, :], ac)[0]
    return d_sum, n_ok, _sum_runs(x, ac), _sum_runs(x * x, ac), na, newest, oldest


#: Whether :func:`reduce_skin_runs` sums with the compiled backend when it is loaded (the tests switch it off
#: to compare both paths).
COMPILED_SUMS = True


def _run_sums_compiled(fc: np.ndarray, f: np.ndarray, tare: np.ndarray, off: np.ndarray, stamp_ns: int,
                       ac: np.ndarray, a: np.ndarray, a_scale: float, invalid_count: int, invalid_accel: int
                       ) -> tuple[np.ndarray, ...] | None:
    """:func:`_run_sums` in one compiled pass (:func:`.numba_kernel.skin_run_sums`), equal to the bit; None
    where it does not serve: no compiled backend, other dtypes than a ``SkinPartFrames``' (uint16 force,
    int16 accelerometer, float64 tares), or arrays of another layout (:func:`.fast.loaded_layout`).

    The numpy sums took 11 ``bincount`` calls and a dozen array operations a message, about 100 us of
    the contact node's 390 us for a NAO body part's message.
    """
    from . import fast

    kernel = _sums_kernel()
    if kernel is None or f.dtype != np.uint16 or a.dtype != np.int16 or tare.dtype != np.float64 \
            or not fast.loaded_layout(fc, f, tare, off, ac, a):
        return None
    runs = fc.size
    d_sum, s1, s2 = np.empty((3, runs)), np.empty((3, runs)), np.empty((3, runs))
    n_ok, na = np.empty(runs), np.empty(runs)
    newest, oldest = np.empty(runs, np.int64), np.empty(runs, np.int64)
    kernel.skin_run_sums(fc, f, tare, off, stamp_ns, ac, a, a_scale, invalid_count, invalid_accel, d_sum, n_ok,
                         s1, s2, na, newest, oldest)
    return d_sum, n_ok, s1, s2, na, newest, oldest


def load_compiled() -> bool:
    """Load the compiled sums of :func:`reduce_skin_runs` now (numba's import and its cache, about 0.3 s; a
    compilation when the cache is empty), so that a node's first message does not wait for them; False where
    numpy serves.  A contact node serving skin cells calls it when it starts."""
    from . import fast

    kernel = _sums_kernel()
    if kernel is None:
        return False
    fast.warm_up_contact(kernel)
    return True


def _sums_kernel() -> ModuleType | None:
    """The compiled backend's module when :func:`reduce_skin_runs` may use it (:data:`COMPILED_SUMS`), else None."""
    from . import fast

    return fast.kernel_module() if COMPILED_SUMS else None


def reduce_skin_runs(cell_ids: np.ndarray, force: np.ndarray, force_count: np.ndarray, force_offset_ns: np.ndarray,
                     force_tare: np.ndarray, force_n_per_count: float, accel: np.ndarray, accel_count: np.ndarray,
                     accel_si_per_count: float, stamp_ns: int, *, invalid_count: int = INVALID_COUNT,
                     invalid_accel: int = INVALID_ACCEL) -> RunReductions:
    """Reduce every cell run of a skin body part's message at once (``SkinPartFrames``' arrays, vectorised).

    Parameters
    ----------
    cell_ids : numpy.ndarray, shape (runs,)
    force : numpy.ndarray of uint16, shape (k, 3)
        Counts of the three force sensors, every run's samples concatenated.
    force_count, accel_count : numpy.ndarray, shape (runs,)
    force_offset_ns : numpy.ndarray of int64, shape (k,)
    force_tare : numpy.ndarray, shape (runs, 3)
        [counts]
    force_n_per_count : float
    accel : numpy.ndarray of int16, shape (3, n)
    accel_si_per_count : float
    stamp_ns : int
        The message's stamp (offsets are from it).

    Returns
    -------
    RunReductions
        A cell's force is the mean of its three tared sensors times the scale
        (eq. 27); a sample with any sensor invalid is left out, so is an
        invalid accelerometer sample.

    Raises
    ------
    SignalError
        For arrays whose lengths do not match the run counts.
    """
    ids = np.asarray(cell_ids, dtype=np.int64)
    fc = np.asarray(force_count, dtype=np.int64)
    ac = np.asarray(accel_count, dtype=np.int64)
    f = np.asarray(force).reshape(-1, 3)
    a = np.asarray(accel).reshape(3, -1)
    tare = np.asarray(force_tare, dtype=float).reshape(-1, 3)
    off = np.asarray(force_offset_ns, dtype=np.int64)
    if not (ids.size == fc.size == ac.size == tare.shape[0]) or fc.sum() != f.shape[0] or ac.sum() != a.shape[1] \
            or off.size != f.shape[0]:
        raise SignalError(f"skin runs do not add up: {ids.size} runs, {f.shape[0]} force samples for counts summing "
                          f"to {fc.sum()}, {a.shape[1]} accelerometer samples for {ac.sum()}")
    args = (fc, f, tare, off, int(stamp_ns), ac, a, float(accel_si_per_count), invalid_count, invalid_accel)
    sums = _run_sums_compiled(*args)
    if sums is None:
        sums = _run_sums(*args)
    d_sum_3, n_ok_f, s1, s2, na, newest, oldest = sums
    d_sum = d_sum_3.T  # (runs, 3)
    n_ok = n_ok_f.astype(np.int64)
    force_sum = d_sum.mean(axis=1) * float(force_n_per_count)
    with np.errstate(invalid="ignore", divide="ignore"):
        ss = np.where(na >= 2, (s2 - s1 * s1 / np.maximum(na, 1)).sum(axis=0), 0.0)
    return RunReductions(ids, force_sum, n_ok, d_sum, n_ok.copy(), np.maximum(ss, 0.0),
                         np.where(na >= 2, 3 * na, 0).astype(np.int64), newest, oldest)


@dataclass(frozen=True)
class ContactEstimate:
    """The contact of one body part over one window (see the module docstring).

    Attributes
    ----------
    in_contact : bool
    force_n : float
        Total normal force [N].
    centre_of_pressure : numpy.ndarray, shape (3,)
        [m] in the body part's frame; zeros when no cell carries force.
    normal : numpy.ndarray, shape (3,)
        Unit contact normal (outward) in that frame; zeros when no cell carries force.
    cell_force_n : numpy.ndarray, shape (n_cells,)
        Mean force of each cell [N]; NaN for a cell without a valid sample.
    taxel_force_n : numpy.ndarray, shape (n_taxels,)
        Force carried by each sensing point [N] (a skin cell's is its force).
    active_cells : numpy.ndarray of int64
        Ids of the cells at or above ``F_t``.
    vibration_rms : float
        Root mean square of the vibration (each channel's mean removed) over
        every cell of the part, in the modality's unit; NaN without samples.
    """

    in_contact: bool
    force_n: float
    centre_of_pressure: np.ndarray
    normal: np.ndarray
    cell_force_n: np.ndarray
    taxel_force_n: np.ndarray
    active_cells: np.ndarray
    vibration_rms: float


def site_weights(change: np.ndarray) -> np.ndarray:
    """Weights of a cell's sensing sites from their mean deformation change [counts], shape (n_sites,).

    ``(change - median(change))**2``: the common-mode change every electrode
    shows under load is removed, what is left is how much more (or less) the
    electrodes near the contact changed; squared, so the few electrodes
    under the contact outweigh the many that moved a little (on the
    simulated touches this halves the error of the centre of pressure
    against the plain departure).  Zeros when no site departs.
    """
    change = np.asarray(change, dtype=float)
    if change.size == 0:
        return change
    return np.abs(change - np.median(change)) ** 2


def locate_contact(taxels: Taxels, cell_ids: np.ndarray, cell_force_n: np.ndarray,
                   site_change: np.ndarray | None = None, *, threshold_n: float, floor_n: float,
                   vibration_rms: float = float("nan")) -> ContactEstimate:
    """Contact of one body part from its cells' mean forces (and, for sites, their deformation change).

    Parameters
    ----------
    taxels : Taxels
        The body part's sensing points (:meth:`~.geometry.RobotGeometry.taxels`).
    cell_ids : numpy.ndarray of int, shape (n_cells,)
        The body part's cells, in the order of ``cell_force_n``.
    cell_force_n : numpy.ndarray, shape (n_cells,)
        Mean force of each cell over the window [N], NaN where none.
    site_change : numpy.ndarray, shape (n_taxels,), optional
        For ``taxels.kind == "sites"``: each site's mean deformation change
        from the tare [counts] (NaN where unknown); the sites of a cell then
        share its force by :func:`site_weights`, equally when none departs.
    threshold_n : float
        ``F_t``: a cell at or above it is active and the part in contact.
    floor_n : float
        Cells below it carry no force (their noise stays out of the sum and the centre).
    vibration_rms : float
        Passed through to the estimate.

    Returns
    -------
    ContactEstimate
    """
    ids = np.asarray(cell_ids, dtype=np.int64)
    forces = np.asarray(cell_force_n, dtype=float)
    if forces.shape != ids.shape:
        raise SignalError(f"{forces.size} cell forces for {ids.size} cells")
    index = {int(c): k for k, c in enumerate(ids)}
    try:
        owner = np.array([index[int(c)] for c in taxels.cell_ids], dtype=np.intp)
    except KeyError as exc:
        raise SignalError(f"taxel of cell {exc.args[0]} which is not among the body part's cells") from None
    carried = np.where(np.isfinite(forces) & (forces >= floor_n), forces, 0.0)
    if taxels.kind == "sites":
        change = np.full(len(taxels), np.nan) if site_change is None else np.asarray(site_change, dtype=float)
        if change.shape != (len(taxels),):
            raise SignalError(f"{change.size} site changes for {len(taxels)} sites")
        taxel_force = np.zeros(len(taxels))
        for k in range(ids.size):
            mine = np.flatnonzero(owner == k)
            if not mine.size or carried[k] <= 0:
                continue
            ch = change[mine]
            w = site_weights(np.where(np.isfinite(ch), ch, np.nanmedian(ch) if np.isfinite(ch).any() else 0.0))
            share = w / w.sum() if w.sum() > 0 else np.full(mine.size, 1.0 / mine.size)
            taxel_force[mine] = carried[k] * share
    else:
        taxel_force = carried[owner]
    total = float(taxel_force.sum())
    if total > 0:
        cop = (taxel_force[:, None] * taxels.positions).sum(axis=0) / total
        n = (taxel_force[:, None] * taxels.normals).sum(axis=0)
        norm = np.linalg.norm(n)
        normal = n / norm if norm > 0 else np.zeros(3)
    else:
        cop, normal = np.zeros(3), np.zeros(3)
    active = np.isfinite(forces) & (forces >= threshold_n)
    return ContactEstimate(bool(active.any()), float(carried.sum()), cop, normal, forces, taxel_force,
                           ids[active], float(vibration_rms))


class ContactWindow:
    """The samples of one body part over one window, reduced as they come (:class:`CellReduction`).

    Parameters
    ----------
    cell_ids : sequence of int
        The body part's cells, in the robot description's order.
    n_deformation : int
        Deformation channels of the cell type.
    """

    def __init__(self, cell_ids, n_deformation: int) -> None:
        self.cell_ids = np.asarray(cell_ids, dtype=np.int64)
        self._index = {int(c): k for k, c in enumerate(self.cell_ids)}
        # the cells sorted, for a vectorised lookup of a message's runs (add_runs)
        self._order = np.argsort(self.cell_ids, kind="stable")
        self._sorted = self.cell_ids[self._order]
        self.n_deformation = int(n_deformation)
        self.newest_ns = np.full(self.cell_ids.size, -1, dtype=np.int64)
        self.reset()

    def reset(self) -> None:
        """Start a new window (the cells' newest stamps are kept: they say which cells are stale)."""
        n = self.cell_ids.size
        self.force_sum = np.zeros(n)
        self.force_count = np.zeros(n, dtype=np.int64)
        self.deformation_sum = np.zeros((n, self.n_deformation))
        self.deformation_count = np.zeros(n, dtype=np.int64)
        self.vibration_sumsq = 0.0
        self.vibration_count = 0
        self.start_ns = -1
        self.end_ns = -1
        self.added = 0  # cell reductions or runs of this body part since the reset

    def _span(self, oldest: int, newest: int) -> None:
        if newest >= 0:
            self.end_ns = max(self.end_ns, newest)
        if oldest >= 0:
            self.start_ns = oldest if self.start_ns < 0 else min(self.start_ns, oldest)

    def add(self, cell_id: int, r: CellReduction) -> bool:
        """Add one cell's reduction; False (nothing added) for a cell not of this body part."""
        k = self._index.get(int(cell_id))
        if k is None:
            return False
        self.added += 1
        self.force_sum[k] += r.force_sum_n
        self.force_count[k] += r.force_count
        if r.deformation_count and r.deformation_sum.size == self.n_deformation:
            self.deformation_sum[k] += r.deformation_sum
            self.deformation_count[k] += r.deformation_count
        self.vibration_sumsq += r.vibration_sumsq
        self.vibration_count += r.vibration_count
        if r.newest_ns >= 0:
            self.newest_ns[k] = max(self.newest_ns[k], r.newest_ns)
        self._span(r.oldest_ns, r.newest_ns)
        return True

    def add_runs(self, runs: RunReductions) -> int:
        """Add several cell runs (:func:`reduce_skin_runs`); returns how many were not of this body part (left out)."""
        ids = np.asarray(runs.cell_ids, dtype=np.int64)
        pos = np.minimum(np.searchsorted(self._sorted, ids), self._sorted.size - 1)
        ok = self._sorted[pos] == ids if self._sorted.size else np.zeros(ids.size, bool)
        kk = self._order[pos[ok]]
        self.added += int(ok.sum())
        np.add.at(self.force_sum, kk, runs.force_sum_n[ok])
        np.add.at(self.force_count, kk, runs.force_count[ok])
        if runs.deformation_sum.shape[1:] == (self.n_deformation,):
            np.add.at(self.deformation_sum, kk, runs.deformation_sum[ok])
            np.add.at(self.deformation_count, kk, runs.deformation_count[ok])
        self.vibration_sumsq += float(runs.vibration_sumsq[ok].sum())
        self.vibration_count += int(runs.vibration_count[ok].sum())
        np.maximum.at(self.newest_ns, kk, runs.newest_ns[ok])
        have = ok & (runs.newest_ns >= 0)
        if have.any():
            self._span(int(runs.oldest_ns[have].min()), int(runs.newest_ns[have].max()))
        return int((~ok).sum())

    def merge(self, other: ContactWindow) -> bool:
        """Add everything ``other`` (a window of the same cells, e.g. one message's) holds; False if it holds nothing.

        Equal to adding ``other``'s reductions one by one (sums and counts
        add, the newest stamps and the span widen), at the cost of a few array
        additions: a display period collects its messages' windows this way.

        Raises
        ------
        SignalError
            For a window of other cells.
        """
        if other.cell_ids.shape != self.cell_ids.shape or not np.array_equal(other.cell_ids, self.cell_ids) \
                or other.n_deformation != self.n_deformation:
            raise SignalError("merge needs a window of the same cells and deformation channels")
        if not other.added:
            return False
        self.added += other.added
        self.force_sum += other.force_sum
        self.force_count += other.force_count
        self.deformation_sum += other.deformation_sum
        self.deformation_count += other.deformation_count
        self.vibration_sumsq += other.vibration_sumsq
        self.vibration_count += other.vibration_count
        np.maximum(self.newest_ns, other.newest_ns, out=self.newest_ns)
        self._span(other.start_ns, other.end_ns)
        return True

    @property
    def empty(self) -> bool:
        """No valid force sample since the last reset."""
        return not self.force_count.any()

    def cell_force_n(self) -> np.ndarray:
        """Mean force per cell over the window [N], NaN for a cell without a valid sample."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(self.force_count > 0, self.force_sum / np.maximum(self.force_count, 1), np.nan)

    def site_change(self, taxels: Taxels) -> np.ndarray | None:
        """Each site's mean deformation change over the window [counts] (``"sites"`` taxels; None otherwise)."""
        if taxels.kind != "sites":
            return None
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(self.deformation_count[:, None] > 0,
                            self.deformation_sum / np.maximum(self.deformation_count, 1)[:, None], np.nan)
        out = np.full(len(taxels), np.nan)
        for t, (cid, chans) in enumerate(zip(taxels.cell_ids, taxels.channels)):
            k = self._index.get(int(cid))
            if k is not None and chans:
                out[t] = float(np.mean(mean[k, list(chans)]))
        return out

    def vibration_rms(self) -> float:
        """RMS of the window's vibration (NaN without samples)."""
        return float(np.sqrt(self.vibration_sumsq / self.vibration_count)) if self.vibration_count else float("nan")

    def contact(self, taxels: Taxels, *, threshold_n: float, floor_n: float) -> ContactEstimate:
        """:func:`locate_contact` over this window."""
        return locate_contact(taxels, self.cell_ids, self.cell_force_n(), self.site_change(taxels),
                              threshold_n=threshold_n, floor_n=floor_n, vibration_rms=self.vibration_rms())

    def stale(self, now_ns: int, stale_s: float) -> np.ndarray:
        """Per cell: no valid force sample within ``stale_s`` before ``now_ns`` (sensor time)."""
        return (self.newest_ns < 0) | (now_ns - self.newest_ns > int(stale_s * 1e9))


def contact_wrench(estimate: ContactEstimate) -> tuple[np.ndarray, np.ndarray]:
    """The contact as a wrench at the body part frame's origin: force [N] and torque [N m].

    The environment pushes on the skin along the inward normal: ``f =
    -force_n * normal`` applied at the centre of pressure ``p``, i.e. ``f``
    and ``tau = p x f`` at the origin (``geometry_msgs/Wrench``'s convention).
    Zero without contact force.
    """
    f = -estimate.force_n * np.asarray(estimate.normal, dtype=float)
    p = np.asarray(estimate.centre_of_pressure, dtype=float)
    # p x f written out: numpy.cross costs some 20 us of axis handling for two 3-vectors, at every message
    tau = np.array([p[1] * f[2] - p[2] * f[1], p[2] * f[0] - p[0] * f[2], p[0] * f[1] - p[1] * f[0]])
    return f, tau
