"""Texture models: autoregressive vibration and slow deformation statistics per material.

Data-driven haptic texture rendering (Culbertson, Kuchenbecker et al.) models
the vibration a probe picks up while sliding over a texture as an
autoregressive (AR) process whose spectrum scales with speed and whose power
scales with force.  We fit the same kind of model to the public BioTac
sliding recordings (``../shared/data/biotac_slide_20_50``):

* **PAC** (vibration S of the descriptor, paper eq. 17): an AR(p) model
  ``x[n] = sum_k a_k x[n-k] + e[n]``, ``e ~ N(0, sigma^2)``, fitted by
  Yule-Walker to the autocovariance of 2 s segments (each segment's mean
  removed, the autocovariances averaged over all segments of all trials), plus
  the mean PAC level above the recording's tare.  Yule-Walker reproduces the
  autocovariance at lags 0..p exactly, so the Hjorth parameters (which depend
  only on lags 0, 1, 2: ``var(x')`` is ``2(r0 - r1)``, ``var(x'')`` is
  ``6 r0 - 8 r1 + 2 r2``) of the model equal those of the average real
  segment in expectation.
* **Electrodes and PDC** (deformation V): per electrode a mean level, a
  linear response to the PAC frame mean and to PDC (what couples S and V and
  gives the correlations L and N of eq. 4-5 their value), and an AR(2) model
  of the residual (AR(2) again pins lags 0..2, hence the electrode's Hjorth
  parameters).

Speed and force rescaling
-------------------------
A texture of spatial spectrum ``P(k)`` slid at speed ``v`` gives the temporal
spectrum ``P(f / v) / v``: speed stretches the frequency axis.  For an AR
model that is a map of its poles: a pole ``z = exp(s / fs)`` of the reference
model becomes ``z ** (v / v_ref * fs_ref / fs)`` (:func:`rescale_ar`), which
also renders a model fitted at 2.2 kHz for a 1 kHz accelerometer.  Poles
pushed beyond the Nyquist frequency are dropped (the sensor's anti-alias
filter removes them).  The innovation variance is set so that the process
variance is kept, then the amplitude is scaled by
``(v / v_ref) ** speed_exponent * (F / F_ref) ** force_exponent``.

Parametric materials
--------------------
The paper uses 120 materials and 120 large objects; we have recordings of 20.
:func:`parametric_material` builds a deterministic material from a name and
a seed: one or more texture resonances at spatial frequencies (cycles per
mm) with bandwidths, a low-frequency wander pole and a roughness, turned into
the same AR form, with electrode statistics drawn around those of the
recorded materials.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from scipy import linalg, signal

from ..errors import DataFormatError, SceneError

__all__ = [
    "VibrationModel",
    "DeformationModel",
    "MaterialModel",
    "yule_walker",
    "autocovariance",
    "ar_process_variance",
    "ar_psd",
    "rescale_ar",
    "render_ar",
    "save_material",
    "load_material",
    "models_dir",
    "material_library",
    "parametric_material",
    "get_material",
    "REFERENCE_SPEED_M_S",
    "BIOTAC_PAC_RATE_HZ",
    "BIOTAC_FRAME_RATE_HZ",
    "PDC_N_PER_COUNT",
    "MODEL_FORMAT",
]

#: Sliding speed of the shared recordings (README: about 2 cm/s).
REFERENCE_SPEED_M_S: float = 0.02
#: PAC rate of the recordings (22 samples per 10 ms frame).
BIOTAC_PAC_RATE_HZ: float = 2200.0
#: Frame (electrode, PDC) rate of the recordings.
BIOTAC_FRAME_RATE_HZ: float = 100.0
#: Newtons per tared PDC count used to express the recordings' force (config/shadow_hand.yaml).
PDC_N_PER_COUNT: float = 0.05
#: Version tag written into every model file.
MODEL_FORMAT: str = "tactile_descriptors_ros/texture-model/1"

#: Amplitude grows with speed roughly as sqrt(v) (vibration power ~ v): the
#: recordings were all taken at one speed, so this is a documented default.
DEFAULT_SPEED_EXPONENT: float = 0.5


# --------------------------------------------------------------------------- AR utilities


def autocovariance(x: np.ndarray, max_lag: int) -> np.ndarray:
    """Biased autocovariance ``r[k] = sum(x[n] x[n+k]) / N`` of mean-removed ``x``, k = 0..max_lag."""
    x = np.asarray(x, dtype=np.float64)
    x = x - x.mean()
    n = x.shape[0]
    if n <= max_lag:
        raise DataFormatError(f"need more than {max_lag} samples for the autocovariance, got {n}")
    return np.array([x[: n - k] @ x[k:] / n for k in range(max_lag + 1)])


def yule_walker(r: np.ndarray) -> tuple[np.ndarray, float]:
    """Solve the Yule-Walker equations for an AR(p) model from autocovariances ``r[0..p]``.

    Returns
    -------
    a : numpy.ndarray, shape (p,)
        Coefficients of ``x[n] = sum_k a[k-1] x[n-k] + e[n]``.
    sigma2 : float
        Innovation variance.  With a biased (positive definite) autocovariance
        the model is always stable.
    """
    r = np.asarray(r, dtype=np.float64)
    p = r.shape[0] - 1
    if p < 1:
        raise DataFormatError("an AR model needs at least lags 0 and 1")
    if not r[0] > 0:
        raise DataFormatError("zero variance: the signal is flat")
    a = linalg.solve_toeplitz(r[:p], r[1 : p + 1])
    sigma2 = float(r[0] - a @ r[1 : p + 1])
    if not sigma2 > 0:
        raise DataFormatError("Yule-Walker gave a non-positive innovation variance")
    return a, sigma2


def _reflection_coefficients(a: np.ndarray) -> np.ndarray:
    """Step-down (reverse Levinson) recursion: reflection coefficients of AR coefficients ``a``."""
    cur = np.asarray(a, dtype=np.float64).copy()
    p = cur.shape[0]
    k = np.zeros(p)
    for m in range(p, 0, -1):
        km = cur[m - 1]
        k[m - 1] = km
        if abs(km) >= 1.0:
            raise SceneError(f"AR model is not stable (reflection coefficient {km:.4f})", key="texture")
        if m > 1:
            cur = (cur[: m - 1] + km * cur[m - 2 :: -1][: m - 1]) / (1.0 - km * km)
    return k


def ar_process_variance(a: np.ndarray, sigma2: float) -> float:
    """Stationary variance of the AR process ``x_t = sum_i a_i x_{t-i} + e_t``, ``var(e) = sigma2``.

    ``sigma2 / prod(1 - k_i^2)`` over the reflection coefficients (step-down
    recursion) when every pole is well inside the unit circle.  With a pole
    of radius above 0.99 (slow textures, more so stretched to slow speeds)
    that recursion loses all precision and reported |k| >= 1 for 30 of 200
    parametric materials whose poles were all inside; there the variance is
    ``sigma2 * sum h_n^2`` over the impulse response ``h`` of ``1 / A(z)``
    (``scipy.signal.lfilter``), summed until the slowest pole has decayed by
    1e-17, which is a plain sum of squares and cannot lose stability.

    Raises
    ------
    SceneError
        When a pole is on or outside the unit circle, or so close to it
        (radius above 1 - 1e-6) that the impulse response would not decay
        within 20 million samples.
    """
    a = np.asarray(a, dtype=np.float64)
    if a.size == 0:
        return float(sigma2)
    radius = float(np.max(np.abs(np.roots(np.r_[1.0, -a]))))
    if not radius < 1.0 - 1e-6:
        raise SceneError(f"AR model is not stable (largest pole radius {radius:.9f})", key="texture")
    if radius <= 0.99:
        k = _reflection_coefficients(a)
        return float(sigma2 / np.prod(1.0 - k * k))
    n = int(math.ceil(math.log(1e-17) / math.log(radius))) + 10 * a.size
    impulse = np.zeros(n)
    impulse[0] = 1.0
    h = signal.lfilter([1.0], np.r_[1.0, -a], impulse)
    return float(sigma2 * (h @ h))


def ar_psd(a: np.ndarray, sigma2: float, fs_hz: float, freqs_hz: np.ndarray) -> np.ndarray:
    """One-sided theoretical PSD ``2 sigma2 / (fs |A(e^{jw})|^2)`` of the AR model, in units^2/Hz.

    Matches :func:`scipy.signal.welch` with its default ``scaling='density'``.
    """
    w = 2.0 * np.pi * np.asarray(freqs_hz, dtype=np.float64) / fs_hz
    poly = np.r_[1.0, -np.asarray(a, dtype=np.float64)]
    _, h = signal.freqz([1.0], poly, worN=w)
    psd = sigma2 * np.abs(h) ** 2 / fs_hz
    f = np.asarray(freqs_hz)
    one_sided = np.where((f > 0) & (f < fs_hz / 2), 2.0, 1.0)
    return psd * one_sided


def rescale_ar(a: np.ndarray, sigma2: float, time_scale: float) -> tuple[np.ndarray, float]:
    """Time-stretch an AR model: ``y(t) = x(time_scale * t)`` in the continuous-pole sense.

    Each pole ``z`` becomes ``z ** time_scale`` (``log z`` scaled); complex
    pole pairs pushed past the Nyquist frequency are dropped.  The innovation
    variance is chosen so that the process variance is unchanged.

    Parameters
    ----------
    a, sigma2 : AR coefficients and innovation variance of the reference model.
    time_scale : float
        ``(v / v_ref) * (fs_ref / fs)``: 1 keeps the model as it is.

    Returns
    -------
    a_new, sigma2_new
    """
    a = np.asarray(a, dtype=np.float64)
    if time_scale <= 0 or not math.isfinite(time_scale):
        raise SceneError(f"time scale must be positive, got {time_scale}", key="speed_m_s")
    if abs(time_scale - 1.0) < 1e-12 or a.size == 0:
        return a.copy(), float(sigma2)
    var = ar_process_variance(a, sigma2)
    poles = np.roots(np.r_[1.0, -a])
    logs = np.log(poles.astype(np.complex128)) * time_scale
    keep = np.abs(logs.imag) < np.pi * (1.0 - 1e-9)
    # real negative poles (angle pi) cannot be stretched meaningfully: drop them too
    keep &= ~((np.abs(poles.imag) < 1e-12) & (poles.real < 0))
    new_poles = np.exp(logs[keep])
    poly = np.real_if_close(np.poly(new_poles), tol=1e6).real if new_poles.size else np.array([1.0])
    a_new = -poly[1:]
    if a_new.size == 0:
        return a_new, var
    unit = ar_process_variance(a_new, 1.0)
    return a_new, var / unit


def render_ar(
    a: np.ndarray, sigma2: float, n: int, rng: np.random.Generator, rows: int = 1, burn_in: int | None = None
) -> np.ndarray:
    """Draw ``rows`` independent stationary realisations of length ``n``.

    The filter is started from a burn-in of ``burn_in`` samples (default:
    enough for the slowest pole to decay by 1e-6), so the output is
    stationary from the first sample.
    """
    a = np.asarray(a, dtype=np.float64)
    if burn_in is None:
        if a.size:
            rmax = float(np.max(np.abs(np.roots(np.r_[1.0, -a]))))
            burn_in = int(min(20000, math.ceil(math.log(1e-6) / math.log(max(rmax, 1e-6))) + a.size)) if rmax < 1 else 20000
        else:
            burn_in = 0
    e = rng.standard_normal((rows, n + burn_in)) * math.sqrt(sigma2)
    if a.size == 0:
        return e[:, burn_in:]
    y = signal.lfilter([1.0], np.r_[1.0, -a], e, axis=-1)
    return y[:, burn_in:]


# --------------------------------------------------------------------------- models


@dataclass(frozen=True)
class VibrationModel:
    """AR model of the vibration signal (BioTac PAC counts) at the reference speed and force.

    Attributes
    ----------
    fs_hz : float
        Rate the model was fitted at.
    ar : tuple of float
        AR coefficients ``a_1..a_p``.
    sigma2 : float
        Innovation variance, counts^2.
    mean_counts : float
        Mean level above the tare at the reference force (the recordings'
        PAC is tared and clipped at 0, so not zero-mean).
    force_exponent, speed_exponent : float
        Amplitude scales as ``(F/F_ref)**force_exponent * (v/v_ref)**speed_exponent``.
    """

    fs_hz: float
    ar: tuple[float, ...]
    sigma2: float
    mean_counts: float
    force_exponent: float = 0.5
    speed_exponent: float = DEFAULT_SPEED_EXPONENT

    @property
    def variance(self) -> float:
        """Process variance in counts^2."""
        return ar_process_variance(np.array(self.ar), self.sigma2)

    def at(self, fs_hz: float, speed_m_s: float, reference_speed_m_s: float) -> tuple[np.ndarray, float]:
        """AR model for a sensor sampled at ``fs_hz`` sliding at ``speed_m_s`` (before the amplitude gains)."""
        scale = (speed_m_s / reference_speed_m_s) * (self.fs_hz / fs_hz)
        return rescale_ar(np.array(self.ar), self.sigma2, scale)


@dataclass(frozen=True)
class DeformationModel:
    """Slow deformation channels (electrodes) and the normal-force channel (PDC), frame rate.

    Per electrode ``e``: ``E_e = mean_e + c_e (P - mean_P) + s_e (D - mean_D) + r_e`` where
    ``P`` is the PAC frame mean, ``D`` the PDC, and ``r_e`` an AR(2) residual.
    """

    fs_hz: float
    electrode_mean: tuple[float, ...]
    electrode_pac_coupling: tuple[float, ...]
    electrode_pdc_slope: tuple[float, ...]
    electrode_ar: tuple[tuple[float, ...], ...]
    electrode_sigma2: tuple[float, ...]
    pdc_mean_counts: float
    pdc_ar: tuple[float, ...]
    pdc_sigma2: float

    @property
    def n_electrodes(self) -> int:
        return len(self.electrode_mean)


@dataclass(frozen=True)
class MaterialModel:
    """One material (or large object's surface): vibration, deformation, friction.

    Attributes
    ----------
    name : str
    vibration : VibrationModel
    deformation : DeformationModel
    reference_speed_m_s : float
    reference_force_n : float
        Force of the recordings (mean PDC times :data:`PDC_N_PER_COUNT`).
    friction : float
        Kinetic friction coefficient (drives the stick-slip effect).
    stick_slip_ratio : float
        Static over kinetic friction (1 = no stick-slip).
    source : dict
        Where the model came from (data set and trials, or ``parametric`` and seed).
    """

    name: str
    vibration: VibrationModel
    deformation: DeformationModel
    reference_speed_m_s: float = REFERENCE_SPEED_M_S
    reference_force_n: float = 1.0
    friction: float = 0.6
    stick_slip_ratio: float = 1.3
    source: Mapping[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """A JSON-serialisable dict, at full float precision.

        AR models with poles near the unit circle (slow electrode motion) are
        very sensitive to their coefficients: rounding to 6 digits can change
        the process variance a thousandfold, so nothing is rounded.
        """
        data = asdict(self)
        data["source"] = dict(self.source)
        return {"format": MODEL_FORMAT, **_plain(data)}

    @classmethod
    def from_json(cls, data: Mapping[str, Any], origin: str = "<dict>") -> MaterialModel:
        """Inverse of :meth:`to_json`; raises DataFormatError naming the missing key."""
        if data.get("format") != MODEL_FORMAT:
            raise DataFormatError(f"{origin}: not a texture model (format {data.get('format')!r}, expected {MODEL_FORMAT!r})")
        try:
            vib = data["vibration"]
            dfm = data["deformation"]
            return cls(
                name=str(data["name"]),
                vibration=VibrationModel(
                    fs_hz=float(vib["fs_hz"]), ar=tuple(float(v) for v in vib["ar"]), sigma2=float(vib["sigma2"]),
                    mean_counts=float(vib["mean_counts"]), force_exponent=float(vib["force_exponent"]),
                    speed_exponent=float(vib["speed_exponent"]),
                ),
                deformation=DeformationModel(
                    fs_hz=float(dfm["fs_hz"]),
                    electrode_mean=tuple(float(v) for v in dfm["electrode_mean"]),
                    electrode_pac_coupling=tuple(float(v) for v in dfm["electrode_pac_coupling"]),
                    electrode_pdc_slope=tuple(float(v) for v in dfm["electrode_pdc_slope"]),
                    electrode_ar=tuple(tuple(float(v) for v in row) for row in dfm["electrode_ar"]),
                    electrode_sigma2=tuple(float(v) for v in dfm["electrode_sigma2"]),
                    pdc_mean_counts=float(dfm["pdc_mean_counts"]),
                    pdc_ar=tuple(float(v) for v in dfm["pdc_ar"]),
                    pdc_sigma2=float(dfm["pdc_sigma2"]),
                ),
                reference_speed_m_s=float(data["reference_speed_m_s"]),
                reference_force_n=float(data["reference_force_n"]),
                friction=float(data["friction"]),
                stick_slip_ratio=float(data["stick_slip_ratio"]),
                source=dict(data.get("source", {})),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise DataFormatError(f"{origin}: bad texture model: {exc!r}") from None


def _plain(value: Any) -> Any:
    if isinstance(value, (float, np.floating)):
        return float(value)
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def save_material(model: MaterialModel, path: str | Path) -> None:
    """Write a model as small, stable JSON."""
    Path(path).write_text(json.dumps(model.to_json(), indent=1, sort_keys=True) + "\n")


def load_material(path: str | Path) -> MaterialModel:
    """Read a model written by :func:`save_material`."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise DataFormatError(f"{path}: cannot read texture model: {exc}") from None
    return MaterialModel.from_json(data, origin=str(path))


# --------------------------------------------------------------------------- library


def models_dir() -> Path:
    """Folder of the shipped fitted models (``sim/models``)."""
    return Path(__file__).resolve().parent / "models"


@lru_cache(maxsize=8)
def _library(folder: str) -> dict[str, MaterialModel]:
    lib = {}
    for path in sorted(Path(folder).glob("*.json")):
        model = load_material(path)
        lib[model.name] = model
    return lib


def material_library(folder: str | Path | None = None) -> Mapping[str, MaterialModel]:
    """Fitted materials by name (read once and cached)."""
    return dict(_library(str(folder or models_dir())))


def _seed_of(*parts: Any) -> int:
    text = "/".join(str(p) for p in parts).encode()
    return int.from_bytes(hashlib.sha256(text).digest()[:8], "little")


def _ar_from_resonances(fs_hz: float, freqs_hz: Sequence[float], bandwidths_hz: Sequence[float],
                        wander_pole: float) -> np.ndarray:
    poles = [wander_pole]
    for f, bw in zip(freqs_hz, bandwidths_hz):
        r = math.exp(-math.pi * bw / fs_hz)
        th = 2.0 * math.pi * f / fs_hz
        poles += [r * complex(math.cos(th), math.sin(th)), r * complex(math.cos(th), -math.sin(th))]
    return -np.real(np.poly(poles))[1:]


def parametric_material(name: str, seed: int = 0, *, n_electrodes: int = 19) -> MaterialModel:
    """A deterministic synthetic material, for scenes with more materials than were recorded.

    The same ``(name, seed)`` always gives the same model.  Its vibration has
    one to three resonances at spatial periods of 0.2-5 mm (so 4-100 Hz at
    2 cm/s, up to 200 Hz at 4 cm/s) with bandwidths of 10-60 % of their
    frequency, over a low-frequency wander pole, and a standard deviation
    spread log-uniformly over the range of the recorded materials
    (about 50 to 250 PAC counts).  Electrode statistics are drawn around those
    of the recorded materials.
    """
    rng = np.random.default_rng(_seed_of("parametric", name, seed))
    fs = BIOTAC_PAC_RATE_HZ
    v = REFERENCE_SPEED_M_S
    n_res = int(rng.integers(1, 4))
    periods_mm = np.exp(rng.uniform(math.log(0.2), math.log(5.0), n_res))
    freqs = v * 1000.0 / periods_mm
    bws = freqs * rng.uniform(0.1, 0.6, n_res)
    wander = float(rng.uniform(0.9, 0.985))
    a = _ar_from_resonances(fs, freqs, bws, wander)
    std = float(np.exp(rng.uniform(math.log(50.0), math.log(250.0))))
    unit = ar_process_variance(a, 1.0)
    s2 = std * std / unit
    el_mean = np.exp(rng.normal(math.log(12.0), 0.8, n_electrodes))
    el_std = np.exp(rng.normal(math.log(2.5), 0.5, n_electrodes))
    rho1 = rng.uniform(0.6, 0.95, n_electrodes)
    el_ar, el_s2 = [], []
    for r1, sd in zip(rho1, el_std):
        # AR(2) with a real double pole at rho: smooth electrode motion
        a2 = (2.0 * r1, -r1 * r1)
        el_ar.append(tuple(float(x) for x in a2))
        el_s2.append(float(sd * sd / ar_process_variance(np.array(a2), 1.0)))
    pdc_mean = float(rng.uniform(20.0, 80.0))
    return MaterialModel(
        name=name,
        vibration=VibrationModel(fs_hz=fs, ar=tuple(float(x) for x in a), sigma2=float(s2),
                                 mean_counts=float(std * rng.uniform(0.6, 1.4)),
                                 force_exponent=float(rng.uniform(0.3, 0.8)), speed_exponent=DEFAULT_SPEED_EXPONENT),
        deformation=DeformationModel(
            fs_hz=BIOTAC_FRAME_RATE_HZ,
            electrode_mean=tuple(float(x) for x in el_mean),
            electrode_pac_coupling=tuple(float(x) for x in rng.normal(0.0, 0.01, n_electrodes)),
            electrode_pdc_slope=tuple(float(x) for x in np.abs(rng.normal(0.2, 0.1, n_electrodes))),
            electrode_ar=tuple(el_ar),
            electrode_sigma2=tuple(el_s2),
            pdc_mean_counts=pdc_mean,
            pdc_ar=(1.5, -0.56),
            pdc_sigma2=float((0.05 * pdc_mean) ** 2 / ar_process_variance(np.array([1.5, -0.56]), 1.0)),
        ),
        reference_speed_m_s=v,
        reference_force_n=pdc_mean * PDC_N_PER_COUNT,
        friction=float(rng.uniform(0.3, 1.0)),
        stick_slip_ratio=float(rng.uniform(1.0, 1.8)),
        source={"parametric": True, "seed": int(seed), "resonance_periods_mm": [float(f"{p:.4g}") for p in periods_mm]},
    )


def get_material(name: str, seed: int = 0, folder: str | Path | None = None) -> MaterialModel:
    """A fitted material by name, or a parametric one for names ``param:<anything>``.

    Raises
    ------
    SceneError
        For an unknown fitted material (the message lists the known ones).
    """
    if name.startswith("param:"):
        return parametric_material(name, seed)
    lib = material_library(folder)
    if name not in lib:
        raise SceneError(
            f"unknown material {name!r}: fitted ones are {', '.join(sorted(lib)) or '(none)'}; "
            "use 'param:<name>' for a parametric material", key="material")
    return lib[name]
