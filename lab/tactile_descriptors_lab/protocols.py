"""The paper's protocols on simulated robots (Kaboli et al. 2018, sections IV-VII).

Each protocol simulates a training scene and one or more test scenes from
``config/scenes/`` at the sample level (:func:`~..sim.engine.iter_simulate`,
no wire formats), turns every exploration into one descriptor with the
core (:func:`~..core.aggregation.describe_window`) and scores the paper's
learners from :mod:`.classifiers` on it:

* **SVM**: linear, C by repeated 5-fold CV over the paper's grid, refit on
  all training explorations (section VI-B);
* **PA-I**: the online learning curve, test accuracy after 1..N training
  explorations per class, the paper's plain PA-I (eq. 30-32, eta = 1) and,
  beside it, the core's ``max_loss`` update with weight averaging;
* **GMM-EM**: spherical mixture, k = number of classes, k-means (20
  restarts) initialisation, NMI (eq. 34) of the test explorations' clusters.

Exploration window: the paper's exploration time ``t`` -- from the moment the
force reached its set value and sliding started to the end of sliding
(``slide_start_ns`` .. ``slide_end_ns`` of the simulator's ground truth;
2 s in training, 2-10 s in the tests).  The force of the contact gate
(eq. 13/16/27) is tared per exploration on the pause after it, as the paper
re-calibrates the sensors between explorations.

Descriptors (``modes``): ``paper`` is eq. 17/28 (``averaged``: channels of an
axis averaged) with the body parts concatenated (eq. 18/29); ``per_channel``
keeps every channel; ``pooled`` averages the body parts in contact (the same
values whichever hand or fingers touch).

Cost is bounded by a :class:`Plan`: fewer materials and repeats than the
shipped scenes (which reproduce the paper's 120 materials x 20 / 100
rounds), applied as documented overrides of the scenes' ``explorations``;
the plan is recorded in the results.  For the NAO material protocols only
the two hands are simulated (:func:`restrict_robot`): every random draw of
the simulator is keyed by cell, so the hands' samples are identical to a
full-robot simulation (a test checks it), and the other body parts, not in
contact, contribute only gated zeros to the concatenated descriptor.

Everything here is **simulated data**: the numbers say what the descriptors
and learners do on the simulator's texture models, not on the paper's robots.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import functools
import math
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import yaml

from tactile_descriptors_ros.core.aggregation import CellSignals, describe_window
from tactile_descriptors_ros.core.cell_types import CellType
from tactile_descriptors_ros.core.robot import RobotDescription
from tactile_descriptors_ros.core.tare import resting_level
from tactile_descriptors_ros.errors import ConfigError, SceneError, SignalError
from tactile_descriptors_ros.sim.engine import CellRecord, ExplorationTiming, SimResult, Stream, iter_simulate
from tactile_descriptors_ros.sim.scene import Scene, parse_scene, restrict_robot, scene_path

__all__ = [
    "MODES",
    "PAPER_NUMBERS",
    "Plan",
    "FULL_PLAN",
    "QUICK_PLAN",
    "SKIN_GROUPS_PLAN",
    "Protocol",
    "PROTOCOLS",
    "DescriptorSet",
    "override_scene",
    "restrict_robot",
    "material_world",
    "renderable",
    "exploration_signals",
    "describe_scene",
    "evaluate_sets",
    "run_protocol",
    "run_protocols",
    "results_table",
    "write_report",
    "PAPER_PA_T",
    "CHECK_SPEEDS_M_S",
    "CHECK_RATES_HZ",
    "CHECK_FORCE_RATES_HZ",
    "HELD_OUT_SEED_OFFSET",
]

#: Descriptor modes: name -> (layout, feature groups) of :func:`describe_window`.  The ``pooled_*``
#: group selections are the candidates the skin cells' default was chosen from (lab/docs/simulated.md).
MODES: dict[str, tuple[str, tuple[str, ...]]] = {
    "paper": ("concat", ("paper",)),
    "per_channel": ("concat", ("per_channel",)),
    "pooled": ("pooled", ("paper",)),
    "pooled_per_channel": ("pooled", ("per_channel",)),
    "pooled_bands": ("pooled", ("per_channel", "bands")),
    "pooled_levels": ("pooled", ("per_channel", "levels")),
    "pooled_statistics": ("pooled", ("per_channel", "statistics")),
    "pooled_combined": ("pooled", ("per_channel", "bands", "levels", "statistics")),
    "pooled_paper_bands": ("pooled", ("paper", "bands")),
}

#: The paper's own numbers (its robots, its data), with where they are printed.
PAPER_NUMBERS: dict[str, dict[str, tuple[float, str]]] = {
    "shadow_lateral": {
        "svm": (1.00, "Table II, lateral sliding (train full hand)"),
        "pa": (1.00, "Fig. 7: 100 % after 15 samples per class (lateral)"),
        "nmi": (0.92, "Table IV, lateral sliding"),
    },
    "shadow_finger_subsets": {
        "svm": (1.00, "Table II: train full hand, test any combination of 1-5 fingers"),
    },
    "shadow_combined": {
        "svm": (1.00, "Table II, combination of lateral, medial and circular"),
        "pa": (1.00, "Fig. 7 / VII-A2: 100 % with only 6 training samples (train LMC, test 9 sequences)"),
        "nmi": (0.95, "Table IV, combination of lateral, medial and circular"),
    },
    "nao_right_to_left": {
        "svm": (0.971, "Table V, lateral sliding (train right hand, test left hand)"),
        "pa": (0.93, "Fig. 9 / VII-B3: > 93 % after 20 training samples"),
        "nmi": (0.88, "Table VII, lateral sliding"),
    },
    "nao_large_objects": {
        "svm": (0.906, "Table VI / VII-B2: train 1000 g, test 500 and 1500 g: 90.6 %"),
        "nmi": (0.83, "Table VII: 0.81 (500 g), 0.83 (1000 g), 0.85 (1500 g)"),
    },
}


@dataclass(frozen=True)
class Plan:
    """How much of each protocol to simulate (an override of the shipped scenes).

    Attributes
    ----------
    name : str
    materials : int
        Materials (or objects) per material protocol: the first ``materials``
        of the scene's list (the 20 fitted materials in name order, then the
        parametric ones).
    objects : int
        Objects for the large-object protocol (parametric ``object_001`` ...).
    train_repeat, test_repeat : int
        Rounds of training / test explorations per material (the scenes: 20 / 100).
    combined_train_repeat : int
        Rounds of the combined-motion training scene.
    objects_train_repeat, objects_test_repeat : int
        Rounds of the large-object scenes (per weight for the test).
    test_duration_s : float or None
        Replace the tests' random 2-10 s exploration time by a fixed one (None: keep the scene's).
    cv_repeats : int
        Repeats of the SVM's 5-fold CV (the paper: 10).
    pa_orders : int
        Presentation orders the PA curve is averaged over.
    modes : tuple of str
        Descriptor modes (:data:`MODES`), each scored with SVM, PA-I and GMM-EM.
    protocols : tuple of str
        Protocols to run (keys of :data:`PROTOCOLS`).
    chunk_s : float
        Simulated seconds per simulator chunk (memory bound).
    """

    name: str
    materials: int = 30
    objects: int = 20
    train_repeat: int = 20
    test_repeat: int = 5
    combined_train_repeat: int = 15
    objects_train_repeat: int = 10
    objects_test_repeat: int = 3
    test_duration_s: float | None = None
    cv_repeats: int = 10
    pa_orders: int = 5
    modes: tuple[str, ...] = ("paper", "per_channel", "pooled")
    protocols: tuple[str, ...] = ("shadow_lateral", "shadow_finger_subsets", "shadow_combined",
                                  "nao_right_to_left", "nao_large_objects")
    chunk_s: float = 60.0

    def __post_init__(self) -> None:
        for k in ("materials", "objects", "train_repeat", "test_repeat", "combined_train_repeat",
                  "objects_train_repeat", "objects_test_repeat", "cv_repeats", "pa_orders"):
            if int(getattr(self, k)) < 1:
                raise ConfigError(f"must be at least 1, got {getattr(self, k)}", key=f"plan.{k}")
        for k in ("train_repeat", "combined_train_repeat", "objects_train_repeat"):
            if int(getattr(self, k)) < 5:
                raise ConfigError("5-fold CV needs at least 5 training explorations per class",
                                  key=f"plan.{k}")
        unknown = [m for m in self.modes if m not in MODES]
        if unknown or not self.modes:
            raise ConfigError(f"unknown descriptor modes {unknown}; choose from {sorted(MODES)}", key="plan.modes")
        bad = [p for p in self.protocols if p not in PROTOCOLS]
        if bad:
            raise ConfigError(f"unknown protocols {bad}; choose from {sorted(PROTOCOLS)}", key="plan.protocols")
        if self.test_duration_s is not None and not self.test_duration_s > 0:
            raise ConfigError(f"must be positive, got {self.test_duration_s}", key="plan.test_duration_s")

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


# --------------------------------------------------------------------------- scenes


def _material_names(spec: Any) -> list[str]:
    """The materials a scene entry names, in the scene's own order (fitted sorted, then parametric)."""
    if isinstance(spec, str):
        return [spec]
    if isinstance(spec, list):
        return [str(m) for m in spec]
    if isinstance(spec, Mapping):
        out: list[str] = []
        fitted = spec.get("fitted", [])
        if fitted == "all":
            from tactile_descriptors_ros.sim.textures import material_library

            out += sorted(material_library())
        elif isinstance(fitted, list):
            out += [str(m) for m in fitted]
        prefix = str(spec.get("prefix", "material"))
        out += [f"param:{prefix}_{j:03d}" for j in range(1, int(spec.get("parametric", 0)) + 1)]
        return out
    raise SceneError(f"cannot read the materials {spec!r}", key="explorations.materials")


#: Speeds (m/s) and sample rates (Hz) a material must render at to be used (:func:`renderable`):
#: the paper's speed grid 0.5-4 cm/s, the large objects' 1-3 cm/s, BioTac PAC and skin accelerometer.
CHECK_SPEEDS_M_S: tuple[float, ...] = tuple(round(0.005 * k, 3) for k in range(1, 9))
CHECK_RATES_HZ: tuple[float, ...] = (2200.0, 1000.0)
#: Skin force-sensor rates (Hz) at which the force texture modulation is rendered.
CHECK_FORCE_RATES_HZ: tuple[float, ...] = (250.0,)


@functools.lru_cache(maxsize=4096)
def renderable(name: str, material_seed: int = 0) -> bool:
    """Whether the simulator can render ``name`` at every speed of :data:`CHECK_SPEEDS_M_S`.

    Checked: the vibration model at :data:`CHECK_RATES_HZ` and the skin's
    force-texture model at :data:`CHECK_FORCE_RATES_HZ` (the two AR models
    the engine rescales with speed).

    Some parametric materials have a pole so close to the unit circle that
    the speed rescaling of their AR model (``textures.rescale_ar``) becomes
    unstable at the slowest speeds (``SceneError``: reflection coefficient
    +-1); a protocol that drew such a pair would stop mid-run.  Material
    lists skip them (counted in the results).
    """
    from tactile_descriptors_ros.sim.textures import get_material, rescale_ar

    try:
        mat = get_material(name, seed=material_seed)
        dm = mat.deformation
        for v in CHECK_SPEEDS_M_S:
            for rate in CHECK_RATES_HZ:
                mat.vibration.at(rate, v, mat.reference_speed_m_s)
            for rate in CHECK_FORCE_RATES_HZ:  # the skin's force-texture modulation (engine, electrode_deformation)
                rescale_ar(np.array(dm.pdc_ar), dm.pdc_sigma2, (v / mat.reference_speed_m_s) * dm.fs_hz / rate)
    except SceneError:
        return False
    return True


def override_scene(name: str, *, materials: int | Sequence[str] | None = None, repeat: int | None = None,
                   duration_s: float | None = None, motion: str | None = None,
                   body_parts: Any = None, seed: int | None = None,
                   material_seed: int = 0) -> tuple[Scene, dict[str, Any]]:
    """Load a shipped scene with smaller exploration lists (the documented override).

    Parameters
    ----------
    name : str
        Shipped scene name or path.
    materials : int or list of str, optional
        Keep the first ``materials`` :func:`renderable` ones of each entry's
        materials, or exactly these.
    repeat, duration_s, motion, body_parts : optional
        Replace the entries' ``repeat`` / the exploration time / the motion /
        the touching body parts.
    seed : int, optional
        Replace the scene's seed (a held-out set from the same scene).
    material_seed : int
        Seed of the parametric materials (:func:`material_world`).

    Returns
    -------
    (Scene, dict)
        The validated scene and a record of what was overridden.
    """
    path = scene_path(name)
    data = yaml.safe_load(path.read_text())
    data = copy.deepcopy(data)
    record: dict[str, Any] = {"scene": path.stem}
    entries = data.get("explorations")
    if not isinstance(entries, list) or not entries:
        raise SceneError("expected a non-empty list", key="explorations", source=str(path))
    for k, entry in enumerate(entries):
        key = "materials" if "materials" in entry else "material"
        names = _material_names(entry[key])
        if materials is not None:
            if isinstance(materials, int):
                ok: list[str] = []
                skipped: list[str] = []
                for n in names:
                    if len(ok) == materials:
                        break
                    (ok if renderable(n, material_seed) else skipped).append(n)
                if len(ok) < materials:
                    raise SceneError(f"only {len(ok)} renderable materials, {materials} asked for",
                                     key=f"explorations[{k}].materials")
                record["skipped_unrenderable"] = sorted(set(record.get("skipped_unrenderable", [])) | set(skipped))
                names = ok
            else:
                names = list(materials)
            entry.pop("material", None)
            entry["materials"] = names
        if repeat is not None:
            entry["repeat"] = int(repeat)
        if duration_s is not None:
            entry["duration_s"] = float(duration_s)
        if motion is not None:
            entry["motion"] = motion
        if body_parts is not None:
            entry["body_parts"] = body_parts
        record.setdefault("entries", []).append({"materials": len(names), "repeat": entry.get("repeat", 1)})
    for k, v in (("materials", materials if isinstance(materials, (int, type(None))) else len(materials)),
                 ("repeat", repeat), ("duration_s", duration_s), ("motion", motion), ("body_parts", body_parts)):
        if v is not None:
            record[k] = v
    if seed is not None:
        record["seed"] = int(seed)
    scene = parse_scene(data, source=str(path), seed=seed)
    record["explorations"] = len(scene.explorations)
    record["simulated_s"] = round(scene.duration_s, 1)
    return scene, record


@contextlib.contextmanager
def material_world(seed: int = 0):
    """Render parametric materials from one fixed seed, whatever the scene's seed.

    The engine draws a parametric material (``param:<name>``) from
    ``(name, scene.seed)``, so a training scene and a test scene with
    different seeds (as every shipped protocol pair has) would render
    *different* textures under the same name.  Inside this context the
    material seed is ``seed`` for every scene, so ``param:material_007`` is
    the same texture in training and test, while each scene's own seed still
    drives its exploration draws, noise and everything else.  The engine
    itself now renders every material from seed 0 whatever the scene's seed,
    so ``material_world(0)`` changes nothing; another seed gives another
    world of parametric materials.
    """
    from tactile_descriptors_ros.sim import engine

    original = engine.get_material

    def fixed(name: str, seed: int = 0, folder: Any = None):
        return original(name, seed=world_seed, folder=folder)

    world_seed = int(seed)
    engine.get_material = fixed
    try:
        yield
    finally:
        engine.get_material = original


# --------------------------------------------------------------------------- windows


def _flat(axes: tuple[tuple[str, ...], ...]) -> tuple[str, ...]:
    return tuple(ch for ax in axes for ch in ax)


def _stream_with(cell: CellRecord, channels: tuple[str, ...]) -> tuple[Stream, np.ndarray]:
    """The stream holding ``channels`` and their row indices."""
    for st in cell.streams.values():
        if all(ch in st.channels for ch in channels):
            return st, np.array([st.channels.index(ch) for ch in channels])
    raise SceneError(f"cell {cell.cell_id} ({cell.name}) has no stream with channels {list(channels)}",
                     key="robot.cell_types")


def _span(st: Stream, t0_ns: int, t1_ns: int) -> slice:
    a, b = np.searchsorted(st.t_ns, [t0_ns, t1_ns], side="left")
    return slice(int(a), int(b))


def _clean(st: Stream, rows: np.ndarray, sl: slice) -> tuple[np.ndarray, np.ndarray, int, bool]:
    """Samples of ``rows`` in ``sl`` without faulty ones; (values, t_ns, n_invalid, gap)."""
    vals = st.counts[rows, sl]
    t = st.t_ns[sl]
    ok = (st.fault[rows, sl] == 0).all(axis=0)
    seq = st.seq[sl]
    gap = bool(seq.size > 1 and np.any(np.diff(seq) > 1))
    n_bad = int(ok.size - np.count_nonzero(ok))
    if n_bad:
        vals, t = vals[:, ok], t[ok]
    return vals, t, n_bad, gap


def _tare(cell: CellRecord, cell_type: CellType, t0_ns: int, t1_ns: int) -> np.ndarray:
    """Per force channel: the resting level over the valid samples in [t0, t1) (no contact).

    :func:`~tactile_descriptors_ros.core.tare.resting_level` over a span at
    rest (``rest_percentile`` 100), as a driver's ``~/tare`` takes it.
    """
    st, rows = _stream_with(cell, cell_type.force.channels)
    vals, _, _, _ = _clean(st, rows, _span(st, t0_ns, t1_ns))
    try:
        return resting_level(vals).reference
    except SignalError as e:
        raise SceneError(f"cell {cell.cell_id}: no force level without contact to tare on ({e}; pause too "
                         "short?)", key="explorations.pause_s") from None


def exploration_signals(result: SimResult, timing: ExplorationTiming, robot: RobotDescription, *,
                        tare_settle_s: float = 0.1) -> dict[int, CellSignals]:
    """One exploration's window of every cell, ready for :func:`describe_window`.

    The window is the exploration time ``[slide_start_ns, slide_end_ns)``;
    force in newtons is ``(counts - tare) * n_per_count`` (mean over a cell's
    force channels, eq. 27), tared on the pause after the exploration
    (from ``release + tare_settle_s`` to the pause's end).  Faulty samples
    are removed and counted (``invalid_samples``); holes in the sample
    sequence set ``gap``.
    """
    e = timing.exploration
    t0, t1 = timing.slide_start_ns, timing.slide_end_ns
    p0 = timing.release_ns + int(round(tare_settle_s * 1e9))
    p1 = timing.release_ns + int(round(e.pause_s * 1e9)) - 1
    if p1 <= p0:
        raise SceneError(f"exploration {e.index}: pause_s {e.pause_s} leaves no time to tare on",
                         key="explorations.pause_s")
    index = robot.cell_index()
    out: dict[int, CellSignals] = {}
    for cid, cell in result.cells.items():
        if cid not in index:
            continue
        ct = robot.cell_types[index[cid][0].cell_type]
        vst, vrows = _stream_with(cell, _flat(ct.vibration.axes))
        dst, drows = _stream_with(cell, _flat(ct.deformation.axes))
        fst, frows = _stream_with(cell, ct.force.channels)
        vib, vt, vbad, vgap = _clean(vst, vrows, _span(vst, t0, t1))
        dfm, dt, dbad, dgap = _clean(dst, drows, _span(dst, t0, t1))
        frc, _, fbad, fgap = _clean(fst, frows, _span(fst, t0, t1))
        tare = _tare(cell, ct, p0, p1)
        force_n = (frc.astype(np.float64) - tare[:, None]).mean(axis=0) * float(ct.force.n_per_count)
        out[cid] = CellSignals(vib, vt, dfm, dt, force_n, valid=vib.shape[1] > 0 and dfm.shape[1] > 1,
                               gap=vgap or dgap or fgap, invalid_samples=vbad + dbad + fbad,
                               extra=_extra_at(cell, ct.extra_channels, dt) if ct.extra_channels else None)
    return out


def _extra_at(cell: CellRecord, channels: tuple[str, ...], t_ns: np.ndarray) -> np.ndarray:
    """The extra channels at the deformation stamps ``t_ns``: each channel's latest valid sample, as a
    driver publishes them with each force sample (NaN before a channel's first sample)."""
    out = np.full((len(channels), t_ns.size), np.nan)
    for k, ch in enumerate(channels):
        st, rows = _stream_with(cell, (ch,))
        ok = st.fault[rows[0]] == 0
        ts, vals = st.t_ns[ok], st.counts[rows[0], ok].astype(np.float64)
        if ch == "temperature":  # the simulator's counts are centi-degrees; drivers publish degrees C
            vals = vals / 100.0
        i = np.searchsorted(ts, t_ns, side="right") - 1
        have = i >= 0
        out[k, have] = vals[i[have]]
    return out


@dataclass
class DescriptorSet:
    """Descriptors of every exploration of one simulated scene.

    Attributes
    ----------
    scene : str
    X : dict of mode -> numpy.ndarray, shape (n, d)
    feature_labels : dict of mode -> tuple of str
    labels : numpy.ndarray of str
        Material (class) of each exploration.
    info : list of dict
        Per exploration: motion, body parts, force, speed, exploration time,
        weight, parts in contact.
    simulate_s, describe_s : float
        Wall time spent simulating and computing descriptors.
    override : dict
        The plan's override of the shipped scene.
    """

    scene: str
    X: dict[str, np.ndarray]
    feature_labels: dict[str, tuple[str, ...]]
    labels: np.ndarray
    info: list[dict[str, Any]]
    simulate_s: float
    describe_s: float
    override: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.labels.size)

    def subset(self, mask: np.ndarray) -> DescriptorSet:
        idx = np.flatnonzero(mask)
        return DescriptorSet(self.scene, {m: x[idx] for m, x in self.X.items()}, self.feature_labels,
                             self.labels[idx], [self.info[i] for i in idx], self.simulate_s, self.describe_s,
                             self.override)


def describe_scene(scene: Scene, modes: Sequence[str], *, chunk_s: float = 60.0, progress: bool = False,
                   override: Mapping[str, Any] | None = None, material_seed: int = 0) -> DescriptorSet:
    """Simulate ``scene`` chunk by chunk and describe each exploration in each mode.

    Parametric materials are rendered from ``material_seed`` (see
    :func:`material_world`), so scenes described with the same value share
    their textures.
    """
    for m in modes:
        if m not in MODES:
            raise ConfigError(f"unknown descriptor mode {m!r}; choose from {sorted(MODES)}", key="modes")
    robot = scene.robot
    rows: dict[str, list[np.ndarray]] = {m: [] for m in modes}
    flabels: dict[str, tuple[str, ...]] = {}
    labels: list[str] = []
    info: list[dict[str, Any]] = []
    sim_s = desc_s = 0.0
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(scene.explorations), desc=scene.name, unit="touch", leave=False)
    chunks = iter_simulate(scene, max_chunk_s=chunk_s)
    while True:
        t = time.perf_counter()
        with material_world(material_seed):
            try:
                res = next(chunks)
            except StopIteration:
                break
        sim_s += time.perf_counter() - t
        t = time.perf_counter()
        for timing in res.explorations:
            sigs = exploration_signals(res, timing, robot)
            contact: list[str] = []
            for m in modes:
                layout, groups = MODES[m]
                d = describe_window(robot, sigs, layout=layout, groups=groups)
                rows[m].append(np.asarray(d.values, dtype=np.float64))
                flabels.setdefault(m, d.labels)
                if not contact:
                    contact = [bp.name for bp in d.body_parts if bp.contact]
            e = timing.exploration
            labels.append(e.label)
            info.append({"motion": "+".join(e.motion), "body_parts": list(e.body_parts), "force_n": e.force_n,
                         "speed_m_s": e.speed_m_s, "duration_s": e.duration_s, "weight_g": e.weight_g,
                         "in_contact": contact})
        desc_s += time.perf_counter() - t
        if bar is not None:
            bar.update(len(res.explorations))
    if bar is not None:
        bar.close()
    X = {m: np.vstack(r) for m, r in rows.items()}
    return DescriptorSet(scene.name, X, flabels, np.array(labels), info, sim_s, desc_s, dict(override or {}))


# --------------------------------------------------------------------------- learners


def _encode(train: np.ndarray, test: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[str]]:
    classes = sorted(set(train.tolist()))
    unseen = sorted(set(test.tolist()) - set(classes))
    if unseen:
        raise ConfigError(f"test classes {unseen[:5]} never occur in training", key="protocol")
    idx = {c: k for k, c in enumerate(classes)}
    return np.array([idx[c] for c in train]), np.array([idx[c] for c in test]), classes


def _accuracy_by(groups: Iterable[Any], correct: np.ndarray) -> dict[str, dict[str, float]]:
    g = np.array([str(x) for x in groups])
    return {k: {"accuracy": float(correct[g == k].mean()), "n": int((g == k).sum())} for k in sorted(set(g))}


def evaluate_sets(train: DescriptorSet, test: DescriptorSet, *, modes: Sequence[str], cv_repeats: int = 10,
                  pa_orders: int = 5, pa_modes: Sequence[str] | None = None, n_pa_max: int = 20,
                  group_by: Callable[[dict[str, Any]], Any] | None = None, seed: int = 0,
                  fits: dict[tuple, Any] | None = None) -> dict[str, Any]:
    """Score the SVM, the PA-I curves and GMM-EM/NMI (``pa_modes``, default every mode) on one split.

    ``fits`` caches the fitted SVMs by training set and mode, so a training
    set scored against several test sets is fitted (and cross-validated) once.

    Returns
    -------
    dict
        ``modes.<mode>.svm`` (``accuracy``, ``best_c``, ``cv_accuracy``,
        ``by_group``), ``modes.<mode>.pa`` (``plain`` and ``max_loss_avg``:
        ``curve``, ``n_per_class``, ``final``), ``modes.<mode>.gmm``
        (``nmi_test``, ``nmi_train``, ``accuracy``), the sizes and the chance level.
    """
    from tactile_descriptors_lab.evaluation.classifiers import fit_svm, gmm_nmi, pa_curve

    y_tr, y_te, classes = _encode(train.labels, test.labels)
    groups_tr = np.arange(len(train))
    pa_modes = list(modes if pa_modes is None else pa_modes)
    out: dict[str, Any] = {"n_train": len(train), "n_test": len(test), "n_classes": len(classes),
                           "chance": 1.0 / len(classes), "modes": {}}
    for m in modes:
        Xtr, Xte, fl = train.X[m], test.X[m], train.feature_labels[m]
        if Xtr.shape[1] != Xte.shape[1]:
            raise ConfigError(f"mode {m}: {Xtr.shape[1]} training features vs {Xte.shape[1]} test features",
                              key="protocol")
        r: dict[str, Any] = {"n_features": int(Xtr.shape[1])}
        fit_key = (id(train), m, cv_repeats, seed)
        if fits is not None and fit_key in fits:
            svm = fits[fit_key][1]
        else:
            svm = fit_svm(Xtr, y_tr, groups_tr, fl, repeats=cv_repeats, seed=seed)
            if fits is not None:
                fits[fit_key] = (train, svm)  # the set is kept alive so its id stays unique
        pred = svm.predict(Xte)
        correct = pred == y_te
        r["svm"] = {"accuracy": float(correct.mean()), "best_c": svm.best_c, "cv_accuracy": svm.cv_accuracy,
                    "select_s": svm.select_s}
        if group_by is not None:
            r["svm"]["by_group"] = _accuracy_by((group_by(i) for i in test.info), correct)
        if m in pa_modes:
            r["pa"] = {}
            for variant, kw in (("plain", {}), ("max_loss_avg", {"update": "max_loss", "average": True})):
                c = pa_curve(Xtr, y_tr, groups_tr, Xte, y_te, fl, n_max=n_pa_max, orders=pa_orders, seed=seed,
                             **kw)
                r["pa"][variant] = {"n_per_class": c.n_per_class.tolist(), "curve": c.accuracy.tolist(),
                                    "curve_std": c.accuracy_std.tolist(), "final": float(c.accuracy[-1])}
            g = gmm_nmi(Xtr, y_tr, Xte, y_te, fl, seed=seed)
            r["gmm"] = {"nmi_test": g.nmi_test, "nmi_train": g.nmi_train, "accuracy": g.accuracy}
        out["modes"][m] = r
    return out


# --------------------------------------------------------------------------- protocols


@dataclass(frozen=True)
class Protocol:
    """One of the paper's experiments on simulated robots.

    ``build(plan)`` returns ``(train_scene, train_override, [(test_name, test_scene, test_override), ...])``.
    """

    key: str
    title: str
    robot: str
    paper_section: str
    build: Callable[[Plan], tuple[Scene, dict, list[tuple[str, Scene, dict]]]]
    group_by: Callable[[dict[str, Any]], Any] | None = None
    notes: str = ""


_HANDS = ("left_hand", "right_hand")
#: Seed offset of a held-out test set drawn from a training scene.
HELD_OUT_SEED_OFFSET = 1000


def _shadow_lateral(plan: Plan):
    tr, o_tr = override_scene("shadow_hand_lateral_train", materials=plan.materials, repeat=plan.train_repeat)
    te, o_te = override_scene("shadow_hand_lateral_test", materials=plan.materials, repeat=plan.test_repeat,
                              duration_s=plan.test_duration_s)
    return tr, o_tr, [("full hand", te, o_te)]


def _shadow_subsets(plan: Plan):
    tr, o_tr = override_scene("shadow_hand_lateral_train", materials=plan.materials, repeat=plan.train_repeat)
    te, o_te = override_scene("shadow_hand_finger_subsets_test", materials=plan.materials,
                              repeat=plan.test_repeat, duration_s=plan.test_duration_s, motion="lateral")
    return tr, o_tr, [("finger subsets", te, o_te)]


def _shadow_combined(plan: Plan):
    tr, o_tr = override_scene("shadow_hand_combined_train", materials=plan.materials,
                              repeat=plan.combined_train_repeat)
    te, o_te = override_scene("shadow_hand_combined_test", materials=plan.materials, repeat=plan.test_repeat,
                              duration_s=plan.test_duration_s)
    return tr, o_tr, [("9 motion sequences", te, o_te)]


def _nao_hands(plan: Plan):
    tr, o_tr = override_scene("nao_right_hand_train", materials=plan.materials, repeat=plan.train_repeat)
    te, o_te = override_scene("nao_left_hand_test", materials=plan.materials, repeat=plan.test_repeat,
                              duration_s=plan.test_duration_s)
    for o in (o_tr, o_te):
        o["robot"] = "nao restricted to left_hand + right_hand (other parts: no contact)"
    return restrict_robot(tr, _HANDS), o_tr, [("left hand", restrict_robot(te, _HANDS), o_te)]


def _nao_objects(plan: Plan):
    tr, o_tr = override_scene("nao_large_objects_train_1000g", materials=plan.objects,
                              repeat=plan.objects_train_repeat)
    te, o_te = override_scene("nao_large_objects_test_500_1500g", materials=plan.objects,
                              repeat=plan.objects_test_repeat)
    # our reference, not in the paper: a held-out set of the training weight (another seed)
    ref, o_ref = override_scene("nao_large_objects_train_1000g", materials=plan.objects,
                                repeat=plan.objects_test_repeat, seed=tr.seed + HELD_OUT_SEED_OFFSET)
    return tr, o_tr, [("500 g + 1500 g", te, o_te), ("1000 g, held out", ref, o_ref)]


#: The protocols, in report order.
PROTOCOLS: dict[str, Protocol] = {p.key: p for p in (
    Protocol("shadow_lateral", "Shadow Hand, lateral sliding: train 2 s, test 2-10 s", "shadow_hand",
             "IV-A2, VII-A1/2/5", _shadow_lateral, lambda i: f"{int(i['duration_s'])} s",
             "train and test with all five fingers"),
    Protocol("shadow_finger_subsets", "Shadow Hand: train full hand, test finger subsets", "shadow_hand",
             "VII-A1, Table II", _shadow_subsets, lambda i: f"{len(i['body_parts'])} finger(s)",
             "test motion overridden to lateral (the scene mixes L/M/C; the paper's Table II row is per motion)"),
    Protocol("shadow_combined", "Shadow Hand: train L+M+C 3 s, test 9 motion sequences 3-10 s", "shadow_hand",
             "IV-A5, VII-A2", _shadow_combined, lambda i: i["motion"], ""),
    Protocol("nao_right_to_left", "NAO: train right hand (2 cm, 2 s), test left hand (1 cm, 2-10 s)", "nao",
             "V-A1, VII-B1", _nao_hands, lambda i: f"{int(i['duration_s'])} s",
             "concatenated descriptor: training fills the right-hand block, tests the left-hand block"),
    Protocol("nao_large_objects", "NAO: large objects, train 1000 g, test 500 g and 1500 g", "nao",
             "V-B, VII-B2", _nao_objects, lambda i: f"{int(i['weight_g'])} g",
             "all 116 cells; force, speed and sliding time follow the weight (docs/simulator.md)"),
)}


#: The full plan (lab/docs/simulated.md): about 10-15 minutes on one core; the SVM's CV is repeated 3
#: times instead of the paper's 10 (its cost is linear in the repeats; C barely moves).
FULL_PLAN = Plan("full", cv_repeats=3)
#: The skin cells' feature groups compared on the NAO protocols (docs/decisions.md): the candidate
#: selections of :data:`MODES` in the pooled layout, 12 materials x 8 training / 4 test rounds, 6 objects.
SKIN_GROUPS_PLAN = Plan("skin_groups", materials=12, objects=6, train_repeat=8, test_repeat=4,
                        objects_train_repeat=5, objects_test_repeat=1, cv_repeats=2, pa_orders=2,
                        modes=("pooled", "pooled_per_channel", "pooled_bands", "pooled_levels", "pooled_statistics",
                               "pooled_combined", "pooled_paper_bands"),
                        protocols=("nao_right_to_left", "nao_large_objects"))
#: A small plan for smoke runs: a few materials, short tests, 2 CV repeats.
QUICK_PLAN = Plan("quick", materials=5, objects=4, train_repeat=6, test_repeat=2, combined_train_repeat=6,
                  objects_train_repeat=5, objects_test_repeat=1, test_duration_s=2.0, cv_repeats=2, pa_orders=2,
                  modes=("paper", "per_channel", "pooled"))


def run_protocol(key: str, plan: Plan, *, progress: bool = False,
                 cache: dict[tuple, DescriptorSet] | None = None,
                 fits: dict[tuple, Any] | None = None) -> dict[str, Any]:
    """Simulate and score one protocol; returns a JSON-able dict."""
    if key not in PROTOCOLS:
        raise ConfigError(f"unknown protocol {key!r}; choose from {sorted(PROTOCOLS)}", key="protocol")
    proto = PROTOCOLS[key]
    t_start = time.perf_counter()
    train_scene, o_tr, tests = proto.build(plan)
    cache = {} if cache is None else cache

    def described(scene: Scene, override: dict) -> DescriptorSet:
        ck = (scene.name, scene.seed, scene.robot.n_cells, repr(sorted(override.items())), plan.modes)
        if ck not in cache:
            cache[ck] = describe_scene(scene, plan.modes, chunk_s=plan.chunk_s, progress=progress,
                                       override=override)
        return cache[ck]

    train = described(train_scene, o_tr)
    out: dict[str, Any] = {"key": key, "title": proto.title, "robot": proto.robot,
                           "paper_section": proto.paper_section, "notes": proto.notes,
                           "paper": {k: {"value": v, "ref": ref} for k, (v, ref) in PAPER_NUMBERS.get(key, {}).items()},
                           "train": _set_summary(train), "tests": {}}
    n_pa = {"shadow_combined": plan.combined_train_repeat, "nao_large_objects": plan.objects_train_repeat}.get(
        key, plan.train_repeat)
    for name, scene, o_te in tests:
        test = described(scene, o_te)
        res = evaluate_sets(train, test, modes=plan.modes, cv_repeats=plan.cv_repeats, pa_orders=plan.pa_orders,
                            n_pa_max=n_pa, group_by=proto.group_by, fits=fits)
        res["set"] = _set_summary(test)
        out["tests"][name] = res
    out["runtime_s"] = time.perf_counter() - t_start
    return out


def _set_summary(s: DescriptorSet) -> dict[str, Any]:
    n_parts = [len(i["body_parts"]) for i in s.info]
    gated = [len(i["body_parts"]) - len([p for p in i["in_contact"] if p in i["body_parts"]]) for i in s.info]
    return {"scene": s.scene, "explorations": len(s), "classes": int(np.unique(s.labels).size),
            "simulate_s": s.simulate_s, "describe_s": s.describe_s,
            "describe_ms_per_window": 1e3 * s.describe_s / max(len(s), 1),
            "touching_parts_below_gate": int(sum(gated)), "touching_parts": int(sum(n_parts)),
            "override": s.override}


def run_protocols(plan: Plan = FULL_PLAN, *, progress: bool = False) -> dict[str, Any]:
    """Run every protocol of ``plan``; the training simulations are shared between protocols.

    A protocol the simulator cannot render (``SceneError``/``ConfigError``)
    is recorded with its ``error`` and listed in the report; the others
    still run.
    """
    t0 = time.perf_counter()
    cache: dict[tuple, DescriptorSet] = {}
    fits: dict[tuple, Any] = {}
    results: dict[str, Any] = {}
    keys = list(plan.protocols)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(keys), desc="protocols", unit="protocol")
    for k in keys:
        if bar is not None:
            bar.set_postfix_str(k)
        try:
            results[k] = run_protocol(k, plan, progress=progress, cache=cache, fits=fits)
        except (SceneError, ConfigError) as exc:  # reported in the results and the report, never dropped
            results[k] = {"key": k, "title": PROTOCOLS[k].title, "error": f"{type(exc).__name__}: {exc}"}
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    return {"simulated": True, "plan": plan.as_dict(), "protocols": results,
            "runtime_s": time.perf_counter() - t0}



# --------------------------------------------------------------------------- report

#: Training explorations per class at which the paper reads its online curve (Fig. 7, 9).
PAPER_PA_T: dict[str, int] = {"shadow_lateral": 15, "shadow_combined": 6, "nao_right_to_left": 20}

_MODE_TITLES = {"paper": "paper descriptor", "per_channel": "per-channel", "pooled": "pooled",
                "pooled_per_channel": "pooled per-channel"}


def _pct(x: float | None) -> str:
    return "--" if x is None else f"{100.0 * x:.1f} %"


def _pa_at(pa: Mapping[str, Any], t: int | None) -> tuple[float, int]:
    n = pa["n_per_class"]
    k = len(n) - 1 if t is None or t > n[-1] else n.index(t)
    return float(pa["curve"][k]), int(n[k])


def results_table(results: Mapping[str, Any]) -> list[dict[str, Any]]:
    """One row per (protocol, test, measure): the paper's number (``paper_number``) and ours per mode."""
    modes = list(results["plan"]["modes"])
    rows: list[dict[str, Any]] = []
    for key, p in results["protocols"].items():
        if "error" in p:
            rows.append({"protocol": key, "title": p["title"], "section": PROTOCOLS[key].paper_section, "test": "--",
                         "size": "--", "measure": "FAILED", "paper_number": "--", **{m: "--" for m in modes},
                         "notes": p["error"]})
            continue
        paper = p.get("paper", {})
        for k_test, (tname, t) in enumerate(p["tests"].items()):
            main = k_test == 0
            size = (f"{t['n_train']} / {t['n_test']} ({t['n_classes']} classes, chance {_pct(t['chance'])})")
            base = {"protocol": key, "title": p["title"], "section": p["paper_section"], "test": tname, "size": size}
            gate = p["train"]["touching_parts_below_gate"]
            notes = p["notes"] if main else ("our reference, not in the paper" if "held out" in tname else "")
            if main and gate:
                notes += (("; " if notes else "") + f"{gate} of {p['train']['touching_parts']} touching parts in "
                          "training below the 0.2 N contact gate (force grid starts at 0.2 N)")

            def cell(m: str, fn, t=t) -> str:
                r = t["modes"].get(m)
                try:
                    return fn(r) if r is not None else "--"
                except KeyError:
                    return "--"

            svm_paper = paper.get("svm") if main else None
            rows.append({**base, "measure": "SVM accuracy",
                         "paper_number": f"{_pct(svm_paper['value'])} ({svm_paper['ref']})" if svm_paper else "--",
                         **{m: cell(m, lambda r: _pct(r["svm"]["accuracy"])) for m in modes}, "notes": notes})
            t_pa = PAPER_PA_T.get(key) if main else None
            pa_paper = paper.get("pa") if main else None
            for variant, label in (("plain", "PA-I (eq. 30-32, eta 1)"), ("max_loss_avg", "PA-I max-loss + averaged")):
                def pa_cell(r, variant=variant, t_pa=t_pa):
                    v, n = _pa_at(r["pa"][variant], t_pa)
                    return f"{_pct(v)} at {n}/class"
                rows.append({**base, "measure": label,
                             "paper_number": (f"{_pct(pa_paper['value'])} ({pa_paper['ref']})" if pa_paper and variant == "plain"
                                       else "--"),
                             **{m: cell(m, pa_cell) for m in modes}, "notes": ""})
            nmi_paper = paper.get("nmi") if main else None
            rows.append({**base, "measure": "NMI, GMM-EM: fitted set / test set",
                         "paper_number": f"{nmi_paper['value']:.2f} ({nmi_paper['ref']})" if nmi_paper else "--",
                         **{m: cell(m, lambda r: f"{r['gmm']['nmi_train']:.2f} / {r['gmm']['nmi_test']:.2f}")
                            for m in modes}, "notes": ""})
    return rows


def _plot_curves(results: Mapping[str, Any], path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [(k, tn, t) for k, p in results["protocols"].items() for tn, t in p.get("tests", {}).items()
              if any("pa" in r for r in t["modes"].values())]
    if not panels:
        return
    cols = min(3, len(panels))
    rows_n = math.ceil(len(panels) / cols)
    fig, axes = plt.subplots(rows_n, cols, figsize=(5.0 * cols, 3.6 * rows_n), squeeze=False)
    styles = {("paper", "plain"): ("C0", "-"), ("paper", "max_loss_avg"): ("C0", "--"),
              ("per_channel", "plain"): ("C1", "-"), ("per_channel", "max_loss_avg"): ("C1", "--"),
              ("pooled", "plain"): ("C2", "-"), ("pooled", "max_loss_avg"): ("C2", "--")}
    for ax, (key, tname, t) in zip(axes.ravel(), panels):
        for m, r in t["modes"].items():
            for variant, pa in r.get("pa", {}).items():
                color, ls = styles.get((m, variant), ("C2", ":"))
                n = np.array(pa["n_per_class"])
                acc, sd = np.array(pa["curve"]), np.array(pa["curve_std"])
                ax.plot(n, acc, color=color, ls=ls, marker=".",
                        label=f"{_MODE_TITLES.get(m, m)}, {'PA-I' if variant == 'plain' else 'max-loss+avg'}")
                ax.fill_between(n, acc - sd, acc + sd, color=color, alpha=0.08)
        paper = results["protocols"][key].get("paper", {}).get("pa")
        if paper and tname == next(iter(results["protocols"][key]["tests"])):
            tp = PAPER_PA_T.get(key)
            ax.plot([tp], [paper["value"]], marker="*", color="k", ms=12, ls="none", label="paper (real robot)")
        ax.axhline(t["chance"], color="grey", lw=0.8, ls=":")
        ax.set_ylim(0, 1.02)
        ax.set_title(f"{key}: {tname}", fontsize=9)
        ax.set_xlabel("training explorations per class")
        ax.set_ylabel("test accuracy")
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[len(panels):]:
        ax.axis("off")
    axes.ravel()[0].legend(fontsize=7, loc="lower right")
    fig.suptitle("Online PA-I learning curves on SIMULATED robots (not real data)", fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plan_text(results: Mapping[str, Any]) -> list[str]:
    plan = results["plan"]
    lines = [
        f"* Plan `{plan['name']}` (the shipped scenes reproduce the paper's 120 materials x 20 training / "
        "100 test rounds; that is hours of simulation, so each scene's `explorations` are overridden):",
        f"  materials per material protocol: the first {plan['materials']} of the scene's list (the 20 fitted "
        f"materials, then parametric ones); large objects: {plan['objects']}; training rounds "
        f"{plan['train_repeat']} (combined motion {plan['combined_train_repeat']}, large objects "
        f"{plan['objects_train_repeat']}); test rounds {plan['test_repeat']} (large objects "
        f"{plan['objects_test_repeat']} per weight)"
        + (f"; test exploration time fixed to {plan['test_duration_s']} s" if plan["test_duration_s"] else "")
        + ".",
        f"* SVM: C by 5-fold CV repeated {plan['cv_repeats']} times over the paper's grid; PA-I curves averaged "
        f"over {plan['pa_orders']} presentation orders; GMM-EM fitted on the training set, NMI on that set and on the test set.",
    ]
    skipped = sorted({n for p in results["protocols"].values() if "error" not in p
                      for s in [p["train"]] + [t["set"] for t in p["tests"].values()]
                      for n in s["override"].get("skipped_unrenderable", [])})
    if skipped:
        lines.append(f"* Skipped {len(skipped)} parametric material(s) the simulator cannot render at the slowest "
                     f"speeds (unstable AR rescaling): {', '.join(f'`{n}`' for n in skipped)}.")
    return lines


def write_report(results: Mapping[str, Any], out_dir) -> dict[str, str]:
    """Write ``simulated.md``, ``simulated.json`` and ``figures/simulated_pa_curves.png`` under ``out_dir``."""
    import json
    from pathlib import Path

    out = Path(out_dir)
    (out / "figures").mkdir(parents=True, exist_ok=True)
    fig_path = out / "figures" / "simulated_pa_curves.png"
    _plot_curves(results, fig_path)
    modes = list(results["plan"]["modes"])
    rows = results_table(results)
    md: list[str] = [
        "# The paper's protocols on simulated robots",
        "",
        "> **Simulated, not real data.** Every number in the *simulated* columns comes from the package's "
        "scene simulator ([simulator.md](simulator.md)): texture models fitted to one BioTac data set plus "
        "parametric textures, rendered on a simulated Shadow Hand and NAO. The *paper* column is Kaboli et al. "
        "(T-RO 2018) on their robots and their 120 real materials. The two are not the same experiment; the "
        "table shows what the descriptors and learners do under the paper's protocols on our simulator, "
        "nothing more. Real-data results: [results.md](results.md).",
        "",
        f"Generated by `tactile protocols --out docs` in {results['runtime_s'] / 60:.1f} min "
        "(one core of a shared 2-core machine).",
        "",
        "## How",
        "",
        "* Each protocol simulates its training and test scenes from `config/scenes/` at the sample level, "
        "cuts every exploration at the paper's exploration time (sliding at the set force: 2 s or 3 s in "
        "training, 2-10 s or 3-10 s in the tests, the whole slide for large objects), tares the contact force "
        "on the pause after each touch (the paper recalibrates between explorations) and computes the "
        "descriptor with the core (`describe_window`).",
        "* Descriptors: **paper descriptor** = eq. 17 / 28 (channels of an axis averaged), body parts "
        "concatenated (eq. 18 / 29); **per-channel** = every channel kept, concatenated; **pooled** = "
        "averaged channels, mean over the body parts in contact (same layout whichever hand or fingers touch).",
        "* Parametric materials are rendered from one material seed in training and test (a material is "
        "its name: the engine no longer draws it from the scene's seed; `material_world` can pick another "
        "material seed). For the NAO material "
        "protocol only the two hands are simulated: the simulator keys every draw by cell, so their samples "
        "equal a full-robot run, and the other five parts (no contact) would add only gated zeros.",
        *_plan_text(results),
        "",
        "## Results",
        "",
        "| protocol | test | measure | paper (their robots, real data) | "
        + " | ".join(f"simulated: {_MODE_TITLES.get(m, m)}" for m in modes)
        + " | n train / test | notes |",
        "|" + "---|" * (6 + len(modes)),
    ]
    for r in rows:
        md.append(f"| {r['protocol']} ({r['section']}) | {r['test']} | {r['measure']} | {r['paper_number']} | "
                  + " | ".join(r[m] for m in modes) + f" | {r['size']} | {r['notes']} |")
    md += ["", "PA-I rows give the test accuracy after the number of training explorations per class at which "
           "the paper reads its curve (Fig. 7, 9), or after all of ours when we have fewer. NMI: the paper "
           "fits EM on its whole data set and scores the same data, which our *fitted set* value matches (the "
           "training explorations); the *test set* value scores the held-out explorations, few per cluster "
           "(NMI is biased upwards when there are few samples per cluster).", "",
           "## SVM accuracy by test condition", "",
           "| protocol | test | condition | n | " + " | ".join(_MODE_TITLES.get(m, m) for m in modes) + " |",
           "|" + "---|" * (4 + len(modes))]
    for key, p in results["protocols"].items():
        for tname, t in p.get("tests", {}).items():
            first = t["modes"][modes[0]]["svm"].get("by_group", {})
            for g, v in first.items():
                cells = [_pct(t["modes"][m]["svm"]["by_group"][g]["accuracy"]) for m in modes]
                md.append(f"| {key} | {tname} | {g} | {v['n']} | " + " | ".join(cells) + " |")
    md += ["", "## Online learning curves", "", f"![PA-I learning curves](figures/{fig_path.name})", "",
           "## Cost", "", "| protocol | scene | explorations | simulate s | descriptors s | ms / window (all modes) |",
           "|---|---|---|---|---|---|"]
    for key, p in results["protocols"].items():
        if "error" in p:
            continue
        for s in [p["train"]] + [t["set"] for t in p["tests"].values()]:
            md.append(f"| {key} | {s['scene']} | {s['explorations']} | {s['simulate_s']:.1f} | {s['describe_s']:.1f} "
                      f"| {s['describe_ms_per_window']:.1f} |")
    md += ["", "A scene shared by two protocols (the Shadow Hand lateral training set) is simulated once; its "
           "cost is listed under both.", "",
           "## Reading the table", "",
           "* The concatenated descriptor puts each body part in its own block. Trained on the right hand and "
           "tested on the left, the test vectors fill a block the model never saw; the paper's NAO result "
           "needs a hand-independent layout, which is what *pooled* is.",
           "* Large objects: the simulator makes the sliding speed proportional to the weight (1 / 2 / 3 cm/s), "
           "and a texture's vibration frequency scales with speed, so Mobility and Complexity move with the "
           "weight; the held-out 1000 g row separates the weight transfer from the descriptor's own power.",
           "* Training forces are drawn from {0.2, 0.6, ..., 3} N, so some touches sit right at the 0.2 N "
           "contact gate and are gated to zeros (counted in the notes).", ""]
    (out / "simulated.md").write_text("\n".join(md))
    (out / "simulated.json").write_text(json.dumps(results, indent=1, default=_json_default) + "\n")
    return {"markdown": str(out / "simulated.md"), "json": str(out / "simulated.json"), "figure": str(fig_path)}


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")
