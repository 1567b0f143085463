"""Descriptor modes for the evaluation: feature banks of recorded windows, cached.

This module computes no feature of its own.  A window of a BioTac recording
(one finger: PAC at 2.2 kHz, the 19 electrodes and PDC, TDC, TAC at 100 Hz)
becomes the core's :class:`~tactile_descriptors_ros.core.aggregation.CellSignals`
(:func:`recording_cells`) and is described by
:func:`~tactile_descriptors_ros.core.aggregation.describe_window` -- the
function the window node calls -- once per feature group of
:data:`~tactile_descriptors_ros.core.groups.GROUPS` (``paper``,
``per_channel``, ``bands``, ``levels``, ``statistics``; definitions, labels
and equations in :mod:`tactile_descriptors_ros.core.features`).  The groups
of every window are kept as a *feature bank* (cached on disk); a named
*descriptor mode* is a list of groups, so ablations and modes are column
selections of one computation, and a mode's columns equal what the window
node publishes for ``descriptor.groups`` set to the same list.

``subwindows``
    *Successive windows inside the window*: the window is cut into
    :data:`N_SUBWINDOWS` equal consecutive pieces, each piece is described
    with ``per_channel`` and ``bands``, and the group is their mean and
    standard deviation over the pieces
    (:func:`~tactile_descriptors_ros.core.features.piece_summary`, labelled
    ``mean_<label>`` and ``sd_<label>``).  Added by :func:`compute_bank` with
    ``subwindows=True``; an evaluation-only ablation (the window node does not
    offer it).

Named modes (:data:`DESCRIPTOR_MODES`): ``paper`` (= the robot
description's ``channels: averaged``), ``per_channel``, ``multiband``
(``per_channel`` + ``bands``), ``multiband_levels`` (+ ``levels``),
``baseline`` (``statistics``, the related work's features), ``combined``
(``per_channel`` + ``bands`` + ``levels`` + ``statistics``, 261 values:
:data:`DEFAULT_MODE`, what the shipped Shadow Hand configuration selects)
and ``combined_subwindows`` (``combined`` + ``subwindows``, 493 values).
On cross-validation over blocks of trials (2 s windows) ``combined`` scored
97.3 % and ``combined_subwindows`` 97.7 %, a gain inside the noise of 400
test windows per fold for twice the descriptor time, so the default stays
``combined``.  ``averaged`` is accepted as an alias of ``paper``.

The contact gate (eq. 16) is applied when a mode is selected: a window whose
mean PDC force is below F_t yields zeros, like the core's body-part
descriptor; ``gate=False`` keeps the computed values.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import time
from collections.abc import Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tactile_descriptors_lab.datasets.biotac_slide import PAC_PER_FRAME
from tactile_descriptors_lab.datasets.recording import BiotacRecording, CellRecording
from tactile_descriptors_lab.evaluation.sampling import Window
from tactile_descriptors_ros.core.aggregation import CellSignals, contact_gate, describe_window
from tactile_descriptors_ros.core.cell_types import CellType
from tactile_descriptors_ros.core.features import piece_summary
from tactile_descriptors_ros.core.groups import (
    DEFORMATION_BANDS_HZ,
    GROUPS,
    VIBRATION_BANDS_HZ,
    check_groups,
    feedable_groups,
    fitted,
    parse_group,
    rocket_parameters,
    selection_labels,
)
from tactile_descriptors_ros.core.robot import VIBRATION_GROUPS, BodyPart, Cell, RobotDescription, load_robot
from tactile_descriptors_ros.errors import ConfigError

__all__ = [
    "cell_type_groups",
    "PAC_BANDS_HZ",
    "ELECTRODE_BANDS_HZ",
    "GROUPS",
    "DESCRIPTOR_MODES",
    "DEFAULT_MODE",
    "BANK_VERSION",
    "QUANTITIES",
    "FeatureBank",
    "biotac_cell_type",
    "finger_robot",
    "recording_cells",
    "bank_labels",
    "window_bank",
    "compute_bank",
    "select_features",
    "N_SUBWINDOWS",
    "subwindow_starts",
    "drop_quantities",
    "mode_groups",
    "recordings_cell_type",
    "recordings_robot",
    "recording_channels",
    "PAC_RATE_TOLERANCE",
]

#: A BioTac's PAC counts as present when its rate (samples a frame x frame rate) is within this fraction of
#: the cell type's vibration rate; a cell's vibration and deformation channels likewise.
PAC_RATE_TOLERANCE: float = 0.05

#: PAC frequency bands of ``bands`` and ``statistics`` (the core's vibration bands; Hz).
PAC_BANDS_HZ: tuple[tuple[float, float], ...] = VIBRATION_BANDS_HZ

#: Electrode frequency bands of ``statistics`` (the core's deformation bands; Hz).
ELECTRODE_BANDS_HZ: tuple[tuple[float, float], ...] = DEFORMATION_BANDS_HZ

#: Pieces of the ``subwindows`` group and the groups described per piece.
N_SUBWINDOWS: int = 4
_SUBWINDOW_SOURCE: tuple[str, ...] = ("per_channel", "bands")

#: Named descriptor modes: which groups they concatenate.
DESCRIPTOR_MODES: dict[str, tuple[str, ...]] = {
    "paper": ("paper",),
    "per_channel": ("per_channel",),
    "multiband": ("per_channel", "bands"),
    "multiband_levels": ("per_channel", "bands", "levels"),
    "baseline": ("statistics",),
    "combined": ("per_channel", "bands", "levels", "statistics"),
    "combined_subwindows": ("per_channel", "bands", "levels", "statistics", "subwindows"),
    "plain": ("plain",),
    "rocket": ("rocket",),
    "combined_rocket": ("per_channel", "bands", "levels", "statistics", "rocket"),
}

#: The mode ``tactile evaluate`` uses unless told otherwise (the paper's own
#: descriptor is ``paper``; see lab/docs/results.md for why this is the default).
DEFAULT_MODE = "combined"

#: Quantity prefixes of the descriptor (eq. 11): Activity, Mobility,
#: Complexity, linear and nonlinear correlation.
QUANTITIES: tuple[str, ...] = ("A", "M", "C", "L", "N")

#: Version of the feature groups' definitions: bumped when a group's definition changes (cached banks
#: of another version are recomputed; the report records it with every section it measures).
BANK_VERSION: int = 6
_BANK_VERSION = BANK_VERSION


def mode_groups(mode: str) -> tuple[str, ...]:
    """Groups of a named mode (``averaged`` is an alias of ``paper``).

    Raises
    ------
    ConfigError
        For an unknown mode.
    """
    if mode == "averaged":
        mode = "paper"
    if mode in DESCRIPTOR_MODES:
        return DESCRIPTOR_MODES[mode]
    # a selection of groups, named as the core names it: "levels", "per_channel+levels", "levels:pdc,tdc,tac"
    tokens = tuple(t.strip() for t in str(mode).split("+") if t.strip())
    try:
        for t in tokens:
            if t != "subwindows":
                parse_group(t, key="channels")
    except ConfigError:
        tokens = ()
    if not tokens or len(set(tokens)) != len(tokens):
        raise ConfigError(f"unknown descriptor mode {mode!r}; choose from "
                          f"{', '.join(['averaged', *DESCRIPTOR_MODES])}, or feature groups joined by '+' "
                          f"({', '.join(GROUPS)}, levels:<ch>,<ch>)", key="channels")
    return tokens


def biotac_cell_type(robot: RobotDescription | None = None) -> CellType:
    """The BioTac cell type of the Shadow Hand description (PAC, 19 electrodes, PDC TDC TAC)."""
    robot = robot or load_robot("shadow_hand")
    return robot.cell_types["biotac"]


_FINGERS: dict[CellType, RobotDescription] = {}


def finger_robot(cell_type: CellType | None = None) -> RobotDescription:
    """A robot of one body part (``finger``) holding one cell (id 0) of ``cell_type``.

    The Shadow Hand description with its five fingers replaced by one:
    the recordings are one BioTac each.  Cached per cell type (the core
    caches its plan per robot object).
    """
    ct = cell_type or biotac_cell_type()
    robot = _FINGERS.get(ct)
    if robot is None:
        hand = load_robot("shadow_hand")
        robot = _FINGERS[ct] = dataclasses.replace(
            hand, cell_types={ct.name: ct}, body_parts=(BodyPart("finger", ct.name, (Cell(0, "finger"),)),),
            nodes={})
    return robot


def recordings_robot(recordings: Sequence[BiotacRecording | CellRecording]) -> tuple[RobotDescription, CellType]:
    """The robot description declaring the one cell type of a set of recordings, and that cell type.

    :class:`BiotacRecording` objects are the Shadow Hand's BioTacs; a
    :class:`CellRecording` names its robot and cell type.  The robot's
    contact threshold F_t is the evaluation's.

    Raises
    ------
    ConfigError
        When the recordings hold cells of different types.
    """
    kinds = {(r.robot, r.cell_type) if isinstance(r, CellRecording) else ("shadow_hand", "biotac")
             for r in recordings}
    if len(kinds) != 1:
        raise ConfigError(f"the recordings hold cells of several types ({', '.join(sorted(k[1] for k in kinds))}): "
                          "train and test on one cell type", key="cell_type")
    name, cell_type = kinds.pop()
    robot = load_robot(name)
    return robot, robot.cell_types[cell_type]


def recordings_cell_type(recordings: Sequence[BiotacRecording | CellRecording]) -> CellType:
    """The one cell type of a set of recordings (the BioTac's for :class:`BiotacRecording`); see :func:`recordings_robot`."""
    return recordings_robot(recordings)[1]


def recording_channels(rec: BiotacRecording | CellRecording, cell_type: CellType
                       ) -> tuple[tuple[str, ...], dict[str, str]]:
    """The channels a recording holds at the cell type's rates, and why the others are absent.

    A BioTac's PAC is present when its rate (samples a frame x frame rate)
    is within :data:`PAC_RATE_TOLERANCE` of the cell type's vibration rate:
    old Shadow drivers' messages carry two PAC samples (``pac0``, ``pac1``)
    a frame, 200 Hz at 100 frames a second, not a 2.2 kHz signal.  A cell's
    vibration and deformation channels likewise at their modalities' rates.

    Returns
    -------
    present : tuple of str
    why : dict of str to str
        Channel -> reason, for the absent ones.
    """
    why: dict[str, str] = {c: "not in the source" for c in rec.absent}
    fps = rec.frame_rate_hz
    k = rec.pac_per_frame if isinstance(rec, BiotacRecording) else rec.samples_per_frame
    vib_hz, want = k * fps, cell_type.vibration.rate_hz
    if abs(vib_hz / want - 1.0) > PAC_RATE_TOLERANCE:
        for c in cell_type.vibration.channels:
            why.setdefault(c, f"{c} at {vib_hz:.0f} Hz ({k} samples a frame at {fps:.1f} frames/s), "
                              f"not the {want:g} Hz the descriptors take")
    dfm_hz = cell_type.deformation.rate_hz
    if isinstance(rec, CellRecording) and abs(fps / dfm_hz - 1.0) > PAC_RATE_TOLERANCE:
        for c in cell_type.deformation.channels:
            why.setdefault(c, f"frames at {fps:.1f} Hz, not the {dfm_hz:g} Hz of {c}")
    return tuple(c for c in cell_type.channels if c not in why), why


def recording_cells(rec: BiotacRecording | CellRecording,
                    cell_type: CellType | None = None) -> dict[int, CellSignals]:
    """The core's cell signals of a recording (or a window of it: :meth:`BiotacRecording.crop_frames`).

    Vibration PAC (counts), deformation the electrodes (counts, tared by the
    recording setup), force ``PDC * n_per_count`` (eq. 16), extra channels
    by name from PDC, TDC and TAC.

    Raises
    ------
    ConfigError
        When the cell type declares an extra channel the recordings do not hold.
    """
    ct = cell_type or biotac_cell_type()
    if isinstance(rec, CellRecording):
        return {0: CellSignals(rec.vibration, rec.vibration_t_ns, rec.deformation, rec.frame_t_ns,
                               rec.force_n(ct.force.n_per_count), extra=rec.extra,
                               deformation_tare=rec.deformation_tare)}
    columns = {"pdc": rec.pdc, "tdc": rec.tdc, "tac": rec.tac}
    missing = [c for c in ct.extra_channels if c not in columns]
    if missing:
        raise ConfigError(f"cell type {ct.name!r} declares extra channel {missing[0]!r}, which BioTac recordings "
                          f"do not hold (they have {', '.join(columns)})", key="extra_channels")
    extra = np.array([columns[c] for c in ct.extra_channels], dtype=np.float64).reshape(-1, rec.n_frames)
    force_n = rec.pdc.astype(np.float64) * ct.force.n_per_count
    return {0: CellSignals(rec.pac[None, :], rec.pac_t_ns, rec.electrodes, rec.frame_t_ns, force_n, extra=extra)}


def cell_type_groups(cell_type: CellType) -> tuple[tuple[str, ...], dict[str, str]]:
    """The groups of :data:`GROUPS` a cell type can feed at its rates, and why it cannot feed the others.

    ``bands`` needs a vibration band below Nyquist (:func:`tactile_descriptors_ros.core.groups.check_groups`): a cell type
    whose vibration is sampled at 40 Hz has none; ``per_channel`` and ``bands`` need vibration channels,
    which a pressure-only cell type does not have.  Such a group is left out of the feature bank, so that
    a mode without it evaluates, and a mode with it is refused by name (:func:`select_features`).
    """
    able, why = [], {}
    for g in GROUPS:
        if g in VIBRATION_GROUPS and not cell_type.has_vibration:
            why[g] = (f"feature group {g!r} reads the vibration channels, which cell type {cell_type.name!r} does "
                      "not have (pressure only)")
            continue
        try:
            check_groups(cell_type, (g,))
        except ConfigError as exc:
            why[g] = str(exc).split("': ", 1)[-1]
            continue
        able.append(g)
    return tuple(able), why


def fed_mode(cell_type: CellType, mode: str = DEFAULT_MODE) -> tuple[str, tuple[str, ...], str]:
    """A mode less the groups a cell type cannot feed: the mode that is left, the groups left out, and why
    the first of them was.

    ``(mode, (), "")`` when the cell type feeds every group of ``mode``.
    """
    _, why = cell_type_groups(cell_type)
    groups = mode_groups(mode)
    left = tuple(g for g in groups if g.partition(":")[0] in why)
    if not left:
        return mode, (), ""
    return "+".join(g for g in groups if g not in left), left, why[left[0].partition(":")[0]]


def bank_labels(cell_type: CellType | None = None) -> dict[str, tuple[str, ...]]:
    """Labels of every group, ``<group>/<label>`` (the core's :func:`~.core.groups.selection_labels`)."""
    ct = cell_type or biotac_cell_type()
    return {g: selection_labels(ct, (g,)) if fitted(ct, g) else () for g in GROUPS}


def _rocket_too_short(cell_type: CellType, window) -> bool:
    """True when a window is shorter than a fitted rocket transform's largest kernel (the group is then not computed)."""
    if not fitted(cell_type, "rocket"):
        return False
    params = rocket_parameters(cell_type)
    n_fast = window.pac.size if isinstance(window, BiotacRecording) else np.shape(window.vibration)[-1]
    return n_fast < params["vibration"].min_samples or window.n_frames < params["slow"].min_samples


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
        Compute time per window of each group (``describe_window`` with that
        group alone).
    """

    windows: list[Window]
    groups: dict[str, np.ndarray]
    labels: dict[str, tuple[str, ...]]
    in_contact: np.ndarray
    mean_force_n: np.ndarray
    seconds: dict[str, np.ndarray] = field(default_factory=dict)
    unfed: dict[str, str] = field(default_factory=dict)

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


def window_bank(rec: BiotacRecording, start: int, n_frames: int, cell_type: CellType,
                force_threshold_n: float) -> tuple[dict[str, np.ndarray], bool, float, dict[str, float]]:
    """Every feature group of frames ``start:start + n_frames`` of one recording.

    Each group is the core's :func:`~.core.aggregation.describe_window` of
    the window with that group alone, every window described whatever its
    force (the gate is applied at selection, :func:`select_features`).

    Returns
    -------
    groups : dict of str to numpy.ndarray
    in_contact : bool
        Contact gate (eq. 16): mean PDC force over the window >= F_t.
    mean_force_n : float
    seconds : dict of str to float
        Compute time of each group.
    """
    w = rec.crop_frames(start, start + n_frames)
    if w.n_frames != n_frames:
        raise ConfigError(f"{rec.path}: window {start}:{start + n_frames} runs past the end ({rec.n_frames})")
    robot = finger_robot(cell_type)
    cells = recording_cells(w, cell_type)
    groups: dict[str, np.ndarray] = {}
    seconds: dict[str, float] = {}
    present, _ = recording_channels(rec, cell_type)
    feedable = {parse_group(g)[0] for g in feedable_groups(cell_type, present)}
    feedable &= set(cell_type_groups(cell_type)[0])
    short = _rocket_too_short(cell_type, w)
    for g in GROUPS:
        if g not in feedable or (g == "rocket" and short):  # a group reading a channel the recording lacks (or
            # its cell type cannot feed, or a window shorter than the rocket transforms' largest kernel)
            groups[g] = np.full(len(selection_labels(cell_type, (g,))) if fitted(cell_type, g) else 0, np.nan)
            seconds[g] = 0.0
            continue
        t0 = time.perf_counter()
        groups[g] = describe_window(robot, cells, layout="concat", groups=(g,), force_threshold_n=-np.inf).values
        seconds[g] = time.perf_counter() - t0
    force_n = cells[0].force_n
    gate = contact_gate([force_n], force_threshold_n)
    return groups, bool(gate[0]), float(force_n.mean()), seconds


# --------------------------------------------------------------------------- bank with cache


def _file_stamp(path: str) -> tuple[int, int]:
    st = os.stat(path)
    return int(st.st_size), int(st.st_mtime_ns)


def _cache_path(cache_dir: Path, n_frames: int, force_threshold_n: float, n_per_count: float,
                cell_type: CellType, present: Sequence[tuple[str, ...]] = ()) -> Path:
    key = json.dumps({"v": _BANK_VERSION, "n_frames": n_frames, "ft": force_threshold_n, "npc": n_per_count,
                      "bands": PAC_BANDS_HZ, "ebands": ELECTRODE_BANDS_HZ, "ppf": PAC_PER_FRAME,
                      "cell_type": repr(cell_type), "rocket": _rocket_digest(cell_type)}
                     | ({"present": [list(p) for p in present]}
                        if any(p != cell_type.channels for p in present) else {}))
    digest = hashlib.sha1(key.encode()).hexdigest()[:16]
    return cache_dir / f"bank_{n_frames}f_{digest}.npz"


def _rocket_digest(cell_type: CellType) -> str:
    """SHA-1 of the cell type's fitted rocket transforms (refitting them recomputes the banks); "" without."""
    try:
        params = rocket_parameters(cell_type)
    except ConfigError:
        return ""
    return hashlib.sha1(json.dumps({k: v.state() for k, v in sorted(params.items())}).encode()).hexdigest()


def _load_cache(path: Path) -> dict[tuple, tuple]:
    if not path.is_file():
        return {}
    try:
        with np.load(path, allow_pickle=False) as z:
            keys = [tuple(k) for k in z["keys"].tolist()]
            paths = z["paths"].tolist()
            rows = {g: z[f"g_{g}"] for g in GROUPS}
            sec = {g: z[f"s_{g}"] for g in GROUPS}
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
    for g in GROUPS:
        arrays[f"s_{g}"] = np.array([e[4][g] for _, e in items])
    tmp = path.with_name(path.name + f".{os.getpid()}.tmp.npz")
    np.savez(tmp, **arrays)
    os.replace(tmp, path)


def _use_config_dir(path: str | None) -> None:
    """A worker's initializer: read the config directory the parent process reads."""
    if path is None:
        os.environ.pop("TACTILE_CONFIG_DIR", None)
    else:
        os.environ["TACTILE_CONFIG_DIR"] = path


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
    summary, names = piece_summary(values.reshape(len(bank.windows), N_SUBWINDOWS, -1), labels)
    bank.groups["subwindows"] = summary
    bank.labels["subwindows"] = tuple(f"subwindows/{lab}" for lab in names)
    per_piece = sum(sub.seconds[g] for g in _SUBWINDOW_SOURCE)
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
    present = sorted({recording_channels(r, cell_type)[0] for r in recordings})
    cpath = (_cache_path(Path(cache_dir), n_frames, threshold, cell_type.force.n_per_count, cell_type, present)
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
            rate_hz = float(np.median([r.frame_rate_hz for r in recordings])) or 100.0
            bar = tqdm(total=len(tasks), desc=f"{desc} ({n_frames / rate_hz:.2f} s windows)", unit="trial",
                       leave=False)
        if jobs > 1 and len(tasks) > 4:
            # the workers read the config directory the caller reads (a transform in use, rocket_fit)
            pool = ProcessPoolExecutor(max_workers=jobs, initializer=_use_config_dir,
                                       initargs=(os.environ.get("TACTILE_CONFIG_DIR"),))
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
        seconds={g: np.array([r[4][g] for r in rows]) for g in GROUPS},
        unfed=cell_type_groups(cell_type)[1],
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


def _group_columns(bank: FeatureBank, group: str) -> tuple[np.ndarray, tuple[str, ...]]:
    """A group's columns of a bank; ``levels:<ch>,<ch>`` the named channels' levels, labelled as the core does."""
    name, chans = parse_group(group, key="channels") if group != "subwindows" else (group, None)
    if chans is None:
        return bank.groups[name], bank.labels[name]
    index = {lab.rsplit("/", 1)[-1]: i for i, lab in enumerate(bank.labels[name])}
    cols = [index.get(f"level_{c}") for c in chans]
    if any(i is None for i in cols):
        raise ConfigError(f"feature group {group!r}: the cell type declares no slow channel "
                          f"{chans[cols.index(None)]!r}", key="channels")
    return bank.groups[name][:, cols], tuple(f"{group}/level_{c}" for c in chans)


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
    unfed = [g for g in groups if g.partition(":")[0] in bank.unfed]
    if unfed:
        able = [g for g in GROUPS if g not in bank.unfed]
        raise ConfigError(f"mode {mode!r}: {bank.unfed[unfed[0]]}; the groups it can feed: {', '.join(able)}",
                          key="channels")
    missing = [g for g in groups if g.partition(":")[0] not in bank.groups]
    if missing:
        raise ConfigError(f"mode {mode!r} needs the {missing} group(s): compute the bank with subwindows=True")
    parts = [_group_columns(bank, g) for g in groups]
    empty = [g for g, p in zip(groups, parts) if p[0].shape[1] == 0]
    if empty:
        raise ConfigError(f"feature group {empty[0]!r} of mode {mode!r} was not computed: the cell type has no "
                          "fitted transform for it (tactile fit-rocket)", key="channels")
    X = np.concatenate([p[0] for p in parts], axis=1)
    labels = tuple(lab for p in parts for lab in p[1])
    if np.isnan(X).all(axis=0).any():
        g = groups[int(np.flatnonzero([np.isnan(p[0]).all(axis=0).any() for p in parts])[0])]
        raise ConfigError(f"feature group {g!r} of mode {mode!r} was not computed: the recordings lack a channel "
                          "it reads, or (rocket) the windows are shorter than its largest kernel", key="channels")
    keep = drop_quantities(labels, drop)
    if not keep.any():
        raise ConfigError(f"dropping {sorted(drop)} leaves no feature of mode {mode!r}")
    X, labels = X[:, keep], tuple(lab for lab, k in zip(labels, keep) if k)
    if gate:
        X = np.where(bank.in_contact[:, None], X, 0.0)
    return X, labels
