"""Random-convolution features (MiniRocket): the ``rocket`` feature group.

MiniRocket (Dempster, Schmidt & Webb, "MINIROCKET: A Very Fast (Almost)
Deterministic Transform for Time Series Classification", KDD 2021) describes
a series by the *proportion of positive values* (PPV) of its convolutions
with fixed kernels, each compared with a bias: 84 kernels of length 9 with
weights -1 (six taps) and 2 (three taps), spread by dilations ``d`` so that
tap ``k`` reads sample ``t + (k - 4) d``.  For a kernel, a dilation and a
bias ``b``, the feature is ``mean_t [C_t > b]``, over the whole series with
zeros past its ends (even ``(dilation index + kernel index)``) or over the
positions where the kernel lies inside the series (odd).  A multichannel
series is convolved on a random combination of 1 to 9 of its channels per
kernel and dilation, summed.  The biases are quantiles of the convolution
output of a training example (the low-discrepancy quantiles
``(k phi) mod 1``, ``phi`` the golden ratio), so they are *fitted on
training data* (:func:`fit`) and stored with the robot's configuration
(:class:`RocketParameters`, :func:`load_parameters`).

How a PPV reads a texture: each kernel is a band-pass shape at the scale
its dilation sets; ``C_t > b`` counts how often that local shape is
stronger than a level typical of the training data.  A PPV is a count, not
an amplitude: a drift of a static level or a louder slide moves it far less
than it moves a mean or a variance, which is what the recordings' later
trials need (docs/evaluation.md).

The transform here equals aeon's ``MiniRocket`` transform
(``aeon.transformations.collection.convolution_based.MiniRocket``) given the
same parameters (a test compares them when aeon is installed, and against
outputs recorded from it); aeon is not a dependency of the robot: it pins an
older numba than this package, and the window node needs the transform
only, for a few hundred features.  The compiled backend
(:func:`.fast.kernel_module`, ``rocket_ppv``) computes the same counts as the
numpy reference here.
"""

from __future__ import annotations

import functools
import itertools
import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ConfigError, SignalError

__all__ = [
    "KERNEL_INDICES",
    "N_KERNELS",
    "RocketParameters",
    "fit_dilations",
    "quantiles",
    "fit",
    "transform",
    "convolve",
    "load_parameters",
    "save_parameters",
    "PARAMETERS_FORMAT",
]

#: The three taps of weight 2 of each of MiniRocket's 84 kernels (the other six weigh -1).
KERNEL_INDICES: np.ndarray = np.array(list(itertools.combinations(range(9), 3)), dtype=np.int64)
N_KERNELS: int = len(KERNEL_INDICES)

#: The ``format`` of a parameters file.
PARAMETERS_FORMAT = "tactile_descriptors_ros/rocket_parameters"
_PARAMETERS_VERSION = 1


@dataclass(frozen=True)
class RocketParameters:
    """A fitted MiniRocket transform of one signal (a vibration channel, or a cell's slow channels).

    Attributes
    ----------
    n_channels : int
        Channels of the series it transforms.
    n_samples : int
        Samples of the series it was fitted on (the dilations depend on it;
        the transform takes any length at least ``8 * max(dilations) + 1``).
    dilations : numpy.ndarray of int64, shape (n_dilations,)
    features_per_dilation : numpy.ndarray of int64, shape (n_dilations,)
        Biases (features) per kernel at each dilation.
    channels_per_combination : numpy.ndarray of int64, shape (n_dilations * 84,)
        Channels summed for each (dilation, kernel), in that order.
    channel_indices : numpy.ndarray of int64, shape (sum of channels_per_combination,)
        Those channels, combination after combination.
    biases : numpy.ndarray of float64, shape (n_features,)
        In feature order: dilation, kernel, bias.
    """

    n_channels: int
    n_samples: int
    dilations: np.ndarray
    features_per_dilation: np.ndarray
    channels_per_combination: np.ndarray
    channel_indices: np.ndarray
    biases: np.ndarray

    @property
    def n_features(self) -> int:
        return int(self.biases.size)

    def __post_init__(self) -> None:
        nd = self.dilations.size
        if nd == 0 or self.features_per_dilation.shape != (nd,) or np.any(self.features_per_dilation < 1):
            raise ConfigError("rocket parameters: dilations and features per dilation must match, at least one each")
        if np.any(self.dilations < 1):
            raise ConfigError("rocket parameters: dilations must be at least 1")
        if self.channels_per_combination.shape != (nd * N_KERNELS,):
            raise ConfigError(f"rocket parameters: {self.channels_per_combination.size} channel combinations, "
                              f"expected {nd * N_KERNELS} (84 kernels x {nd} dilations)")
        if (np.any(self.channels_per_combination < 1) or np.any(self.channels_per_combination > self.n_channels)
                or self.channel_indices.size != int(self.channels_per_combination.sum())
                or np.any(self.channel_indices < 0) or np.any(self.channel_indices >= self.n_channels)):
            raise ConfigError(f"rocket parameters: channel combinations must name 1..{self.n_channels} of the "
                              f"{self.n_channels} channels")
        if self.biases.shape != (N_KERNELS * int(self.features_per_dilation.sum()),):
            raise ConfigError(f"rocket parameters: {self.biases.size} biases, expected "
                              f"{N_KERNELS * int(self.features_per_dilation.sum())}")
        if not np.all(np.isfinite(self.biases)):
            raise ConfigError("rocket parameters: biases must be finite")

    @property
    def min_samples(self) -> int:
        """The shortest series the transform takes: a kernel at the largest dilation must fit inside it."""
        return int(8 * self.dilations.max() + 1)

    def state(self) -> dict:
        """JSON-ready (biases as numbers, shortest round-trip repr: exact)."""
        return {"n_channels": self.n_channels, "n_samples": self.n_samples,
                "dilations": self.dilations.tolist(), "features_per_dilation": self.features_per_dilation.tolist(),
                "channels_per_combination": self.channels_per_combination.tolist(),
                "channel_indices": self.channel_indices.tolist(), "biases": self.biases.tolist()}

    @classmethod
    def from_state(cls, state: dict, where: str = "rocket parameters") -> RocketParameters:
        """Inverse of :meth:`state`, checked.

        Raises
        ------
        ConfigError
            Naming ``where`` and the key, for a missing key or inconsistent arrays.
        """
        try:
            ints = {k: np.asarray(state[k], dtype=np.int64) for k in
                    ("dilations", "features_per_dilation", "channels_per_combination", "channel_indices")}
            return cls(int(state["n_channels"]), int(state["n_samples"]), biases=np.asarray(state["biases"],
                       dtype=np.float64), **ints)
        except KeyError as exc:
            raise ConfigError(f"{where}: key {exc.args[0]!r} is missing") from None
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"{where}: {exc}") from None
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc}") from None


def fit_dilations(n_samples: int, n_features: int, max_dilations_per_kernel: int = 32
                  ) -> tuple[np.ndarray, np.ndarray]:
    """MiniRocket's dilations for a series length and the features per dilation (as aeon and the paper).

    ``n_features // 84`` features per kernel are spread over at most
    ``max_dilations_per_kernel`` dilations ``floor(2^e)``, ``e`` evenly
    spaced in ``[0, log2((n_samples - 1) / 8)]``.
    """
    per_kernel = n_features // N_KERNELS
    if per_kernel < 1:
        raise ConfigError(f"rocket: at least {N_KERNELS} features (one per kernel), got {n_features}")
    if n_samples < 9:
        raise ConfigError(f"rocket: a series of at least 9 samples, got {n_samples}")
    true_max = min(per_kernel, max_dilations_per_kernel)
    multiplier = per_kernel / true_max
    max_exponent = np.log2((n_samples - 1) / (9 - 1))
    # 2^e by the C library's pow, one value at a time, floored 1e-9 above: numpy's vectorised power rounds
    # the last bit by the CPU's instruction set, and where 2^e is an integer (e = log2 of an integer) one
    # machine floored 11.999999999999998 to 11 where another got 12 (aeon's reference was taken on the first)
    powers = np.array([math.pow(2.0, float(e)) for e in np.linspace(0.0, max_exponent, true_max)])
    dilations, counts = np.unique(np.floor(powers + 1e-9).astype(np.int32), return_counts=True)
    counts = (counts * multiplier).astype(np.int32)
    remainder = per_kernel - int(counts.sum())
    i = 0
    while remainder > 0:
        counts[i] += 1
        remainder -= 1
        i = (i + 1) % len(counts)
    return dilations.astype(np.int64), counts.astype(np.int64)


def quantiles(n: int) -> np.ndarray:
    """The low-discrepancy quantiles ``(k phi) mod 1``, k = 1..n, of the biases (float32, as MiniRocket)."""
    return np.array([(k * ((np.sqrt(5) + 1) / 2)) % 1 for k in range(1, n + 1)], dtype=np.float32)


def convolve(x: np.ndarray, dilation: int, kernel: int, channels: np.ndarray) -> np.ndarray:
    """One kernel's convolution output over a series, zeros past its ends, channels summed.

    ``C_t = sum_c sum_k w_k x_c[t + (k - 4) dilation]`` with ``w_k = 2`` at
    the kernel's three taps (:data:`KERNEL_INDICES`) and -1 elsewhere.

    Parameters
    ----------
    x : numpy.ndarray, shape (n_channels, n_samples)
    dilation : int
    kernel : int
        0..83.
    channels : array of int
        The channels summed.
    """
    xs = np.asarray(x, dtype=np.float64)[np.asarray(channels)].sum(axis=0)
    n = xs.size
    out = np.zeros(n)
    taps = set(KERNEL_INDICES[kernel].tolist())
    for k in range(9):
        w = 2.0 if k in taps else -1.0
        shift = (k - 4) * dilation
        lo, hi = max(0, -shift), min(n, n - shift)
        if hi > lo:
            out[lo:hi] += w * xs[lo + shift:hi + shift]
    return out


def fit(series: np.ndarray, n_features: int = 840, max_dilations_per_kernel: int = 32, seed: int = 0,
        n_samples: int | None = None) -> RocketParameters:
    """Fit dilations, channel combinations and biases to training series (MiniRocket's fit).

    For every (dilation, kernel) a training series is drawn at random
    (``numpy.random.default_rng(seed)``), and the combination's biases are
    quantiles (:func:`quantiles`) of its convolution output (zeros past the
    ends, as MiniRocket fits them).  Multichannel series draw
    ``floor(2^u)`` channels, ``u`` uniform in ``[0, log2(min(n_channels, 9) + 1))``,
    without repetition, per combination.

    Parameters
    ----------
    series : array_like, shape (n_series, n_channels, n_samples)
        Training series (windows of the signal the group will describe).
    n_features : int, default 840
        Rounded down to a multiple of 84.
    max_dilations_per_kernel : int, default 32
    seed : int, default 0
    n_samples : int, optional
        Length the dilations are fitted for (defaults to the series').

    Returns
    -------
    RocketParameters
    """
    x = np.asarray(series, dtype=np.float64)
    if x.ndim != 3 or x.shape[0] < 1:
        raise ConfigError(f"rocket fit: series of shape (n_series, n_channels, n_samples), got {x.shape}")
    n_series, n_ch, n_t = x.shape
    dilations, per_dilation = fit_dilations(int(n_samples or n_t), n_features, max_dilations_per_kernel)
    rng = np.random.default_rng(seed)
    n_comb = dilations.size * N_KERNELS
    max_exponent = np.log2(min(n_ch, 9) + 1)
    counts = (2 ** rng.uniform(0, max_exponent, n_comb)).astype(np.int64)
    counts = np.minimum(counts, n_ch)
    chans = np.concatenate([rng.choice(n_ch, c, replace=False) for c in counts]).astype(np.int64)
    q = quantiles(N_KERNELS * int(per_dilation.sum()))
    biases = np.zeros(q.size)
    f = c0 = comb = 0
    for j, dil in enumerate(dilations):
        for k in range(N_KERNELS):
            m = int(per_dilation[j])
            example = x[int(rng.integers(n_series))]
            out = convolve(example, int(dil), k, chans[c0:c0 + counts[comb]]).astype(np.float32)
            biases[f:f + m] = np.quantile(out, q[f:f + m]).astype(np.float32)
            f += m
            c0 += int(counts[comb])
            comb += 1
    return RocketParameters(n_ch, int(n_samples or n_t), dilations, per_dilation, counts, chans, biases)


def transform(series: np.ndarray, params: RocketParameters) -> np.ndarray:
    """PPV features of series (MiniRocket's transform), by the compiled backend when it serves.

    Parameters
    ----------
    series : array_like, shape (n_series, n_channels, n_samples)
    params : RocketParameters

    Returns
    -------
    numpy.ndarray, shape (n_series, n_features)
        Each value a proportion in [0, 1]; NaN for a series holding a
        non-finite sample.

    Raises
    ------
    SignalError
        For another channel count, or a series shorter than ``params.min_samples``.
    """
    x = np.asarray(series)
    if x.ndim != 3 or x.shape[1] != params.n_channels:
        raise SignalError(f"rocket: expected series of shape (n, {params.n_channels}, n_samples), got {x.shape}")
    if x.shape[2] < params.min_samples:
        raise SignalError(f"rocket: a series of {x.shape[2]} samples is shorter than the {params.min_samples} its "
                          f"largest dilation ({int(params.dilations.max())}) needs")
    x = np.ascontiguousarray(x, dtype=np.float64)
    out = np.empty((x.shape[0], params.n_features))
    from . import fast  # the compiled backend, when numba serves

    kernel = fast.kernel_module()
    if kernel is not None and hasattr(kernel, "rocket_ppv"):
        kernel.rocket_ppv(x, params.dilations, params.features_per_dilation, params.channels_per_combination,
                          params.channel_indices, params.biases, KERNEL_INDICES, out)
    else:
        _transform_numpy(x, params, out)
    bad = ~np.isfinite(x).all(axis=(1, 2))
    if bad.any():
        out[bad] = np.nan
    return out


def _transform_numpy(x: np.ndarray, p: RocketParameters, out: np.ndarray) -> None:
    """The reference: every (dilation, kernel) convolved with :func:`convolve`, its PPVs counted."""
    for i in range(x.shape[0]):
        f = c0 = comb = 0
        for j, dil in enumerate(p.dilations):
            pad = 4 * int(dil)
            for k in range(N_KERNELS):
                m = int(p.features_per_dilation[j])
                nc = int(p.channels_per_combination[comb])
                c = convolve(x[i], int(dil), k, p.channel_indices[c0:c0 + nc])
                if (j + k) % 2 == 1:
                    c = c[pad:c.size - pad]
                out[i, f:f + m] = (c[:, None] > p.biases[None, f:f + m]).mean(axis=0)
                f += m
                c0 += nc
                comb += 1


# ------------------------------------------------------------------ files


def save_parameters(path: str | os.PathLike[str], groups: dict[str, RocketParameters], *,
                    description: str = "") -> None:
    """Write fitted transforms (one per signal: ``vibration``, ``slow``) as JSON."""
    data = {"format": PARAMETERS_FORMAT, "format_version": _PARAMETERS_VERSION, "description": description,
            "signals": {k: v.state() for k, v in groups.items()}}
    Path(path).write_text(json.dumps(data, indent=None, separators=(",", ":")) + "\n")


@functools.lru_cache(maxsize=16)
def _load_cached(path: str, mtime_ns: int, size: int) -> dict[str, RocketParameters]:
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{path}: cannot read rocket parameters: {exc}") from None
    if not isinstance(data, dict) or data.get("format") != PARAMETERS_FORMAT:
        raise ConfigError(f"{path}: not a rocket parameters file (format {PARAMETERS_FORMAT!r})")
    if data.get("format_version") != _PARAMETERS_VERSION:
        raise ConfigError(f"{path}: rocket parameters v{data.get('format_version')!r}, expected "
                          f"v{_PARAMETERS_VERSION}")
    signals = data.get("signals")
    if not isinstance(signals, dict) or not signals:
        raise ConfigError(f"{path}: 'signals' must name at least one fitted transform")
    return {k: RocketParameters.from_state(v, f"{path}: signals.{k}") for k, v in signals.items()}


def load_parameters(path: str | os.PathLike[str]) -> dict[str, RocketParameters]:
    """Read a parameters file (cached per path, size and modification time).

    Raises
    ------
    ConfigError
        Naming the file: missing, not JSON, another format, inconsistent arrays.
    """
    p = Path(path)
    try:
        st = p.stat()
    except OSError as exc:
        raise ConfigError(f"{p}: cannot read rocket parameters: {exc.strerror or exc}") from None
    return _load_cached(str(p.resolve()), st.st_mtime_ns, st.st_size)


def check_lengths(params: Sequence[RocketParameters], n_samples: Sequence[int]) -> None:
    """Refuse series shorter than a transform's largest kernel (a :class:`SignalError` naming both)."""
    for p, n in zip(params, n_samples):
        if n < p.min_samples:
            raise SignalError(f"rocket: a series of {n} samples is shorter than the {p.min_samples} its largest "
                              f"dilation needs")
