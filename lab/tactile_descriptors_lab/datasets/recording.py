"""One BioTac trial in memory, whatever it was read from (CSV, NPZ, HDF5, a bag).

Every reader of :mod:`tactile_descriptors_lab.datasets` yields
:class:`BiotacRecording` objects; evaluation and import only ever see these.
The class of a recording is a name taken from the data (a folder, file,
group, label column, message or an option), never from a list inside the
package; ``material`` is the class's number inside one data source (the
number in the name when the name carries one, such as ``mat12``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from tactile_descriptors_ros.core.tare import TRIAL_REST_PERCENTILE, RestingLevel, resting_level
from tactile_descriptors_ros.errors import DataFormatError, SignalError

__all__ = ["BiotacRecording", "CellRecording", "N_ELECTRODES", "spread_pac_stamps", "UNTARED_REST_COUNTS",
           "trial_rest", "tare_recording"]

#: Impedance electrodes of a BioTac.
N_ELECTRODES = 19

#: A trial whose resting PDC (:func:`trial_rest`) lies above this many counts has not been tared: a tared
#: BioTac rests near 0 (the shared sliding recordings rest at 0 to 50 counts), an untared one at its
#: absolute pressure (about 1,000 to 3,000 counts).
UNTARED_REST_COUNTS = 300


class _Trial:
    """What a recording of one trial of any cell type does with its names and frame stamps.

    A mixin of the frozen dataclasses below: fills ``class_name`` and
    ``source_file`` when the reader left them empty, counts the frames and
    estimates their rate.
    """

    #: Frame rate given for a trial of fewer than two frames (no rate can be estimated).
    ONE_FRAME_RATE_HZ = 0.0

    def __post_init__(self) -> None:
        if not self.class_name:
            object.__setattr__(self, "class_name", f"mat{self.material}")
        if not self.source_file:
            object.__setattr__(self, "source_file", self.path.split("#", 1)[0])

    @property
    def n_frames(self) -> int:
        return int(self.frame_t_ns.shape[0])

    @property
    def frame_rate_hz(self) -> float:
        """Frame rate estimated from the time stamps (a frame is one V sample)."""
        if self.n_frames < 2:
            return self.ONE_FRAME_RATE_HZ
        return float(1e9 * (self.n_frames - 1) / (self.frame_t_ns[-1] - self.frame_t_ns[0]))

    @property
    def material_name(self) -> str:
        """The class name (kept for callers written before classes were named by the data)."""
        return self.class_name


@dataclass(frozen=True)
class BiotacRecording(_Trial):
    """One trial: a BioTac touching one class of object.

    Attributes
    ----------
    material : int
        Class number inside the data source (see :attr:`class_name`).
    trial : int
        Trial number (from the data: a name, a group, a column or the order of files).
    frame_t_ns : numpy.ndarray of int64, shape (n_frames,)
        Frame time stamps in ns.
    pac : numpy.ndarray of int64, shape (n_frames * pac_per_frame,)
        PAC counts in time order.
    pac_t_ns : numpy.ndarray of int64, shape (n_frames * pac_per_frame,)
        PAC sample times, strictly increasing.
    pdc, tac, tdc : numpy.ndarray of int64, shape (n_frames,)
    electrodes : numpy.ndarray of int64, shape (19, n_frames)
    path : str
        Where the trial came from: a file, or ``file#group`` / ``bag#topic`` inside a container.
    class_name : str
        The class as the data name it; ``mat<material>`` when the data give only a number.
    pac_per_frame : int
        PAC samples per frame (22 on a BioTac sampled at 2.2 kHz with 100 Hz frames).
    source_file : str
        The file on disk holding the trial (for caches keyed by size and modification time).
    tare_counts : tuple of float
        PDC tare subtracted on reading (empty when the data were already tared).
    absent : tuple of str
        Channels the source does not hold (their arrays are zeros): the
        electrodes ``e1`` .. ``e19`` of an old driver's messages without them.
    """

    material: int
    trial: int
    frame_t_ns: np.ndarray
    pac: np.ndarray
    pac_t_ns: np.ndarray
    pdc: np.ndarray
    tac: np.ndarray
    tdc: np.ndarray
    electrodes: np.ndarray
    path: str
    class_name: str = ""
    pac_per_frame: int = 22
    source_file: str = ""
    tare_counts: tuple[float, ...] = ()
    absent: tuple[str, ...] = ()

    #: Frame rate assumed for a trial of fewer than two frames (a BioTac's 100 Hz).
    ONE_FRAME_RATE_HZ = 100.0

    def crop_frames(self, start: int, stop: int) -> BiotacRecording:
        """Frames ``start:stop`` (and their PAC samples) as a new recording."""
        s, e = max(0, start), min(self.n_frames, stop)
        k = self.pac_per_frame
        return replace(self, frame_t_ns=self.frame_t_ns[s:e], pac=self.pac[s * k:e * k],
                       pac_t_ns=self.pac_t_ns[s * k:e * k], pdc=self.pdc[s:e], tac=self.tac[s:e],
                       tdc=self.tdc[s:e], electrodes=self.electrodes[:, s:e])

    def force_n(self, n_per_count: float) -> np.ndarray:
        """Normal force of every frame, PDC x ``n_per_count`` (the contact gate's input, eq. 13)."""
        return self.pdc.astype(np.float64) * float(n_per_count)


@dataclass(frozen=True)
class CellRecording(_Trial):
    """One trial of one cell of any cell type a robot description declares (a skin cell, ...).

    The channels are the cell type's (:class:`~..core.cell_types.CellType`): the
    vibration channels S (``samples_per_frame`` samples a frame), the
    deformation channels V and the extra channels (one value a frame).  A
    frame is one V sample.

    Attributes
    ----------
    material, trial : int
        As :class:`BiotacRecording`'s.
    frame_t_ns : numpy.ndarray of int64, shape (n_frames,)
        V sample (frame) time stamps in ns.
    vibration : numpy.ndarray of int64, shape (n_s, n_frames * samples_per_frame)
        S counts in time order, one row a vibration channel.
    vibration_t_ns : numpy.ndarray of int64, shape (n_frames * samples_per_frame,)
    deformation : numpy.ndarray of int64, shape (n_v, n_frames)
        V counts, as recorded (a tare is kept apart, in ``deformation_tare``).
    extra : numpy.ndarray of float64, shape (n_extra, n_frames)
        The extra channels (proximity counts, temperature in degC, ...); NaN
        for a channel listed in ``absent``.
    force_counts : numpy.ndarray of float64, shape (n_frames,)
        Mean of the force channels minus their tare, in counts (the contact gate's input).
    deformation_tare : numpy.ndarray of float64, shape (n_v,)
        Tare of each deformation channel (zeros when untared); subtracted by
        the ``levels`` group only, as a driver's reported tare.
    path : str
    robot : str
        The robot description declaring the cell type (a shipped name or a file).
    cell_type : str
    class_name : str
    samples_per_frame : int
    source_file : str
    tare_counts : tuple of float
        The force channels' tare (empty when untared).
    absent : tuple of str
        Channels the source does not hold.
    """

    material: int
    trial: int
    frame_t_ns: np.ndarray
    vibration: np.ndarray
    vibration_t_ns: np.ndarray
    deformation: np.ndarray
    extra: np.ndarray
    force_counts: np.ndarray
    deformation_tare: np.ndarray
    path: str
    robot: str
    cell_type: str
    class_name: str = ""
    samples_per_frame: int = 1
    source_file: str = ""
    tare_counts: tuple[float, ...] = ()
    absent: tuple[str, ...] = ()

    def crop_frames(self, start: int, stop: int) -> CellRecording:
        """Frames ``start:stop`` (and their S samples) as a new recording."""
        s, e = max(0, start), min(self.n_frames, stop)
        k = self.samples_per_frame
        return replace(self, frame_t_ns=self.frame_t_ns[s:e], vibration=self.vibration[:, s * k:e * k],
                       vibration_t_ns=self.vibration_t_ns[s * k:e * k], deformation=self.deformation[:, s:e],
                       extra=self.extra[:, s:e], force_counts=self.force_counts[s:e])

    def force_n(self, n_per_count: float) -> np.ndarray:
        """Normal force of every frame (tared force counts x ``n_per_count``; eq. 27)."""
        return self.force_counts * float(n_per_count)


def spread_pac_stamps(frame_t_ns: np.ndarray, pac_per_frame: int, where: str) -> np.ndarray:
    """PAC sample times spread evenly over each frame's interval.

    Each frame's samples cover the interval up to the next frame's stamp (the
    median period for the last frame), so PAC stamps stay increasing when
    frame stamps jitter.

    Raises
    ------
    DataFormatError
        When the frame stamps do not increase.
    """
    frame_t_ns = np.asarray(frame_t_ns, dtype=np.int64)
    if frame_t_ns.shape[0] > 1 and np.any(np.diff(frame_t_ns) <= 0):
        i = int(np.flatnonzero(np.diff(frame_t_ns) <= 0)[0])
        raise DataFormatError(
            f"{where}: frame time stamps do not increase (frame {i + 1} at {int(frame_t_ns[i + 1])} ns after "
            f"{int(frame_t_ns[i])} ns); stamps of coarse resolution need a frame rate (stamps: rate_hz)")
    period_ns = np.int64(10_000_000) if frame_t_ns.shape[0] < 2 else np.int64(np.median(np.diff(frame_t_ns)))
    intervals = np.append(np.diff(frame_t_ns), period_ns)
    steps = np.arange(pac_per_frame, dtype=np.int64)
    return (frame_t_ns[:, None] + (intervals[:, None] * steps[None, :]) // pac_per_frame).ravel()


def trial_rest(rec: BiotacRecording) -> RestingLevel:
    """Resting level of a trial's PDC and electrodes (:func:`~tactile_descriptors_ros.core.tare.resting_level`).

    The trial touches most of the time: its resting frames are those whose
    PDC lies at or below the :data:`~tactile_descriptors_ros.core.tare.TRIAL_REST_PERCENTILE`
    th percentile, each channel's level its median over them [counts].

    Raises
    ------
    DataFormatError
        For a trial too short to rest on (fewer than three resting frames).
    """
    try:
        return resting_level(rec.pdc, rec.electrodes, rest_percentile=TRIAL_REST_PERCENTILE)
    except SignalError as e:
        raise DataFormatError(f"{rec.path}: no resting level: {e}") from None


def tare_recording(rec: BiotacRecording, rest: RestingLevel | None = None) -> BiotacRecording:
    """Tare one trial as a tared BioTac set-up would: subtract resting levels, clip at 0.

    PDC and each electrode lose their resting level (:func:`trial_rest`, or
    ``rest`` when already taken), rounded to the nearest count so the counts
    stay integers like the sensor's; PAC, TAC and TDC are left as they are
    (the descriptors use their variations).  Values are clipped at 0, as in
    the tared recordings this package was developed on.  ``tare_counts``
    holds the PDC counts subtracted.
    """
    rest = trial_rest(rec) if rest is None else rest
    tare = int(np.round(rest.reference[0]))
    e_tare = np.round(rest.channels).astype(np.int64)
    return replace(rec, pdc=np.clip(rec.pdc - tare, 0, None),
                   electrodes=np.clip(rec.electrodes - e_tare[:, None], 0, None),
                   tare_counts=(float(tare),))
