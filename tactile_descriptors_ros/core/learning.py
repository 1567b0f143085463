"""Online multiclass Passive-Aggressive learning (PA-I), open-ended.

Kaboli et al. 2018, section VI-A, eq. 30-32, after Crammer et al., "Online
Passive-Aggressive Algorithms", JMLR 2006: multiclass, cost-sensitive PA-I
with the prediction-based update.  One weight vector per class (the
multiclass feature map Phi(x, y) places x in class y's block), all zero at
start; for a sample (x, y):

* predict ``y_hat = argmax_r w_r . x`` (eq. 30's confidence);
* loss ``l = max(0, 1 - (w_y . x - w_y_hat . x))`` when ``y_hat != y``, else 0;
* step ``theta = min(eta, l / ||Phi(x, y) - Phi(x, y_hat)||^2)`` with
  ``||Phi(x, y) - Phi(x, y_hat)||^2 = 2 ||x||^2`` (eq. 32);
* update ``w_y += theta x``, ``w_y_hat -= theta x`` (eq. 31).

Eq. 32 as printed has the inner product's sign garbled; this is the JMLR
form the paper cites.  Ties: a prediction counts as correct only when the
true class is the unique maximum, so the all-zero start learns from its
first sample.  A constant 1 is appended to x (a bias per class).  Classes
may be added at any time (open-ended): a new class starts with zero weights.

Two options beyond the paper, both from the same JMLR paper's framework and
off by default (``PassiveAggressive(update="prediction", average=False)`` is
eq. 30-32 exactly):

* ``update="max_loss"``: Crammer et al.'s *max-loss* update.  The rival is
  the highest-scoring wrong class ``r = argmax_{r != y} w_r . x`` and the
  model also learns when it is right but by a margin below 1
  (``l = max(0, 1 - (w_y . x - w_r . x)) > 0``), so it keeps pushing the
  classes apart instead of stopping at the first correct prediction.
* ``average=True``: predictions use the mean of the weight vectors after
  every update so far (the averaged perceptron of Freund & Schapire 1999,
  applied to PA), which damps the last few samples' pull on the model.  The
  sum is kept in O(1) per update: with ``U = sum_t t * delta_t``, the mean
  after ``T`` samples is ``W + (W - U) / T``.

On the real BioTac recordings (2 s windows, train trials 1-20, test 21-30)
these two lift one-pass online accuracy from about 85 % to about 94 %
(``lab/docs/results.md``).

A second-order learner of the same family (``update="arow"``): multiclass
AROW, *Adaptive Regularization of Weight Vectors* (Crammer, Kulesza & Dredze,
NIPS 2009), with the max-loss rival and one covariance ``Sigma`` shared by
the classes (a full matrix, identity at start).  For a sample (x, y) with
rival r and margin ``m = w_y . x - w_r . x``: when ``m < 1``,
``v = 2 x' Sigma x``, ``beta = 1 / (v + R)``, ``alpha = (1 - m) beta``,
``w_y += alpha Sigma x``, ``w_r -= alpha Sigma x`` and
``Sigma -= beta (Sigma x)(Sigma x)'``.  The step along each direction
shrinks as the direction is seen, so late samples no longer undo what early
ones taught (PA-I's step depends on the current sample alone); one pass,
classes open-ended as above.  ``R = r_per_feature x (n_features + 1)``
keeps the trade-off independent of the descriptor's length (the scaled
features have unit variance, so ``x' x`` grows with it).  Cost per update:
O(n^2) for n features (a 1,306-value Shadow Hand descriptor: one
1,306 x 1,306 matrix, a few ms per label); prediction is unchanged.
On the BioTac recordings (2 s windows) it scores 94.1 % on the development
split and 95.0 +- 1.6 % by trial cross-validation against averaged max-loss
PA-I's 93.55 % and 92.5 +- 2.8 % (the SVM: 97.0 % and 96.8 +- 0.8 %;
``lab/docs/evaluation.md``).

Scikit-learn's PassiveAggressiveClassifier is being deprecated and costs
about 25 ms per single-sample update for 120 classes; this numpy version
costs microseconds.

This module reads and writes no file: a model is plain data
(:meth:`OnlineClassifier.state`, :meth:`OnlineClassifier.delta`), and
:mod:`.model_store` keeps it on disk (model file, journal, lock).
"""

from __future__ import annotations

import base64
import binascii
from collections.abc import Sequence

import numpy as np

from ..errors import ModelError, SignalError
from .scaling import FeatureScaler

__all__ = ["PA_UPDATES", "RECOMMENDED_PA_UPDATE", "RECOMMENDED_PA_AVERAGE", "AROW_R_PER_FEATURE", "PassiveAggressive",
           "OnlineClassifier"]

#: Update rules of :class:`PassiveAggressive`: the paper's prediction-based
#: update (eq. 30-32), Crammer et al.'s max-loss update, and the
#: second-order AROW update (shared covariance, max-loss rival).
PA_UPDATES: tuple[str, ...] = ("prediction", "max_loss", "arow")

#: AROW's regularisation R per feature (``R = AROW_R_PER_FEATURE x (n_features + 1)``).
AROW_R_PER_FEATURE: float = 0.4

#: The variant the classifier node and ``tactile evaluate`` use by default
#: (the classes themselves default to the paper's): AROW, not averaged (an
#: average dilutes a class that appears late with the zeros it had before,
#: and scored lower: 92.9 % against 94.1 % on the development split at 2 s).
#: Max-loss averaged PA-I (``max_loss``, averaged) is the first-order choice
#: for a descriptor of many thousand values, where AROW's n x n covariance
#: is too large to keep.
RECOMMENDED_PA_UPDATE: str = "arow"
RECOMMENDED_PA_AVERAGE: bool = False

_FORMAT = "tactile_descriptors_ros/online_classifier"
#: Version 2 adds the AROW covariance (``pa.covariance``) and ``pa.r_per_feature``; version 1 files
#: (PA-I only) still load.
_FORMAT_VERSION = 2
_READABLE_VERSIONS = (1, 2)


class PassiveAggressive:
    """Multiclass PA-I (eq. 30-32), prediction-based or max-loss update, optionally averaged.

    Parameters
    ----------
    n_features : int
        Length of x (the bias is added internally).
    eta : float, default 1.0
        Aggressiveness (the paper fixes eta = 1).
    update : {"prediction", "max_loss", "arow"}, default "prediction"
        ``prediction`` learns only from mistakes (the paper); ``max_loss``
        also from correct predictions whose margin is below 1; ``arow`` is
        the second-order update of the module docstring (``eta`` unused).
    average : bool, default False
        Predict with the mean of the weights over all samples seen.
    r_per_feature : float, default :data:`AROW_R_PER_FEATURE`
        AROW's regularisation per feature (``update="arow"`` only).
    """

    def __init__(self, n_features: int, eta: float = 1.0, update: str = "prediction",
                 average: bool = False, r_per_feature: float = AROW_R_PER_FEATURE) -> None:
        if n_features <= 0:
            raise SignalError(f"n_features must be positive, got {n_features}")
        if not eta > 0:
            raise SignalError(f"eta must be positive, got {eta}")
        if update not in PA_UPDATES:
            raise SignalError(f"unknown PA update {update!r}; choose from {', '.join(PA_UPDATES)}")
        if not (np.isfinite(r_per_feature) and r_per_feature > 0):
            raise SignalError(f"r_per_feature must be a positive number, got {r_per_feature}")
        self.n_features = int(n_features)
        self.r_per_feature = float(r_per_feature)
        self.update = update
        self._covariance: np.ndarray | None = None  # made when first asked for (covariance)
        #: ``(beta, Sigma x)`` of the last AROW update (what :class:`ModelStore` journals), else None
        self.covariance_step: tuple[float, np.ndarray] | None = None
        self.eta = float(eta)
        self.average = bool(average)
        self.classes: list[str] = []
        self.weights = np.zeros((0, self.n_features + 1))
        self._u = np.zeros((0, self.n_features + 1))  # sum of t * delta_t, for the average
        self.updates = 0
        self.mistakes = 0
        self.changed_rows: tuple[int, ...] = ()  # classes whose rows the last partial_fit changed

    @property
    def covariance(self) -> np.ndarray | None:
        """AROW's shared covariance (``update="arow"``), else None.

        The identity until the first update, made when first asked for
        (an update, a save): predicting needs none, and a NAO descriptor's
        918 x 918 identity took 5 ms (15 ms on a loaded machine), which fell
        on the classifier node's first prediction, where the model is made.
        """
        if self._covariance is None and self.update == "arow":
            self._covariance = np.eye(self.n_features + 1)
        return self._covariance

    @covariance.setter
    def covariance(self, value: np.ndarray | None) -> None:
        self._covariance = value

    def _x(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        if x.shape != (self.n_features,):
            raise SignalError(f"expected a vector of {self.n_features} features, got shape {x.shape}")
        if not np.all(np.isfinite(x)):
            raise SignalError("features must be finite")
        return np.append(x, 1.0)

    def add_class(self, name: str) -> int:
        """Add a class with zero weights (no-op if known); return its index."""
        if name in self.classes:
            return self.classes.index(name)
        self.classes.append(name)
        self.weights = np.vstack([self.weights, np.zeros(self.n_features + 1)])
        self._u = np.vstack([self._u, np.zeros(self.n_features + 1)])
        return len(self.classes) - 1

    @property
    def decision_weights(self) -> np.ndarray:
        """The weights predictions use: the current ones, or their running mean with ``average``."""
        if not self.average or self.updates == 0:
            return self.weights
        return self.weights + (self.weights - self._u) / self.updates

    def scores(self, x: np.ndarray) -> np.ndarray:
        """``w_r . x`` for every known class (averaged weights with ``average``)."""
        return self.decision_weights @ self._x(x)

    def predict(self, x: np.ndarray) -> str | None:
        """Class with the highest score, or None before any class is known."""
        if not self.classes:
            return None
        return self.classes[int(np.argmax(self.scores(x)))]

    def partial_fit(self, x: np.ndarray, y: str) -> float:
        """Learn from one labelled sample; return the loss before the update.

        The loss is ``max(0, 1 - (w_y . x - w_r . x))`` against the
        highest-scoring wrong class ``r``; the prediction-based update counts
        it only when ``r`` wins or ties (a mistake).
        """
        xb = self._x(x)
        yi = self.add_class(y)
        self.updates += 1
        self.changed_rows = ()
        self.covariance_step = None
        if len(self.classes) < 2:
            return 0.0
        s = self.weights @ xb
        rivals = s.copy()
        rivals[yi] = -np.inf
        best_rival = int(np.argmax(rivals))
        mistake = not s[yi] > s[best_rival]
        loss = max(0.0, 1.0 - (s[yi] - s[best_rival]))
        if mistake:
            self.mistakes += 1
        elif self.update == "prediction" or loss == 0.0:
            return 0.0  # unique maximum (and, for max-loss and AROW, margin >= 1): nothing to learn
        if self.update == "arow":
            sx = self.covariance @ xb
            beta = 1.0 / (2.0 * float(xb @ sx) + self.r_per_feature * xb.size)
            step = (loss * beta) * sx
            self.covariance -= beta * np.outer(sx, sx)
            self.covariance_step = (beta, sx)
        else:
            norm2 = 2.0 * float(xb @ xb)
            theta = min(self.eta, loss / norm2) if norm2 > 0 else 0.0
            step = theta * xb
        self.weights[yi] += step
        self.weights[best_rival] -= step
        self._u[yi] += self.updates * step
        self._u[best_rival] -= self.updates * step
        self.changed_rows = (yi, best_rival)
        return loss

    def state(self) -> dict:
        out = {"n_features": self.n_features, "eta": self.eta, "update": self.update, "average": self.average,
               "classes": list(self.classes), "weights": self.weights.tolist(),
               "weighted_sum": self._u.tolist(), "updates": self.updates, "mistakes": self.mistakes}
        if self.covariance is not None:
            out["r_per_feature"] = self.r_per_feature
            out["covariance"] = _encode_matrix(self.covariance)
        return out

    @classmethod
    def from_state(cls, state: dict) -> PassiveAggressive:
        """Rebuild from :meth:`state`, checked: a corrupt but parseable state raises :class:`ModelError`.

        Files written before ``update``, ``average`` and ``weighted_sum``
        existed are the paper's plain PA-I.
        """
        if not isinstance(state, dict):
            raise ModelError(f"'pa' must be an object, not {type(state).__name__}")
        n = _integer(state, "n_features", "pa", minimum=1)
        eta = _number(state, "eta", "pa")
        if not eta > 0:
            raise ModelError(f"'pa.eta' must be positive, not {eta!r}")
        update = state.get("update", "prediction")
        if update not in PA_UPDATES:
            raise ModelError(f"'pa.update' must be one of {PA_UPDATES}, not {update!r}")
        average = state.get("average", False)
        if not isinstance(average, bool):
            raise ModelError(f"'pa.average' must be true or false, not {average!r}")
        r_per_feature = _number(state, "r_per_feature", "pa") if "r_per_feature" in state else AROW_R_PER_FEATURE
        if not r_per_feature > 0:
            raise ModelError(f"'pa.r_per_feature' must be positive, not {r_per_feature!r}")
        obj = cls(n, eta, update, average, r_per_feature)
        if update == "arow":
            if "covariance" not in state:
                raise ModelError("'pa.covariance' is missing (an AROW model holds its covariance)")
            obj.covariance = _decode_matrix(state["covariance"], (n + 1, n + 1), "pa.covariance")
        elif "covariance" in state:
            raise ModelError(f"'pa.covariance' given for the {update!r} update, which has none")
        classes = state.get("classes")
        if not isinstance(classes, list) or not all(isinstance(c, str) and c for c in classes):
            raise ModelError("'pa.classes' must be a list of non-empty class names")
        dup = sorted({c for c in classes if classes.count(c) > 1})
        if dup:
            raise ModelError(f"'pa.classes' names {', '.join(map(repr, dup))} more than once")
        obj.classes = list(classes)
        shape = (len(classes), n + 1)
        obj.weights = _matrix(state.get("weights"), shape, "pa.weights")
        obj._u = _matrix(state["weighted_sum"], shape, "pa.weighted_sum") if "weighted_sum" in state \
            else np.zeros(shape)
        obj.updates = _integer(state, "updates", "pa", minimum=0, default=0)
        obj.mistakes = _integer(state, "mistakes", "pa", minimum=0, default=0)
        if obj.mistakes > obj.updates:
            raise ModelError(f"'pa.mistakes' ({obj.mistakes}) exceeds 'pa.updates' ({obj.updates})")
        return obj


def _encode_matrix(a: np.ndarray) -> dict:
    """A float64 matrix as JSON: shape and its little-endian bytes in base64 (exact, 2.5x smaller than text)."""
    return {"shape": list(a.shape), "float64_le_base64":
            base64.b64encode(np.ascontiguousarray(a, dtype="<f8").tobytes()).decode("ascii")}


def _decode_matrix(value, shape: tuple[int, int], key: str) -> np.ndarray:
    """Inverse of :func:`_encode_matrix`, checked: the shape, the byte count, finite values."""
    if not isinstance(value, dict) or not isinstance(value.get("float64_le_base64"), str):
        raise ModelError(f"'{key}' must be an object with 'shape' and 'float64_le_base64'")
    if value.get("shape") != list(shape):
        raise ModelError(f"'{key}' has shape {value.get('shape')!r}, expected {list(shape)}")
    try:
        raw = base64.b64decode(value["float64_le_base64"], validate=True)
    except (ValueError, binascii.Error):
        raise ModelError(f"'{key}' is not valid base64") from None
    if len(raw) != 8 * shape[0] * shape[1]:
        raise ModelError(f"'{key}' holds {len(raw)} bytes, expected {8 * shape[0] * shape[1]}")
    arr = np.frombuffer(raw, dtype="<f8").astype(np.float64).reshape(shape)
    bad = int(np.count_nonzero(~np.isfinite(arr)))
    if bad:
        raise ModelError(f"'{key}' holds {bad} non-finite value{'s' if bad > 1 else ''}")
    return arr


def _integer(state: dict, key: str, where: str, minimum: int, default: int | None = None) -> int:
    value = state.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int):
        raise ModelError(f"'{where}.{key}' must be an integer, not {value!r}")
    if value < minimum:
        raise ModelError(f"'{where}.{key}' must be at least {minimum}, not {value}")
    return value


def _number(state: dict, key: str, where: str) -> float:
    value = state.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise ModelError(f"'{where}.{key}' must be a finite number, not {value!r}")
    return float(value)


def _matrix(value, shape: tuple[int, ...], key: str) -> np.ndarray:
    """``value`` as a finite float64 array of exactly ``shape`` (never reshaped)."""
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ModelError(f"'{key}' must be numbers of shape {shape}") from None
    if len(shape) == 2 and shape[0] == 0 and arr.size == 0:
        arr = arr.reshape(shape)  # no class yet: [] is the empty matrix
    if arr.shape != shape:
        raise ModelError(f"'{key}' has shape {arr.shape}, expected {shape}")
    bad = int(np.count_nonzero(~np.isfinite(arr)))
    if bad:
        raise ModelError(f"'{key}' holds {bad} non-finite value{'s' if bad > 1 else ''}")
    return arr


def _scaler_from_state(state) -> FeatureScaler:
    """:meth:`FeatureScaler.from_state`, checked (labels, flags, statistics of the labels' length)."""
    if not isinstance(state, dict):
        raise ModelError(f"'scaler' must be an object, not {type(state).__name__}")
    labels = state.get("labels")
    if not isinstance(labels, list) or not labels or not all(isinstance(x, str) and x for x in labels):
        raise ModelError("'scaler.labels' must be a non-empty list of descriptor labels")
    if len(set(labels)) != len(labels):
        raise ModelError("'scaler.labels' names a descriptor value more than once")
    for key in ("log_activity", "standardize"):
        if not isinstance(state.get(key), bool):
            raise ModelError(f"'scaler.{key}' must be true or false, not {state.get(key)!r}")
    std = state.get("standardizer")
    if not isinstance(std, dict):
        raise ModelError("'scaler.standardizer' must be an object")
    n = len(labels)
    obj = FeatureScaler(labels, state["log_activity"], state["standardize"])
    st = obj.standardizer
    st.n = _integer(std, "n", "scaler.standardizer", minimum=0)
    st.mean = _matrix(std.get("mean"), (n,), "scaler.standardizer.mean")
    st.m2 = _matrix(std.get("m2"), (n,), "scaler.standardizer.m2")
    if np.any(st.m2 < 0):
        raise ModelError("'scaler.standardizer.m2' holds negative sums of squares")
    st.min_std = _number(std, "min_std", "scaler.standardizer") if "min_std" in std else st.min_std
    if st.min_std < 0:
        raise ModelError(f"'scaler.standardizer.min_std' must not be negative, not {st.min_std}")
    return obj


class OnlineClassifier:
    """Feature scaling plus PA-I: what the classifier node runs.

    Parameters
    ----------
    labels : sequence of str
        Descriptor labels (fix the feature layout; a model refuses other layouts).
    eta : float, default 1.0
    log_activity, standardize : bool
        See :class:`~.scaling.FeatureScaler`.
    update : {"prediction", "max_loss", "arow"}, default "prediction"
    average : bool, default False
    r_per_feature : float, default :data:`AROW_R_PER_FEATURE`
        See :class:`PassiveAggressive`.
    """

    def __init__(self, labels: Sequence[str], eta: float = 1.0, log_activity: bool = True,
                 standardize: bool = True, update: str = "prediction", average: bool = False,
                 r_per_feature: float = AROW_R_PER_FEATURE) -> None:
        self.scaler = FeatureScaler(labels, log_activity, standardize)
        self.pa = PassiveAggressive(len(self.scaler.labels), eta, update, average, r_per_feature)
        self.version = 0

    @property
    def labels(self) -> tuple[str, ...]:
        return self.scaler.labels

    @property
    def classes(self) -> list[str]:
        return self.pa.classes

    def observe(self, values: np.ndarray) -> None:
        """Update the running feature statistics with an unlabelled descriptor."""
        self.scaler.partial_fit(values)

    def predict(self, values: np.ndarray) -> tuple[str | None, np.ndarray]:
        """Predicted class (None without classes) and per-class scores."""
        z = self.scaler.transform(values)
        if not self.pa.classes:
            return None, np.zeros(0)
        s = self.pa.scores(z)
        return self.pa.classes[int(np.argmax(s))], s

    def learn(self, values: np.ndarray, label: str) -> float:
        """PA-I update with a labelled descriptor; returns the loss."""
        loss = self.pa.partial_fit(self.scaler.transform(values), label)
        self.version += 1
        return loss

    def state(self) -> dict:
        return {"format": _FORMAT, "format_version": _FORMAT_VERSION, "version": self.version,
                "scaler": self.scaler.state(), "pa": self.pa.state()}

    @classmethod
    def from_state(cls, state: dict) -> OnlineClassifier:
        """Rebuild from :meth:`state`; every field is checked.

        Raises
        ------
        ModelError
            Naming the key, for anything a model written by :meth:`save`
            cannot hold: another format, non-finite weights or statistics,
            a class named twice, negative counts, arrays of the wrong shape
            (e.g. a scaler for another number of descriptor values).
        """
        if not isinstance(state, dict):
            raise ModelError(f"not a model of this package (a JSON {type(state).__name__}, not an object)")
        if state.get("format") != _FORMAT or state.get("format_version") not in _READABLE_VERSIONS:
            raise ModelError(f"not a model of this package (format {state.get('format')!r} "
                             f"v{state.get('format_version')!r}, expected {_FORMAT!r} v"
                             f"{' or v'.join(map(str, _READABLE_VERSIONS))})")
        for key in ("version", "scaler", "pa"):
            if key not in state:
                raise ModelError(f"'{key}' is missing")
        obj = cls.__new__(cls)
        obj.scaler = _scaler_from_state(state["scaler"])
        obj.pa = PassiveAggressive.from_state(state["pa"])
        obj.version = _integer(state, "version", "model", minimum=0)
        if obj.pa.n_features != len(obj.scaler.labels):
            raise ModelError(f"'pa.n_features' ({obj.pa.n_features}) differs from the scaler's "
                             f"{len(obj.scaler.labels)} descriptor labels")
        return obj

    def delta(self, classes_before: int) -> dict:
        """What the last :meth:`learn` changed, exactly, as plain JSON-ready data.

        The two weight rows of eq. 31 and their averaging sums, the classes
        added since the model had ``classes_before`` of them, the counters and
        the feature statistics: :meth:`apply_delta` on the model as it was
        before that :meth:`learn` gives this model bit for bit.  The model
        store journals one delta per label instead of rewriting the model.
        """
        pa = self.pa
        rows = sorted(set(pa.changed_rows) | set(range(classes_before, len(pa.classes))))
        std = self.scaler.standardizer
        out = {"version": self.version, "new_classes": pa.classes[classes_before:], "rows": rows,
               "weights": pa.weights[rows].tolist(), "weighted_sum": pa._u[rows].tolist(),
               "updates": pa.updates, "mistakes": pa.mistakes,
               "scaler": {"n": std.n, "mean": std.mean.tolist(), "m2": std.m2.tolist()}}
        if pa.covariance_step is not None:  # AROW: the rank-one step of the covariance, replayed as computed
            beta, sx = pa.covariance_step
            out["covariance_step"] = {"beta": beta, "vector": sx.tolist()}
        return out

    def apply_delta(self, delta: dict) -> None:
        """Apply one :meth:`delta` (checked like a model state: versions, shapes, finite values, counts).

        Raises
        ------
        ModelError
            Naming the key, for a delta this model cannot take (e.g. not the
            next version); the model is then unchanged.
        """
        if not isinstance(delta, dict):
            raise ModelError("an entry must be an object")
        version = _integer(delta, "version", "entry", minimum=1)
        if version != self.version + 1:
            raise ModelError(f"entry of version {version} does not follow version {self.version}")
        pa = self.pa
        new = delta.get("new_classes")
        if not isinstance(new, list) or not all(isinstance(c, str) and c for c in new):
            raise ModelError("'new_classes' must be a list of class names")
        known = set(pa.classes)
        if any(name in known for name in new) or len(set(new)) != len(new):
            raise ModelError(f"'new_classes' adds {new!r}, of which some are already classes")
        n_classes = len(pa.classes) + len(new)
        rows = delta.get("rows")
        if not isinstance(rows, list) or not all(isinstance(r, int) and not isinstance(r, bool)
                                                 and 0 <= r < n_classes for r in rows):
            raise ModelError(f"'rows' must be class indices below {n_classes}")
        width = pa.n_features + 1
        weights = _matrix(delta.get("weights"), (len(rows), width), "weights")
        weighted = _matrix(delta.get("weighted_sum"), (len(rows), width), "weighted_sum")
        updates = _integer(delta, "updates", "entry", minimum=pa.updates)
        mistakes = _integer(delta, "mistakes", "entry", minimum=pa.mistakes)
        if mistakes > updates:
            raise ModelError(f"'mistakes' ({mistakes}) exceeds 'updates' ({updates})")
        sc = delta.get("scaler")
        if not isinstance(sc, dict):
            raise ModelError("'scaler' must be an object")
        n = len(self.labels)
        std = self.scaler.standardizer
        count = _integer(sc, "n", "scaler", minimum=std.n)
        mean = _matrix(sc.get("mean"), (n,), "scaler.mean")
        m2 = _matrix(sc.get("m2"), (n,), "scaler.m2")
        if np.any(m2 < 0):
            raise ModelError("'scaler.m2' holds negative sums of squares")
        step = delta.get("covariance_step")
        if step is not None:
            if pa.covariance is None:
                raise ModelError(f"'covariance_step' given for the {pa.update!r} update, which has no covariance")
            if not isinstance(step, dict):
                raise ModelError("'covariance_step' must be an object")
            beta = _number(step, "beta", "covariance_step")
            sx = _matrix(step.get("vector"), (width,), "covariance_step.vector")
        for name in new:  # everything checked: now change the model
            pa.add_class(name)
        pa.weights[rows] = weights
        pa._u[rows] = weighted
        if step is not None:
            pa.covariance -= beta * np.outer(sx, sx)
        pa.updates, pa.mistakes = updates, mistakes
        std.n, std.mean, std.m2 = count, mean, m2
        self.version = version
