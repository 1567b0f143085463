"""Descriptor modes for the evaluation, computed once per window as a *feature bank*.

Every window of a BioTac recording (one finger: PAC at 2.2 kHz as the
vibration signal S, the 19 electrodes at 100 Hz as the deformation signals V,
PDC for the contact force) is turned into a bank of feature groups; a named
*descriptor mode* is a list of groups, so ablations and modes are column
selections of one computation.

Groups (all per window):

``paper``
    The paper's BioTac finger descriptor, eq. 17: ``[A_pac, A_E, M_pac, M_E,
    C_pac, C_E, L(pac,E), N(pac,E)]``, electrodes averaged (8 values).
``per_channel``
    The same quantities kept per electrode (98 values: Hjorth of PAC and of
    each electrode, Pearson and Spearman of PAC with each electrode).
    ``paper`` and ``per_channel`` come from one call of the core's
    :func:`~tactile_descriptors_ros.core.aggregation.cell_features` reduced by
    :func:`~tactile_descriptors_ros.core.aggregation.reduce_body_part`.
``bands``
    Hjorth Activity, Mobility and Complexity (eq. 1-3, the core's
    :func:`~tactile_descriptors_ros.core.descriptors.hjorth`) of PAC
    band-passed into :data:`PAC_BANDS_HZ` (4th-order Butterworth, causal
    ``sosfilt`` of the window with its mean removed): 18 values.
``levels``
    Mean level of each electrode, PDC, TDC and TAC over the window (22
    values): static deformation, force and thermal state.
``subwindows``
    *Successive windows inside the window*: the window is cut into
    :data:`N_SUBWINDOWS` equal consecutive pieces, each piece gets the
    ``per_channel`` and ``bands`` values (Activity as ``log1p``), and the
    group is their mean and standard deviation over the pieces (2 x 116
    values, labelled ``mean_<label>`` and ``sd_<label>``).  The standard
    deviation says how steady the texture is over the slide (stick-slip,
    uneven weave), which one descriptor of the whole window averages away.
    Derived from the banks of the pieces (cached like any bank), added by
    :func:`compute_bank` with ``subwindows=True``.
``baseline``
    The related work's hand-made features (e.g. Fishel & Loeb 2012, Jamali &
    Sammut 2011 -- statistics and spectra): log variance, skewness and
    kurtosis of PAC and of each electrode, and log band powers (Welch) of PAC
    in :data:`PAC_BANDS_HZ` and of each electrode in :data:`ELECTRODE_BANDS_HZ`.

Named modes (:data:`DESCRIPTOR_MODES`): ``paper`` (= the core's ``averaged``
mode), ``per_channel`` (the core's ``per_channel`` mode), ``multiband``
(``per_channel`` + ``bands``), ``multiband_levels`` (+ ``levels``),
``baseline``, ``combined`` (``per_channel`` + ``bands`` + ``levels`` +
``baseline``, 261 values: :data:`DEFAULT_MODE`) and ``combined_subwindows``
(``combined`` + ``subwindows``, 493 values).  On cross-validation over
blocks of trials (2 s windows) ``combined`` scored 97.3 % and
``combined_subwindows`` 97.7 %, a gain inside the noise of 400 test windows
per fold for twice the descriptor time, so the default stays ``combined``.
``averaged`` is accepted as an alias of ``paper``.

The contact gate (eq. 16) is applied when a mode is selected: a window whose
mean PDC force is below F_t yields zeros, like the core's body-part
descriptor; ``gate=False`` keeps the computed values.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from collections.abc import Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import signal, stats

from ..core.aggregation import body_part_layout, cell_features, contact_gate, reduce_body_part
from ..core.descriptors import hjorth
from ..core.robot import CellType, RobotDescription, load_robot
from ..core.scaling import activity_mask, log_activity
from ..datasets.biotac_slide import PAC_PER_FRAME
from ..datasets.recording import BiotacRecording
from ..errors import ConfigError
from .windows import Window

__all__ = [
    "PAC_BANDS_HZ",
    "ELECTRODE_BANDS_HZ",
    "GROUPS",
    "DESCRIPTOR_MODES",
    "DEFAULT_MODE",
    "QUANTITIES",
    "FeatureBank",
    "biotac_cell_type",
    "bank_labels",
    "window_bank",
    "compute_bank",
    "select_features",
    "N_SUBWINDOWS",
    "subwindow_starts",
    "drop_quantities",
    "mode_groups",
]

#: PAC frequency bands of the ``bands`` group and the baseline (Hz).  PAC is
#: sampled at 2.2 kHz (Nyquist 1.1 kHz); the BioTac's PAC channel is
#: AC-coupled, so nothing below 20 Hz is used.
PAC_BANDS_HZ: tuple[tuple[float, float], ...] = (
    (20.0, 50.0), (50.0, 100.0), (100.0, 200.0), (200.0, 400.0), (400.0, 800.0), (800.0, 1050.0))

#: Electrode frequency bands of the baseline (Hz; electrodes at 100 Hz).
ELECTRODE_BANDS_HZ: tuple[tuple[float, float], ...] = ((0.0, 2.0), (2.0, 10.0), (10.0, 50.0))

#: Feature groups in bank order (computed per window and cached).
GROUPS: tuple[str, ...] = ("paper", "per_channel", "bands", "levels", "baseline")

#: Pieces of the ``subwindows`` group and the groups described per piece.
N_SUBWINDOWS: int = 4
_SUBWINDOW_SOURCE: tuple[str, ...] = ("per_channel", "bands")

#: Named descriptor modes: which groups they concatenate.
DESCRIPTOR_MODES: dict[str, tuple[str, ...]] = {
    "paper": ("paper",),
    "per_channel": ("per_channel",),
    "multiband": ("per_channel", "bands"),
    "multiband_levels": ("per_channel", "bands", "levels"),
    "baseline": ("baseline",),
    "combined": ("per_channel", "bands", "levels", "baseline"),
    "combined_subwindows": ("per_channel", "bands", "levels", "baseline", "subwindows"),
}

#: The mode ``tactile evaluate`` uses unless told otherwise (the paper's own
#: descriptor is ``paper``; see docs/results.md for why this is the default).
DEFAULT_MODE = "combined"

#: Quantity prefixes of the descriptor (eq. 11): Activity, Mobility,
#: Complexity, linear and nonlinear correlation.
QUANTITIES: tuple[str, ...] = ("A", "M", "C", "L", "N")

_BANK_VERSION = 3  # bump when a group's definition changes


def mode_groups(mode: str) -> tuple[str, ...]:
    """Groups of a named mode (``averaged`` is an alias of ``paper``).

    Raises
    ------
    ConfigError
        For an unknown mode.
    """
    if mode == "averaged":
        mode = "paper"
    try:
        return DESCRIPTOR_MODES[mode]
    except KeyError:
        raise ConfigError(f"unknown descriptor mode {mode!r}; choose from "
                          f"{', '.join(['averaged', *DESCRIPTOR_MODES])}", key="channels") from None


def biotac_cell_type(robot: RobotDescription | None = None) -> CellType:
    """The BioTac cell type of the Shadow Hand description (PAC, 19 electrodes, PDC)."""
    robot = robot or load_robot("shadow_hand")
    return robot.cell_types["biotac"]


def bank_labels(cell_type: CellType | None = None) -> dict[str, tuple[str, ...]]:
    """Labels of every group, prefixed ``<group>/`` (the quantity follows the slash)."""
    ct = cell_type or biotac_cell_type()
    pac = ct.vibration.channels[0]
    elec = ct.deformation.channels
    band_names = [f"{int(lo)}-{int(hi)}Hz" for lo, hi in PAC_BANDS_HZ]
    out = {
        "paper": body_part_layout(ct, "averaged"),
        "per_channel": body_part_layout(ct, "per_channel"),
        "bands": tuple(f"{q}_{pac}_{b}" for q in ("A", "M", "C") for b in band_names),
        "levels": tuple([f"level_{e}" for e in elec] + ["level_pdc", "level_tdc", "level_tac"]),
        "baseline": tuple(
            [f"logvar_{c}" for c in (pac, *elec)] + [f"skew_{c}" for c in (pac, *elec)]
            + [f"kurt_{c}" for c in (pac, *elec)] + [f"logbp_{pac}_{b}" for b in band_names]
            + [f"logbp_{e}_{int(lo)}-{int(hi)}Hz" for e in elec for lo, hi in ELECTRODE_BANDS_HZ]),
    }
    return {g: tuple(f"{g}/{lab}" for lab in labs) for g, labs in out.items()}


@dataclass
class FeatureBank:
    """Feature groups of a list of windows.

    Attributes
    ----------
    windows : list of Window
    groups : dict of str to numpy.ndarray, shape (n_windows, n_values)
    labels : dict of str to tuple of str
    in_contact : numpy.ndarray of bool, shape (n_windows,)
        The contact gate (mean PDC force >= F_t).
    mean_force_n : numpy.ndarray, shape (n_windows,)
    seconds : dict of str to numpy.ndarray, shape (n_windows,)
        Compute time per window of ``core`` (the paper and per-channel
        descriptor), ``bands``, ``levels`` and ``baseline``.
    """

    windows: list[Window]
    groups: dict[str, np.ndarray]
    labels: dict[str, tuple[str, ...]]
    in_contact: np.ndarray
    mean_force_n: np.ndarray
    seconds: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def y(self) -> np.ndarray:
        """Material of every window."""
        return np.array([w.material for w in self.windows], dtype=int)

    @property
    def trials(self) -> np.ndarray:
        """Trial of every window."""
        return np.array([w.trial for w in self.windows], dtype=int)

    @property
    def groups_id(self) -> np.ndarray:
        """One integer per recording (material * 10000 + trial), for grouped CV."""
        return self.y * 10000 + self.trials


def _bandpass_sos(fs_hz: float) -> list[np.ndarray]:
    nyq = fs_hz / 2.0
    out = []
    for lo, hi in PAC_BANDS_HZ:
        hi = min(hi, 0.98 * nyq)
        out.append(signal.butter(4, [lo, hi], btype="bandpass", fs=fs_hz, output="sos"))
    return out


_SOS_CACHE: dict[float, list[tuple[np.ndarray, np.ndarray]]] = {}


def _bands(pac: np.ndarray, fs_hz: float) -> np.ndarray:
    if fs_hz not in _SOS_CACHE:
        _SOS_CACHE[fs_hz] = [(sos, signal.sosfilt_zi(sos)) for sos in _bandpass_sos(fs_hz)]
    x = pac.astype(np.float64) - pac.mean()
    filtered = np.stack([signal.sosfilt(sos, x, zi=zi * x[0])[0] for sos, zi in _SOS_CACHE[fs_hz]])
    h = hjorth(filtered, fs_hz)
    return np.concatenate([h.activity, h.mobility, h.complexity])


def _band_powers(x: np.ndarray, fs_hz: float, bands: Sequence[tuple[float, float]]) -> np.ndarray:
    """Log band powers of the rows of ``x`` (Welch, 1 s segments or shorter)."""
    x = np.atleast_2d(np.asarray(x, dtype=np.float64))
    nper = int(min(x.shape[-1], max(8, round(fs_hz))))
    f, p = signal.welch(x, fs=fs_hz, nperseg=nper, axis=-1)
    df = f[1] - f[0] if f.size > 1 else 1.0
    out = np.empty((x.shape[0], len(bands)))
    for k, (lo, hi) in enumerate(bands):
        sel = (f >= lo) & (f < hi) if hi < fs_hz / 2 else (f >= lo)
        out[:, k] = np.log1p(p[:, sel].sum(axis=-1) * df) if sel.any() else 0.0
    return out


def _moments(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    x = np.atleast_2d(np.asarray(x, dtype=np.float64))
    var = x.var(axis=-1)
    flat = var <= 1e-12 * np.maximum(1.0, np.abs(x).max(axis=-1)) ** 2
    with np.errstate(all="ignore"):
        sk = stats.skew(x, axis=-1)
        ku = stats.kurtosis(x, axis=-1)
    # A flat signal has no defined shape: 0 (documented), never NaN.
    sk = np.where(flat | ~np.isfinite(sk), 0.0, sk)
    ku = np.where(flat | ~np.isfinite(ku), 0.0, ku)
    return np.log1p(var), sk, ku


def window_bank(rec: BiotacRecording, start: int, n_frames: int, cell_type: CellType,
                force_threshold_n: float) -> tuple[dict[str, np.ndarray], bool, float, dict[str, float]]:
    """Every feature group of frames ``start:start + n_frames`` of one recording.

    Returns
    -------
    groups : dict of str to numpy.ndarray
    in_contact : bool
        Contact gate (eq. 16): mean PDC force over the window >= F_t.
    mean_force_n : float
    seconds : dict of str to float
        Compute time of each part.
    """
    w = rec.crop_frames(start, start + n_frames)
    if w.n_frames != n_frames:
        raise ConfigError(f"{rec.path}: window {start}:{start + n_frames} runs past the end ({rec.n_frames})")
    fs_s, fs_v = cell_type.vibration.rate_hz, cell_type.deformation.rate_hz
    force_n = w.pdc.astype(np.float64) * cell_type.force.n_per_count
    seconds: dict[str, float] = {}

    t0 = time.perf_counter()
    feats = cell_features(w.pac[None, None, :], w.pac_t_ns, w.electrodes[None], w.frame_t_ns, fs_s, fs_v)
    gate = contact_gate([force_n], force_threshold_n)
    everyone = np.ones(1, dtype=bool)  # the gate is applied at selection (select_features)
    paper = reduce_body_part(feats, everyone, cell_type, "averaged")
    per_channel = reduce_body_part(feats, everyone, cell_type, "per_channel")
    seconds["core"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    bands = _bands(w.pac, fs_s)
    seconds["bands"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    levels = np.concatenate([w.electrodes.mean(axis=1), [w.pdc.mean(), w.tdc.mean(), w.tac.mean()]])
    seconds["levels"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    sigs_v = w.electrodes.astype(np.float64)
    lv_s, sk_s, ku_s = _moments(w.pac)
    lv_v, sk_v, ku_v = _moments(sigs_v)
    baseline = np.concatenate([
        lv_s, lv_v, sk_s, sk_v, ku_s, ku_v,
        _band_powers(w.pac - w.pac.mean(), fs_s, PAC_BANDS_HZ).ravel(),
        _band_powers(sigs_v - sigs_v.mean(axis=1, keepdims=True), fs_v, ELECTRODE_BANDS_HZ).ravel(),
    ])
    seconds["baseline"] = time.perf_counter() - t0
    groups = {"paper": paper, "per_channel": per_channel, "bands": bands, "levels": levels,
              "baseline": baseline}
    return groups, bool(gate[0]), float(force_n.mean()), seconds


# --------------------------------------------------------------------------- bank with cache


def _file_stamp(path: str) -> tuple[int, int]:
    st = os.stat(path)
    return int(st.st_size), int(st.st_mtime_ns)


def _cache_path(cache_dir: Path, n_frames: int, force_threshold_n: float, n_per_count: float) -> Path:
    key = json.dumps({"v": _BANK_VERSION, "n_frames": n_frames, "ft": force_threshold_n, "npc": n_per_count,
                      "bands": PAC_BANDS_HZ, "ebands": ELECTRODE_BANDS_HZ, "ppf": PAC_PER_FRAME})
    digest = hashlib.sha1(key.encode()).hexdigest()[:16]
    return cache_dir / f"bank_{n_frames}f_{digest}.npz"


def _load_cache(path: Path) -> dict[tuple, tuple]:
    if not path.is_file():
        return {}
    try:
        with np.load(path, allow_pickle=False) as z:
            keys = [tuple(k) for k in z["keys"].tolist()]
            paths = z["paths"].tolist()
            rows = {g: z[f"g_{g}"] for g in GROUPS}
            sec = {s: z[f"s_{s}"] for s in ("core", "bands", "levels", "baseline")}
            contact, force = z["contact"], z["force"]
    except (OSError, KeyError, ValueError):
        return {}  # a damaged cache is recomputed, never trusted
    out = {}
    for i, (k, p) in enumerate(zip(keys, paths)):
        mat, trial, start, size, mtime = k
        out[(p, start)] = ((size, mtime), {g: rows[g][i] for g in GROUPS}, bool(contact[i]), float(force[i]),
                           {s: float(sec[s][i]) for s in sec}, (mat, trial))
    return out


def _save_cache(path: Path, entries: dict[tuple, tuple]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    items = sorted(entries.items())
    keys = np.array([[*e[5], start, *e[0]] for (p, start), e in items], dtype=np.int64)
    arrays = {"keys": keys, "paths": np.array([p for (p, _), _ in items]),
              "contact": np.array([e[2] for _, e in items]), "force": np.array([e[3] for _, e in items])}
    for g in GROUPS:
        arrays[f"g_{g}"] = np.stack([e[1][g] for _, e in items])
    for s in ("core", "bands", "levels", "baseline"):
        arrays[f"s_{s}"] = np.array([e[4][s] for _, e in items])
    tmp = path.with_name(path.name + f".{os.getpid()}.tmp.npz")
    np.savez(tmp, **arrays)
    os.replace(tmp, path)


def _work(args: tuple) -> list[tuple]:
    rec, starts, n_frames, cell_type, threshold = args
    return [window_bank(rec, s, n_frames, cell_type, threshold) for s in starts]


def subwindow_starts(window: Window, n_pieces: int = N_SUBWINDOWS) -> list[Window]:
    """The ``n_pieces`` equal consecutive pieces of a window (a remainder of frames at the end is unused).

    Raises
    ------
    ConfigError
        When a piece would be shorter than 3 frames.
    """
    size = window.n_frames // n_pieces
    if size < 3:
        raise ConfigError(f"a {window.n_frames}-frame window is too short for {n_pieces} pieces of >= 3 frames",
                          key="window")
    return [Window(window.material, window.trial, window.start + k * size, size) for k in range(n_pieces)]


def _add_subwindows(bank: FeatureBank, recordings: Sequence[BiotacRecording], **kwargs) -> None:
    """Compute the ``subwindows`` group of ``bank`` from the banks of its windows' pieces."""
    pieces = [p for w in bank.windows for p in subwindow_starts(w)]
    sub = compute_bank(recordings, pieces, **kwargs)
    values = np.concatenate([sub.groups[g] for g in _SUBWINDOW_SOURCE], axis=1)
    labels = [lab.split("/", 1)[1] for g in _SUBWINDOW_SOURCE for lab in sub.labels[g]]
    values = log_activity(values, activity_mask(labels)).reshape(len(bank.windows), N_SUBWINDOWS, -1)
    bank.groups["subwindows"] = np.concatenate([values.mean(axis=1), values.std(axis=1)], axis=1)
    bank.labels["subwindows"] = tuple([f"subwindows/mean_{lab}" for lab in labels]
                                      + [f"subwindows/sd_{lab}" for lab in labels])
    per_piece = sub.seconds["core"] + sub.seconds["bands"]
    bank.seconds["subwindows"] = per_piece.reshape(len(bank.windows), N_SUBWINDOWS).sum(axis=1)


def compute_bank(recordings: Sequence[BiotacRecording], windows: Sequence[Window], *,
                 cell_type: CellType | None = None, force_threshold_n: float | None = None,
                 cache_dir: str | Path | None = None, jobs: int = 1, progress: bool = False,
                 desc: str = "descriptors", subwindows: bool = False) -> FeatureBank:
    """Feature bank of ``windows`` (which must all have the same length).

    Parameters
    ----------
    recordings : sequence of BiotacRecording
        Must include every (material, trial) that a window refers to.
    windows : sequence of Window
    cell_type : CellType, optional
        Defaults to the Shadow Hand's BioTac.
    force_threshold_n : float, optional
        F_t; defaults to the Shadow Hand description's (0.2 N).
    cache_dir : path, optional
        Folder of the on-disk cache (one file per window length; entries are
        keyed by recording path, size, modification time and start frame).
    jobs : int, default 1
        Worker processes for windows not in the cache.
    progress : bool
        Show a tqdm bar on stderr.
    subwindows : bool, default False
        Also compute the derived ``subwindows`` group (from the banks of the
        windows' :data:`N_SUBWINDOWS` pieces).
    """
    if not windows:
        raise ConfigError("no windows to describe")
    lengths = {w.n_frames for w in windows}
    if len(lengths) != 1:
        raise ConfigError(f"all windows of a bank must have one length (crop rule), got {sorted(lengths)}")
    n_frames = lengths.pop()
    robot = load_robot("shadow_hand")
    cell_type = cell_type or robot.cell_types["biotac"]
    threshold = robot.contact.force_threshold_n if force_threshold_n is None else float(force_threshold_n)
    by_key = {(r.material, r.trial): r for r in recordings}
    if len(by_key) != len(recordings):
        raise ConfigError("recordings hold the same material and trial twice (two folders?): describe each "
                          "folder's windows with its own recordings")
    cpath = (_cache_path(Path(cache_dir), n_frames, threshold, cell_type.force.n_per_count)
             if cache_dir else None)
    cache = _load_cache(cpath) if cpath else {}
    stamps = {r.path: _file_stamp(r.source_file) for r in recordings}
    todo: dict[str, list[int]] = {}
    for w in windows:
        rec = by_key.get((w.material, w.trial))
        if rec is None:
            raise ConfigError(f"window refers to material {w.material} trial {w.trial}, which is not loaded")
        hit = cache.get((rec.path, w.start))
        if hit is None or hit[0] != stamps[rec.path]:
            todo.setdefault(rec.path, [])
            if w.start not in todo[rec.path]:
                todo[rec.path].append(w.start)
    if todo:
        by_path = {r.path: r for r in recordings}
        tasks = [(by_path[p], starts, n_frames, cell_type, threshold) for p, starts in todo.items()]
        results: Iterable
        bar = None
        if progress:
            from tqdm import tqdm
            bar = tqdm(total=len(tasks), desc=f"{desc} ({n_frames / 100:.2f} s windows)", unit="trial",
                       leave=False)
        if jobs > 1 and len(tasks) > 4:
            pool = ProcessPoolExecutor(max_workers=jobs)
            results = pool.map(_work, tasks, chunksize=4)
        else:
            pool = None
            results = map(_work, tasks)
        try:
            for task, res in zip(tasks, results):
                rec = task[0]
                for s, (groups, contact, force, sec) in zip(task[1], res):
                    cache[(rec.path, s)] = (stamps[rec.path], groups, contact, force, sec,
                                            (rec.material, rec.trial))
                if bar is not None:
                    bar.update(1)
        finally:
            if pool is not None:
                pool.shutdown()
            if bar is not None:
                bar.close()
        if cpath:
            _save_cache(cpath, cache)
    labels = bank_labels(cell_type)
    rows = [cache[(by_key[(w.material, w.trial)].path, w.start)] for w in windows]
    groups = {g: np.stack([r[1][g] for r in rows]) for g in GROUPS}
    for g in GROUPS:
        if groups[g].shape[1] != len(labels[g]):
            raise ConfigError(f"feature group {g}: {groups[g].shape[1]} values but {len(labels[g])} labels")
    bank = FeatureBank(
        windows=list(windows), groups=groups, labels=labels,
        in_contact=np.array([r[2] for r in rows], dtype=bool),
        mean_force_n=np.array([r[3] for r in rows]),
        seconds={s: np.array([r[4][s] for r in rows]) for s in ("core", "bands", "levels", "baseline")},
    )
    if subwindows:
        _add_subwindows(bank, recordings, cell_type=cell_type, force_threshold_n=threshold, cache_dir=cache_dir,
                        jobs=jobs, progress=progress, desc=f"{desc}, pieces")
    return bank


# --------------------------------------------------------------------------- selection


def drop_quantities(labels: Sequence[str], drop: Iterable[str]) -> np.ndarray:
    """Mask keeping labels whose quantity (text after ``/`` up to ``_``, past a ``mean_``/``sd_``) is not in ``drop``."""
    drop = set(drop)
    bad = drop - set(QUANTITIES)
    if bad:
        raise ConfigError(f"unknown quantities {sorted(bad)}; choose from {QUANTITIES}")

    def quantity(lab: str) -> str:
        q = lab.rsplit("/", 1)[-1]
        if q.startswith(("mean_", "sd_")):
            q = q.split("_", 1)[1]
        return q.split("_", 1)[0]

    return np.array([quantity(lab) not in drop for lab in labels], dtype=bool)


def select_features(bank: FeatureBank, mode: str, *, gate: bool = True,
                    drop: Iterable[str] = ()) -> tuple[np.ndarray, tuple[str, ...]]:
    """Descriptor matrix of a mode.

    Parameters
    ----------
    bank : FeatureBank
    mode : str
        A name of :data:`DESCRIPTOR_MODES` (or ``averaged``).
    gate : bool, default True
        Apply the contact gate: windows out of contact become zeros (eq. 16).
    drop : iterable of {"A", "M", "C", "L", "N"}
        Quantities to leave out (ablation); other groups' features stay.

    Returns
    -------
    X : numpy.ndarray, shape (n_windows, n_values)
    labels : tuple of str
    """
    groups = mode_groups(mode)
    missing = [g for g in groups if g not in bank.groups]
    if missing:
        raise ConfigError(f"mode {mode!r} needs the {missing} group(s): compute the bank with subwindows=True")
    X = np.concatenate([bank.groups[g] for g in groups], axis=1)
    labels = tuple(lab for g in groups for lab in bank.labels[g])
    keep = drop_quantities(labels, drop)
    if not keep.any():
        raise ConfigError(f"dropping {sorted(drop)} leaves no feature of mode {mode!r}")
    X, labels = X[:, keep], tuple(lab for lab, k in zip(labels, keep) if k)
    if gate:
        X = np.where(bank.in_contact[:, None], X, 0.0)
    return X, labels
