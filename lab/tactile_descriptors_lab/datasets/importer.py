"""Turn BioTac recordings (tables or other drivers' bags) into a bag the live graph can replay.

Any source :func:`~tactile_descriptors_lab.datasets.readers.read_source`
reads (CSV, NPZ or HDF5 tables described by a mapping file; Shadow Robot
``sr_robot_msgs/BiotacAll`` or UPenn ``biotac_sensors/BioTacHand`` bags, ROS
1 or ROS 2) gives trials; each trial becomes a run of ``BioTacFrameBatch``
messages, as the BioTac driver would publish them:

* ``frames_per_batch`` frames a message (10 = 100 ms), PAC at full rate
  (22 samples a frame) with per-sample offsets, slow channels one sample a
  frame; ``header.stamp`` is the first PAC sample's time (the CSV stamp of
  the batch's first frame), the log time is the end of the batch (when a
  driver would have it complete);
* trials follow each other: trial k keeps its CSV time stamps relative to
  its own start and starts ``release_s`` after trial k-1 ended, so every
  trial is one exploration (contact onset to release).  The gap is filled
  with *release frames* (PDC, PAC, TAC and electrodes 0, TDC held: the
  recordings are tared and clipped at 0, so 0 is "no contact") so that a
  windowing node sees the force drop and closes the exploration, exactly as
  it would on the robot; ``release_fill=False`` leaves a silent gap instead;
* a ``Label`` (``class_name`` = material name, ``exploration_id`` 0 = the
  most recent exploration) is logged ``label_delay_s`` after each trial
  ends, inside the gap, after the window node's release time has passed;
* scales come from the robot description (``config/shadow_hand.yaml``):
  ``pac_pa_per_count`` = the vibration modality's ``si_per_count``,
  ``force_n_per_count`` = the force spec's ``n_per_count``;
  ``pdc_pa_per_count`` is the BioTac manual's 36.5 Pa/count (the robot
  description has no PDC pressure scale).  Counts are written tared
  (``pdc_tare_counts`` 0, no electrode tares): a source whose resting PDC is
  far from zero is tared per trial on reading, and the report says so.

The bag is written under a temporary name and renamed when complete, so a
failed import leaves nothing behind and can simply be run again.  Its
metadata (``custom_data``, key ``tactile.trials``) lists each trial's class,
number and frames, so ``tactile evaluate`` reads the trials back exactly.

The contact gate of the descriptor (paper eq. 13, mean force over a window
at least F_t) reads force = PDC x ``force_n_per_count``: :class:`ImportReport`
says how many frames and trials pass it, so that a recording which would be
gated out is seen before it is replayed.
"""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tactile_descriptors_lab.datasets.bagfiles import TRIALS_KEY
from tactile_descriptors_lab.datasets.readers import LoadReport, read_source, resolve_mapping
from tactile_descriptors_lab.datasets.recording import N_ELECTRODES, BiotacRecording
from tactile_descriptors_ros.bags.io import BagWriter
from tactile_descriptors_ros.bags.qos import make_qos
from tactile_descriptors_ros.bags.types import tactile_typestore
from tactile_descriptors_ros.core.robot import RobotDescription, load_robot
from tactile_descriptors_ros.errors import BagError, ConfigError, DataFormatError
from tactile_descriptors_ros.topics import FRAMES_TOPIC, LABEL_TOPIC, absolute

__all__ = [
    "DEFAULT_BIOTAC_TOPIC",
    "DEFAULT_LABEL_TOPIC",
    "BIOTAC_PDC_PA_PER_COUNT",
    "BIOTAC_QOS",
    "LABEL_QOS",
    "ImportOptions",
    "TrialStats",
    "ImportReport",
    "import_biotac_slide",
    "import_source",
    "import_recordings",
    "parse_index_ranges",
]

#: Default topic of BioTac frame batches, as the window node subscribes (``{body_part}`` is filled in).
DEFAULT_BIOTAC_TOPIC = absolute(FRAMES_TOPIC)
#: Default topic of true labels.
DEFAULT_LABEL_TOPIC = absolute(LABEL_TOPIC)
#: BioTac static-pressure resolution from the SynTouch product manual (0..100 kPa over 12 bit).
BIOTAC_PDC_PA_PER_COUNT = 36.5
#: Offered QoS of the imported frames: reliable (matches reliable and best-effort subscribers).
BIOTAC_QOS = make_qos("reliable", "volatile", 50)
#: Offered QoS of the imported labels.
LABEL_QOS = make_qos("reliable", "volatile", 10)

_MAX_COUNT = 4095
_BATCH = "tactile_descriptors_msgs/msg/BioTacFrameBatch"
_LABEL = "tactile_descriptors_msgs/msg/Label"


@dataclass(frozen=True)
class ImportOptions:
    """How recordings become messages (see the module docstring).

    Attributes
    ----------
    robot : str
        Robot description name or path; gives scales, sensor name and thresholds.
    body_part : str
        Body part the BioTac is mounted on (``"index"``).
    frames_per_batch : int
        Frames per ``BioTacFrameBatch`` (10 = 100 ms at 100 Hz).
    release_s : float
        Gap between trials, in seconds.
    release_fill : bool
        Fill the gap with no-contact frames (else publish nothing in it).
    label_delay_s : float
        Label time after a trial's end; must lie inside the gap.
    order : {"trial", "material"}
        ``"trial"``: trial 1 of every material, then trial 2, ... (interleaved, the
        natural order for online learning); ``"material"``: all trials of one
        material, then the next.
    max_frames : int or None
        Crop every trial to its first ``max_frames`` frames (the data set's
        README asks for a common length so duration cannot give the class away).
    biotac_topic, label_topic : str
        ``{body_part}`` in ``biotac_topic`` is replaced by the body part.
    frame_id : str or None
        ``header.frame_id``; the sensor name when None.
    """

    robot: str = "shadow_hand"
    body_part: str = "index"
    frames_per_batch: int = 10
    release_s: float = 1.0
    release_fill: bool = True
    label_delay_s: float = 0.5
    order: str = "trial"
    max_frames: int | None = None
    biotac_topic: str = DEFAULT_BIOTAC_TOPIC
    label_topic: str = DEFAULT_LABEL_TOPIC
    frame_id: str | None = None

    def validate(self) -> None:
        if self.frames_per_batch < 1:
            raise ConfigError("frames_per_batch must be at least 1", key="frames_per_batch")
        if not self.release_s > 0:
            raise ConfigError("release_s must be positive", key="release_s")
        if not 0 <= self.label_delay_s < self.release_s:
            raise ConfigError(
                f"label_delay_s ({self.label_delay_s}) must lie inside the gap [0, release_s={self.release_s})",
                key="label_delay_s",
            )
        if self.order not in ("trial", "material"):
            raise ConfigError(f"order must be 'trial' or 'material', not {self.order!r}", key="order")
        if self.max_frames is not None and self.max_frames < 1:
            raise ConfigError("max_frames must be at least 1", key="max_frames")


@dataclass(frozen=True)
class TrialStats:
    """Contact-gate check of one imported trial."""

    material: int
    material_name: str
    trial: int
    frames: int
    frames_in_contact: int
    mean_force_n: float
    min_force_n: float
    max_force_n: float
    start_ns: int
    end_ns: int

    @property
    def contact_fraction(self) -> float:
        return self.frames_in_contact / self.frames if self.frames else 0.0


@dataclass
class ImportReport:
    """What :func:`import_biotac_slide` wrote and how the data meet the contact gate."""

    bag: str
    storage: str
    force_threshold_n: float
    force_n_per_count: float
    batches: int = 0
    labels: int = 0
    release_frames: int = 0
    trials: list[TrialStats] = field(default_factory=list)
    source: str = ""
    mapping: str = ""
    tare_notes: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def frames(self) -> int:
        return sum(t.frames for t in self.trials)

    @property
    def frames_in_contact(self) -> int:
        return sum(t.frames_in_contact for t in self.trials)

    @property
    def contact_fraction(self) -> float:
        """Fraction of recorded frames whose force is at least F_t."""
        return self.frames_in_contact / self.frames if self.frames else 0.0

    @property
    def trials_passing_gate(self) -> int:
        """Trials whose mean force over the whole trial is at least F_t (eq. 13 on one exploration)."""
        return sum(t.mean_force_n >= self.force_threshold_n for t in self.trials)

    def to_dict(self) -> dict[str, Any]:
        return {
            "bag": self.bag,
            "storage": self.storage,
            "source": self.source,
            "mapping": self.mapping,
            "tare": self.tare_notes,
            "notes": self.notes,
            "trials": len(self.trials),
            "batches": self.batches,
            "labels": self.labels,
            "frames": self.frames,
            "release_frames": self.release_frames,
            "force_threshold_n": self.force_threshold_n,
            "force_n_per_count": self.force_n_per_count,
            "frames_in_contact": self.frames_in_contact,
            "contact_fraction": self.contact_fraction,
            "trials_passing_gate": self.trials_passing_gate,
            "per_trial": [
                {
                    "material": t.material,
                    "material_name": t.material_name,
                    "trial": t.trial,
                    "frames": t.frames,
                    "contact_fraction": t.contact_fraction,
                    "mean_force_n": t.mean_force_n,
                    "min_force_n": t.min_force_n,
                    "max_force_n": t.max_force_n,
                    "start_ns": t.start_ns,
                    "end_ns": t.end_ns,
                }
                for t in self.trials
            ],
        }


def parse_index_ranges(text: str) -> list[int]:
    """``"1-5,8,10-12"`` -> ``[1, 2, 3, 4, 5, 8, 10, 11, 12]``.

    Raises
    ------
    ConfigError
        For anything but positive integers and ascending ranges.
    """
    out: list[int] = []
    for part in text.split(","):
        part = part.strip()
        if not part:
            continue
        lo, sep, hi = part.partition("-")
        try:
            a = int(lo)
            b = int(hi) if sep else a
        except ValueError:
            raise ConfigError(f"not a number or range: {part!r} (use e.g. 1-30 or 1,3,5)") from None
        if a < 1 or b < a:
            raise ConfigError(f"bad range {part!r}: numbers start at 1 and ranges ascend")
        out.extend(range(a, b + 1))
    if not out:
        raise ConfigError(f"empty selection {text!r}")
    return sorted(set(out))


def _ns_time(t_ns: int) -> dict[str, int]:
    return {"sec": int(t_ns // 1_000_000_000), "nanosec": int(t_ns % 1_000_000_000)}


def _check_counts(rec: BiotacRecording) -> None:
    for name, arr in (("pac", rec.pac), ("pdc", rec.pdc), ("tac", rec.tac), ("tdc", rec.tdc),
                      ("electrodes", rec.electrodes)):
        if arr.size and (int(arr.min()) < 0 or int(arr.max()) > _MAX_COUNT):
            raise DataFormatError(
                f"{rec.path}: {name} counts outside the 12-bit range 0..{_MAX_COUNT} "
                f"(min {int(arr.min())}, max {int(arr.max())})"
            )
    if rec.n_frames > 1 and np.any(np.diff(rec.frame_t_ns) <= 0):
        raise DataFormatError(f"{rec.path}: frame time stamps do not increase")


class _BatchFactory:
    """Builds rosbags ``BioTacFrameBatch`` / ``Label`` objects with fixed metadata."""

    def __init__(self, store: Any, sensor_name: str, body_part: str, frame_id: str,
                 pac_scale: float, pdc_scale: float, force_scale: float) -> None:
        self.store = store
        self.batch_cls = store.types[_BATCH]
        self.label_cls = store.types[_LABEL]
        self.header_cls = store.types["std_msgs/msg/Header"]
        self.time_cls = store.types["builtin_interfaces/msg/Time"]
        self.sensor_name = sensor_name
        self.body_part = body_part
        self.frame_id = frame_id
        self.pac_scale = pac_scale
        self.pdc_scale = pdc_scale
        self.force_scale = force_scale

    def header(self, stamp_ns: int) -> Any:
        return self.header_cls(stamp=self.time_cls(**_ns_time(stamp_ns)), frame_id=self.frame_id)

    def batch(self, seq: int, frame_t_ns: np.ndarray, pac_t_ns: np.ndarray, pac: np.ndarray,
              pdc: np.ndarray, tac: np.ndarray, tdc: np.ndarray, electrodes_fm: np.ndarray) -> Any:
        stamp = int(pac_t_ns[0])
        return self.batch_cls(
            header=self.header(stamp),
            sensor_name=self.sensor_name,
            body_part=self.body_part,
            serial_number="",
            chip_select=0,
            first_frame_sequence=seq & 0xFFFFFFFF,
            frame_count=int(frame_t_ns.shape[0]),
            electrode_count=N_ELECTRODES,
            pac=pac.astype(np.uint16),
            pac_offset_ns=(pac_t_ns - stamp).astype(np.int64),
            frame_offset_ns=(frame_t_ns - stamp).astype(np.int64),
            pdc=pdc.astype(np.uint16),
            tac=tac.astype(np.uint16),
            tdc=tdc.astype(np.uint16),
            electrodes=electrodes_fm.astype(np.uint16).ravel(),
            pac_pa_per_count=float(self.pac_scale),
            pdc_pa_per_count=float(self.pdc_scale),
            force_n_per_count=float(self.force_scale),
            pdc_tare_counts=0.0,
            electrode_tare_counts=np.zeros(0, dtype=np.float64),
            bad_words=0,
        )

    def label(self, stamp_ns: int, class_name: str) -> Any:
        return self.label_cls(header=self.header(stamp_ns), exploration_id=0, class_name=class_name)


def _biotac_part(opts: ImportOptions) -> tuple[RobotDescription, Any, Any]:
    """The robot, body part and cell type the options name; the part must carry a BioTac."""
    robot: RobotDescription = load_robot(opts.robot)
    part = robot.body_part(opts.body_part)
    cell_type = robot.cell_types[part.cell_type]
    if cell_type.force.channels != ("pdc",):
        raise ConfigError(
            f"body part {part.name!r} is a {part.cell_type!r} cell, not a BioTac (force from PDC)",
            key="body_part", source=robot.source,
        )
    if not part.cells:
        raise ConfigError(f"body part {part.name!r} has no cells", key="body_part", source=robot.source)
    return robot, part, cell_type


def _ordered(recordings: list[BiotacRecording], order: str) -> list[BiotacRecording]:
    if order == "material":
        return sorted(recordings, key=lambda r: (r.material, r.trial))
    return sorted(recordings, key=lambda r: (r.trial, r.material))


def import_biotac_slide(
    data_dir: str | os.PathLike[str],
    bag_path: str | os.PathLike[str],
    trials: Sequence[int] | None = None,
    materials: Sequence[int] | None = None,
    options: ImportOptions | None = None,
    storage: str = "mcap",
    progress: Callable[[Iterable[BiotacRecording]], Iterable[BiotacRecording]] | None = None,
) -> ImportReport:
    """Import the BioTac sliding recordings (the shipped ``biotac_slide_20_50`` mapping); see :func:`import_source`."""
    return import_source(data_dir, bag_path, mapping=None, trials=trials,
                         classes=None if materials is None else [str(int(m)) for m in materials],
                         options=options, storage=storage, progress=progress)


def import_source(
    source: str | os.PathLike[str],
    bag_path: str | os.PathLike[str],
    mapping: str | os.PathLike[str] | None = None,
    trials: Sequence[int] | None = None,
    classes: Sequence[str] | None = None,
    class_name: str | None = None,
    tare: str | None = None,
    options: ImportOptions | None = None,
    storage: str = "mcap",
    progress: Callable[[Iterable[BiotacRecording]], Iterable[BiotacRecording]] | None = None,
) -> ImportReport:
    """Read ``source`` (see :func:`~..datasets.sources.read_source`) and write its trials as a bag.

    Parameters
    ----------
    source : path
        Folder or file of tables, or bags.
    bag_path : path
        Bag directory to create (never overwritten).
    mapping : str or path, optional
        Shipped mapping name or mapping file (default: the bag default for
        bags, else ``biotac_slide_20_50``).
    trials : sequence of int, optional
    classes : sequence of str, optional
        By name or number; asking for what the data do not hold is an error.
    class_name : str, optional
        Class of every trial (overrides the mapping).
    tare : {"auto", "per_trial", "none"}, optional
    options, storage, progress
        See :func:`import_recordings`.

    Raises
    ------
    DataFormatError, ConfigError, BagError
        Before anything is written for bad input; a failure while writing
        removes the partial bag.
    """
    opts = options or ImportOptions()
    opts.validate()
    if Path(bag_path).exists():
        raise BagError(f"{bag_path} exists already; bags are never overwritten")
    _biotac_part(opts)  # bad options fail before any data is read
    cell_mapping = resolve_mapping(Path(source), mapping)
    if cell_mapping.cell is not None:
        raise ConfigError(f"{cell_mapping.source}: tactile import writes BioTac frames; recordings of cell type "
                          f"{cell_mapping.cell_type!r} are evaluated straight from their tables (tactile evaluate "
                          "--train SOURCE --test SOURCE --mapping MAPPING)", key="cell_type")
    load = LoadReport(source=str(source), mapping="")
    recs = read_source(source, mapping, trials=trials, classes=classes, class_name=class_name, tare=tare,
                       report=load)
    report = import_recordings(recs, bag_path, options=opts, storage=storage, progress=progress)
    report.source = str(source)
    report.mapping = load.mapping
    report.tare_notes = load.tare_lines()
    report.notes = load.note_lines()
    return report


def import_recordings(
    recordings: Sequence[BiotacRecording],
    bag_path: str | os.PathLike[str],
    options: ImportOptions | None = None,
    storage: str = "mcap",
    progress: Callable[[Iterable[BiotacRecording]], Iterable[BiotacRecording]] | None = None,
) -> ImportReport:
    """Write recordings as a bag of ``BioTacFrameBatch`` and ``Label`` messages.

    The bag is written to a temporary folder beside ``bag_path`` and renamed
    when complete; on any error the temporary folder is removed, so nothing
    is left behind.

    Parameters
    ----------
    recordings : sequence of BiotacRecording
    bag_path : path
        Bag directory to create.
    options : ImportOptions, optional
    storage : {"mcap", "sqlite3"}
    progress : callable, optional
        Wraps the list of recordings (e.g. ``tqdm``).

    Returns
    -------
    ImportReport

    Raises
    ------
    DataFormatError
        For counts outside 12 bits or stamps that do not increase.
    ConfigError
        For bad options or an unknown body part.
    """
    opts = options or ImportOptions()
    opts.validate()
    final = Path(bag_path)
    if final.exists():
        raise BagError(f"{final} exists already; bags are never overwritten")
    if not recordings:
        raise ConfigError("no recordings to import")
    biotac_topic = opts.biotac_topic.format(body_part=opts.body_part)
    robot, part, cell_type = _biotac_part(opts)
    sensor_name = part.cells[0].name
    force_scale = float(cell_type.force.n_per_count)
    threshold_n = float(robot.contact.force_threshold_n)

    recs = [r.crop_frames(0, opts.max_frames) if opts.max_frames is not None else r for r in recordings]
    for rec in recs:
        _check_counts(rec)
    recs = _ordered(recs, opts.order)
    store = tactile_typestore()
    factory = _BatchFactory(store, sensor_name, part.name, opts.frame_id or sensor_name,
                            float(cell_type.vibration.si_per_count), BIOTAC_PDC_PA_PER_COUNT, force_scale)
    report = ImportReport(bag=str(final), storage=storage, force_threshold_n=threshold_n,
                          force_n_per_count=force_scale)
    custom = {
        "tactile.source": "tactile import",
        "tactile.robot": robot.name,
        "tactile.body_part": part.name,
        "tactile.release_s": repr(opts.release_s),
        "tactile.frames_per_batch": str(opts.frames_per_batch),
    }
    final.parent.mkdir(parents=True, exist_ok=True)
    staging = final.parent / f".{final.name}.partial-{os.getpid()}"
    if staging.exists():
        shutil.rmtree(staging)
    staging.mkdir()
    try:
        _write(recs, staging / final.name, storage, store, custom, factory, opts, biotac_topic, report,
               threshold_n, force_scale, progress)
        os.replace(staging / final.name, final)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    shutil.rmtree(staging, ignore_errors=True)
    return report


def _write(recs: list[BiotacRecording], path: Path, storage: str, store: Any, custom: dict[str, str],
           factory: _BatchFactory, opts: ImportOptions, biotac_topic: str, report: ImportReport,
           threshold_n: float, force_scale: float, progress: Callable | None) -> None:
    release_ns = int(round(opts.release_s * 1e9))
    label_delay_ns = int(round(opts.label_delay_s * 1e9))
    seq = 0
    next_start_ns: int | None = None
    listed: list[dict[str, Any]] = []
    with BagWriter(path, storage=storage, typestore=store, custom_data=custom) as bag:
        bag.add_topic(biotac_topic, _BATCH, [BIOTAC_QOS])
        bag.add_topic(opts.label_topic, _LABEL, [LABEL_QOS])
        for rec in (progress(recs) if progress else recs):
            k = rec.pac_per_frame
            period_ns = int(np.median(np.diff(rec.frame_t_ns))) if rec.n_frames > 1 else 10_000_000
            shift = 0 if next_start_ns is None else next_start_ns - int(rec.frame_t_ns[0])
            frame_t = rec.frame_t_ns + shift
            pac_t = rec.pac_t_ns + shift
            electrodes_fm = rec.electrodes.T  # (n_frames, 19), frame-major
            n = rec.n_frames
            fpb = opts.frames_per_batch
            listed.append({"class_name": rec.class_name, "material": rec.material, "trial": rec.trial,
                           "first_frame": seq, "frames": n, "source": rec.path})
            for s in range(0, n, fpb):
                e = min(n, s + fpb)
                msg = factory.batch(seq, frame_t[s:e], pac_t[s * k:e * k], rec.pac[s * k:e * k], rec.pdc[s:e],
                                    rec.tac[s:e], rec.tdc[s:e], electrodes_fm[s:e])
                bag.write(biotac_topic, int(frame_t[e - 1]) + period_ns, msg)
                seq += e - s
                report.batches += 1
            # The trial ends after its last sample: a frame's PAC samples can run past the median frame
            # period, and release frames stamped before them would reach a window node out of order.
            end_ns = max(int(frame_t[-1]) + period_ns, int(pac_t[-1]) + 1)
            force = rec.force_n(force_scale)
            report.trials.append(TrialStats(
                material=rec.material, material_name=rec.class_name, trial=rec.trial, frames=n,
                frames_in_contact=int(np.count_nonzero(force >= threshold_n)), mean_force_n=float(force.mean()),
                min_force_n=float(force.min()), max_force_n=float(force.max()), start_ns=int(frame_t[0]),
                end_ns=end_ns,
            ))
            # Release: no-contact frames through the gap, the label inside it.
            label_ns = end_ns + label_delay_ns
            label_written = False
            next_start_ns = end_ns + release_ns
            if opts.release_fill:
                n_release = max(1, release_ns // period_ns)
                next_start_ns = end_ns + n_release * period_ns  # the stream stays gap-free
                offsets = np.arange(k, dtype=np.int64) * period_ns // k
                last_tdc = int(rec.tdc[-1])
                for s in range(0, n_release, fpb):
                    e = min(n_release, s + fpb)
                    rf_t = end_ns + np.arange(s, e, dtype=np.int64) * period_ns
                    rp_t = (rf_t[:, None] + offsets[None, :]).ravel()
                    m = e - s
                    zeros = np.zeros(m, dtype=np.int64)
                    msg = factory.batch(seq, rf_t, rp_t, np.zeros(m * k, dtype=np.int64), zeros, zeros,
                                        np.full(m, last_tdc, dtype=np.int64), np.zeros((m, N_ELECTRODES), np.int64))
                    log_ns = int(rf_t[-1]) + period_ns
                    if not label_written and log_ns > label_ns:
                        bag.write(opts.label_topic, label_ns, factory.label(label_ns, rec.class_name))
                        label_written = True
                        report.labels += 1
                    bag.write(biotac_topic, log_ns, msg)
                    seq += m
                    report.batches += 1
                    report.release_frames += m
            if not label_written:
                bag.write(opts.label_topic, label_ns, factory.label(label_ns, rec.class_name))
                report.labels += 1
        bag.set_custom_data(TRIALS_KEY, json.dumps(listed))
