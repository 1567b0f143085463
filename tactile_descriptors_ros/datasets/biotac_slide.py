"""Reader for the public BioTac sliding recordings (``BioTac_slide_20_50`` layout).

Layout: ``raw_data/mat<M>/mat<M>_<N>_bio.csv``, M the material (class), N the
trial.  Each row is one 10 ms BioTac frame: ``timestamp`` (Unix seconds),
``tdc``, ``tac``, ``pdc``, ``pac1..pac22`` (22 PAC samples per frame, so PAC is
2.2 kHz), ``ele1..ele19``; every row ends with a comma.  Values are 12-bit
counts that the recording setup tared and clipped at 0.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import DataFormatError

__all__ = [
    "BiotacRecording",
    "read_biotac_csv",
    "find_recordings",
    "load_recordings",
    "MATERIAL_NAMES",
    "PAC_PER_FRAME",
    "N_ELECTRODES",
]

PAC_PER_FRAME = 22
N_ELECTRODES = 19
_COLUMNS = ["timestamp", "tdc", "tac", "pdc"] + [f"pac{i}" for i in range(1, 23)] + [f"ele{i}" for i in range(1, 20)]
_NAME = re.compile(r"^mat(\d+)_(\d+)_bio\.csv$")

#: Material names of the 20 classes, from the data set's README.
MATERIAL_NAMES = {
    1: "carpet_net", 2: "cotton", 3: "bath_towel", 4: "fake_leather", 5: "polypropylene_mixed",
    6: "felt", 7: "soft_material_2", 8: "japanese_paper", 9: "smooth_polypropylene",
    10: "thin_polypropylene", 11: "soft_material_1", 12: "cork", 13: "eva_foam", 14: "pvc_paper",
    15: "fibre_board", 16: "hard_wood", 17: "styrofoam", 18: "soft_sponge",
    19: "polyethylene_foam", 20: "steel",
}


@dataclass(frozen=True)
class BiotacRecording:
    """One trial: a BioTac sliding over one material.

    Attributes
    ----------
    material : int
        Class number M.
    trial : int
        Trial number N.
    frame_t_ns : numpy.ndarray of int64, shape (n_frames,)
        Frame time stamps in ns (Unix epoch).
    pac : numpy.ndarray of int64, shape (n_frames * 22,)
        PAC counts at 2.2 kHz, in time order.
    pac_t_ns : numpy.ndarray of int64, shape (n_frames * 22,)
        PAC sample times, spread evenly over each frame's interval
        (strictly increasing).
    pdc, tac, tdc : numpy.ndarray of int64, shape (n_frames,)
    electrodes : numpy.ndarray of int64, shape (19, n_frames)
    path : str
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

    @property
    def n_frames(self) -> int:
        return int(self.frame_t_ns.shape[0])

    @property
    def frame_rate_hz(self) -> float:
        """Frame rate estimated from the time stamps (100 Hz in this data set)."""
        if self.n_frames < 2:
            return 100.0
        return float(1e9 * (self.n_frames - 1) / (self.frame_t_ns[-1] - self.frame_t_ns[0]))

    @property
    def material_name(self) -> str:
        return MATERIAL_NAMES.get(self.material, f"mat{self.material}")

    def crop_frames(self, start: int, stop: int) -> "BiotacRecording":
        """Frames ``start:stop`` (and their PAC samples) as a new recording."""
        s, e = max(0, start), min(self.n_frames, stop)
        return BiotacRecording(
            self.material, self.trial, self.frame_t_ns[s:e], self.pac[s * PAC_PER_FRAME : e * PAC_PER_FRAME],
            self.pac_t_ns[s * PAC_PER_FRAME : e * PAC_PER_FRAME], self.pdc[s:e], self.tac[s:e], self.tdc[s:e],
            self.electrodes[:, s:e], self.path,
        )


def read_biotac_csv(path: str | Path) -> BiotacRecording:
    """Read one ``mat<M>_<N>_bio.csv`` file.

    Raises
    ------
    DataFormatError
        If the name, header or any row does not have the expected layout.
    """
    path = Path(path)
    match = _NAME.match(path.name)
    if not match:
        raise DataFormatError(f"{path}: file name is not mat<M>_<N>_bio.csv")
    with path.open() as fh:
        header = [h.strip() for h in fh.readline().strip().rstrip(",").split(",")]
        if header != _COLUMNS:
            raise DataFormatError(f"{path}: unexpected header {header[:6]}... (expected {_COLUMNS[:6]}...)")
        rows = []
        for lineno, line in enumerate(fh, start=2):
            line = line.strip()
            if not line:
                continue
            fields = line.rstrip(",").split(",")
            if len(fields) != len(_COLUMNS):
                raise DataFormatError(f"{path}:{lineno}: {len(fields)} fields, expected {len(_COLUMNS)}")
            rows.append(fields)
    if not rows:
        raise DataFormatError(f"{path}: no frames")
    stamps = [r[0] for r in rows]
    try:
        values = np.array([[int(v) for v in r[1:]] for r in rows], dtype=np.int64)
    except ValueError as exc:
        raise DataFormatError(f"{path}: non-integer sample: {exc}") from None
    frame_t_ns = np.array([_seconds_to_ns(s) for s in stamps], dtype=np.int64)
    period_ns = np.int64(round(1e9 / 100.0))
    if frame_t_ns.shape[0] > 1:
        period_ns = np.int64(np.median(np.diff(frame_t_ns)))
    # Spread each frame's 22 PAC samples evenly over that frame's actual
    # interval (to the next frame's stamp; the median period for the last), so
    # PAC stamps stay increasing even when frame stamps jitter.
    if np.any(np.diff(frame_t_ns) <= 0):
        raise DataFormatError(f"{path}: frame time stamps are not increasing")
    intervals = np.append(np.diff(frame_t_ns), period_ns)
    steps = np.arange(PAC_PER_FRAME, dtype=np.int64)
    pac_t_ns = (frame_t_ns[:, None] + (intervals[:, None] * steps[None, :]) // PAC_PER_FRAME).ravel()
    return BiotacRecording(
        material=int(match.group(1)),
        trial=int(match.group(2)),
        frame_t_ns=frame_t_ns,
        pac=values[:, 3 : 3 + PAC_PER_FRAME].ravel(),
        pac_t_ns=pac_t_ns,
        pdc=values[:, 2],
        tac=values[:, 1],
        tdc=values[:, 0],
        electrodes=values[:, 3 + PAC_PER_FRAME :].T.copy(),
        path=str(path),
    )


def _seconds_to_ns(text: str) -> int:
    """Exact conversion of a decimal seconds string to integer ns."""
    whole, _, frac = text.strip().partition(".")
    frac = (frac + "000000000")[:9]
    try:
        return int(whole) * 1_000_000_000 + int(frac)
    except ValueError:
        raise DataFormatError(f"bad timestamp {text!r}") from None


def find_recordings(root: str | Path, trials: range | list[int] | None = None,
                    materials: range | list[int] | None = None) -> list[Path]:
    """Paths of the recordings below ``root`` (the folder holding ``raw_data/``, or ``raw_data`` itself).

    Sorted by material then trial; optionally only the given trials/materials.
    """
    root = Path(root)
    base = root / "raw_data" if (root / "raw_data").is_dir() else root
    if not base.is_dir():
        raise DataFormatError(f"{root}: no raw_data/ folder")
    found = []
    for path in base.glob("mat*/mat*_*_bio.csv"):
        m = _NAME.match(path.name)
        if not m:
            continue
        mat, trial = int(m.group(1)), int(m.group(2))
        if trials is not None and trial not in trials:
            continue
        if materials is not None and mat not in materials:
            continue
        found.append((mat, trial, path))
    if not found:
        raise DataFormatError(f"{root}: no mat<M>_<N>_bio.csv recordings found")
    return [p for _, _, p in sorted(found)]


def load_recordings(root: str | Path, trials=None, materials=None) -> list[BiotacRecording]:
    """Read every matching recording (see :func:`find_recordings`)."""
    return [read_biotac_csv(p) for p in find_recordings(root, trials, materials)]
