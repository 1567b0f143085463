"""Online feature scaling of descriptors: log-Activity and running standardisation.

Raw Activity spans decades between materials and sensors while Mobility and
Complexity do not, and the paper says nothing about scaling.
Our choice, usable online (one sample at a time, no second pass):

1. Activity values (labels whose quantity is ``A``) are replaced by
   ``log1p(A)``: a no-contact zero stays zero, and decades become units.
2. Every feature is standardised with a running mean and variance
   (Welford's algorithm), updated with every sample seen.  A feature whose
   running standard deviation is below ``min_std`` is only centred.

The benchmark (``tactile evaluate``) shows the effect of each step.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np

from ..errors import SignalError

__all__ = ["activity_mask", "log_activity", "RunningStandardizer", "FeatureScaler"]


def activity_mask(labels: Sequence[str]) -> np.ndarray:
    """True for labels whose quantity is Activity (``A_...`` after any ``part/`` prefix)."""
    if isinstance(labels, tuple):  # a descriptor's labels: the same tuple window after window
        return _activity_mask_of(labels).copy()
    return np.array([lab.rsplit("/", 1)[-1].startswith("A_") for lab in labels], dtype=bool)


@functools.lru_cache(maxsize=64)
def _activity_mask_of(labels: tuple[str, ...]) -> np.ndarray:
    return np.array([lab.rsplit("/", 1)[-1].startswith("A_") for lab in labels], dtype=bool)


def log_activity(values: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Apply ``log1p`` to the Activity columns (negative values are clipped at 0)."""
    out = np.array(values, dtype=np.float64, copy=True)
    out[..., mask] = np.log1p(np.maximum(out[..., mask], 0.0))
    return out


class RunningStandardizer:
    """Running mean and variance per feature (Welford), and standardisation.

    Parameters
    ----------
    n_features : int
    min_std : float, default 1e-9
        Features with a smaller running standard deviation are only centred.
    """

    def __init__(self, n_features: int, min_std: float = 1e-9) -> None:
        self.n = 0
        self.mean = np.zeros(n_features)
        self.m2 = np.zeros(n_features)
        self.min_std = float(min_std)

    def partial_fit(self, x: np.ndarray) -> RunningStandardizer:
        """Update with one sample (1-D) or several (2-D, one per row)."""
        x = np.atleast_2d(np.asarray(x, dtype=np.float64))
        if x.shape[1] != self.mean.shape[0]:
            raise SignalError(f"expected {self.mean.shape[0]} features, got {x.shape[1]}")
        for row in x:
            if not np.all(np.isfinite(row)):
                raise SignalError("cannot update feature statistics with non-finite values")
            self.n += 1
            delta = row - self.mean
            self.mean += delta / self.n
            self.m2 += delta * (row - self.mean)
        return self

    @property
    def std(self) -> np.ndarray:
        """Population standard deviation so far (0 before two samples)."""
        if self.n < 2:
            return np.zeros_like(self.mean)
        return np.sqrt(self.m2 / self.n)

    def transform(self, x: np.ndarray) -> np.ndarray:
        """Standardise ``x`` with the statistics so far."""
        x = np.asarray(x, dtype=np.float64)
        std = self.std
        scale = np.where(std > self.min_std, std, 1.0)
        return (x - self.mean) / scale

    def state(self) -> dict:
        return {"n": self.n, "mean": self.mean.tolist(), "m2": self.m2.tolist(), "min_std": self.min_std}

    @classmethod
    def from_state(cls, state: dict) -> RunningStandardizer:
        obj = cls(len(state["mean"]), state.get("min_std", 1e-9))
        obj.n = int(state["n"])
        obj.mean = np.asarray(state["mean"], dtype=np.float64)
        obj.m2 = np.asarray(state["m2"], dtype=np.float64)
        return obj


class FeatureScaler:
    """log-Activity followed by running standardisation (see module docstring).

    Parameters
    ----------
    labels : sequence of str
        Descriptor labels; fixes the feature count and which are Activity.
    log_activity : bool, default True
    standardize : bool, default True
    """

    def __init__(self, labels: Sequence[str], log_activity: bool = True, standardize: bool = True) -> None:
        self.labels = tuple(labels)
        self.use_log = bool(log_activity)
        self.use_std = bool(standardize)
        self.mask = activity_mask(self.labels)
        self.standardizer = RunningStandardizer(len(self.labels))

    def _pre(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        if x.shape[-1] != len(self.labels):
            raise SignalError(f"expected {len(self.labels)} descriptor values, got {x.shape[-1]}")
        return log_activity(x, self.mask) if self.use_log else x

    def partial_fit(self, x: np.ndarray) -> FeatureScaler:
        """Update the running statistics with one or more samples."""
        if self.use_std:
            self.standardizer.partial_fit(self._pre(x))
        return self

    def transform(self, x: np.ndarray) -> np.ndarray:
        """Scale one or more samples with the statistics so far."""
        y = self._pre(x)
        return self.standardizer.transform(y) if self.use_std else y

    def state(self) -> dict:
        return {"labels": list(self.labels), "log_activity": self.use_log, "standardize": self.use_std,
                "standardizer": self.standardizer.state()}

    @classmethod
    def from_state(cls, state: dict) -> FeatureScaler:
        obj = cls(state["labels"], state["log_activity"], state["standardize"])
        obj.standardizer = RunningStandardizer.from_state(state["standardizer"])
        return obj
