"""The offline side of the live check (``tactile evaluate --live``): the same windows, the node's protocol.

The live check replays recorded trials through the window and classifier
nodes, one window per trial (its first ``n_frames`` frames, the whole
common-length crop with ``--window whole``).  This module computes what the
nodes must produce, with the evaluation's own code and no ROS:

* descriptors: :func:`~.experiments.describe_windows` and
  :func:`~.features.select_features` of those windows, exactly as
  ``tactile evaluate`` describes any window (the contact gate off, as there;
  block averaging as ``--block``, the window node's ``descriptor.block_s``);
* predictions: the classifier node's online protocol over the windows in
  replay order -- every descriptor updates the running feature statistics and
  is predicted (:meth:`~..core.learning.OnlineClassifier.observe`, then
  ``predict``); a training window's label is then matched by the node's
  :class:`~..core.labels.LabelProtocol` and learned (predict first, then
  update, paper section VI-A); a test window is only predicted.

:func:`compare` checks the live run against it: the same descriptor values
(relative tolerance), the same predicted class for every window.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from tactile_descriptors_lab.datasets.biotac_slide import BiotacRecording
from tactile_descriptors_lab.evaluation.bank import mode_groups, select_features
from tactile_descriptors_lab.evaluation.experiments import describe_windows
from tactile_descriptors_lab.evaluation.sampling import Window
from tactile_descriptors_ros.core.labels import LEARN, LabelProtocol
from tactile_descriptors_ros.core.learning import (
    RECOMMENDED_PA_AVERAGE,
    RECOMMENDED_PA_UPDATE,
    OnlineClassifier,
)
from tactile_descriptors_ros.errors import ConfigError

__all__ = ["LiveStep", "OfflineReplay", "plan_steps", "check_segmentable", "offline_replay", "compare",
           "DESCRIPTOR_RTOL"]

#: Largest relative difference allowed between a live and an offline descriptor value (float
#: round-off of the same computation on the same samples; a wrong sample moves values by far more).
DESCRIPTOR_RTOL = 1e-9


@dataclass(frozen=True)
class LiveStep:
    """One replayed window: which recording, its class name, and whether its label is taught."""

    material: int
    trial: int
    class_name: str
    train: bool


@dataclass
class OfflineReplay:
    """What the live nodes must produce, window by window (replay order)."""

    steps: list[LiveStep]
    values: np.ndarray
    labels: tuple[str, ...]
    predictions: list[str | None] = field(default_factory=list)

    @property
    def test_accuracy(self) -> float:
        """Accuracy of the test windows' predictions."""
        pairs = [(p, s.class_name) for p, s in zip(self.predictions, self.steps) if not s.train]
        return sum(p == t for p, t in pairs) / len(pairs) if pairs else float("nan")


def plan_steps(recordings: Sequence[BiotacRecording], train_trials: Sequence[int],
               test_trials: Sequence[int]) -> list[LiveStep]:
    """Steps of a replay, in the importer's default order (trial 1 of every class, then trial 2, ...).

    Every recording's trial must be in exactly one split; class names come from the recordings.

    Raises
    ------
    ConfigError
        For a trial in both splits or in neither.
    """
    train, test = set(train_trials), set(test_trials)
    both = sorted(train & test)
    if both:
        raise ConfigError(f"trials {both} are in both the training and the test split", key="trials")
    out = []
    for r in sorted(recordings, key=lambda r: (r.trial, r.material)):
        if r.trial not in train and r.trial not in test:
            raise ConfigError(f"{r.class_name} trial {r.trial} is in neither split", key="trials")
        out.append(LiveStep(int(r.material), int(r.trial), str(r.class_name), r.trial in train))
    return out


def check_segmentable(recordings: Sequence[BiotacRecording], steps: Sequence[LiveStep], n_frames: int) -> None:
    """Check that force alone delimits each window, as the live window node finds explorations.

    In the replay any PDC count above zero is contact and the zero-force gap between trials is the
    release (the recordings are tared and clipped at 0).  A window is one exploration exactly when
    every frame of it reads force: soft materials read 0 counts for up to 1.24 s inside a slide,
    never in the first 2 s of the shared recordings.

    Raises
    ------
    ConfigError
        Naming the first recording and frame where the window reads no force.
    """
    by_key = {(r.material, r.trial): r for r in recordings}
    for s in steps:
        rec = by_key[(s.material, s.trial)]
        pdc = rec.pdc[:n_frames]
        if pdc.shape[0] < n_frames:
            raise ConfigError(f"{rec.path}: {rec.n_frames} frames, shorter than the {n_frames}-frame window")
        zero = np.flatnonzero(pdc <= 0)
        if zero.size:
            raise ConfigError(f"{rec.path}: PDC reads 0 at frame {int(zero[0])} of the {n_frames}-frame window, so "
                              "the live window node would end or start an exploration there; choose a shorter "
                              "--window", key="window")


def offline_replay(recordings: Sequence[BiotacRecording], steps: Sequence[LiveStep], n_frames: int, mode: str, *,
                   pa_update: str = RECOMMENDED_PA_UPDATE, pa_average: bool = RECOMMENDED_PA_AVERAGE,
                   scaling: str = "log_standardize", cache_dir: str | None = None, jobs: int = 1,
                   block_s: float = 0.0, block_hop_s: float = 0.5) -> OfflineReplay:
    """Descriptors of each step's window (frames ``0:n_frames``) and the node protocol's predictions.

    Parameters
    ----------
    recordings : sequence of BiotacRecording
        Holding every step's (material, trial).
    steps : sequence of LiveStep
        In replay order.
    n_frames : int
        Window length in frames.
    mode : str
        Descriptor mode (:data:`~.features.DESCRIPTOR_MODES` or ``averaged``).
    pa_update, pa_average
        The classifier node's ``pa_update`` and ``pa_average``.
    scaling : {"log_standardize", "standardize", "none"}
        The classifier node's ``log_activity`` and ``standardize``.
    block_s, block_hop_s : float
        Block averaging, the window node's ``descriptor.block_s`` and
        ``descriptor.block_hop_s`` (0: one descriptor of the whole window).
    """
    if not steps:
        raise ConfigError("nothing to replay")
    windows = [Window(s.material, s.trial, 0, int(n_frames)) for s in steps]
    blocks = ({"block_frames": int(round(block_s * 100.0)), "hop_frames": int(round(block_hop_s * 100.0))}
              if block_s else {})
    bank = describe_windows(recordings, windows, cache_dir=cache_dir, jobs=jobs,
                            subwindows="subwindows" in mode_groups(mode), **blocks)
    X, labels = select_features(bank, mode, gate=False)
    # The classifier node's model (eta 1, its default) and its label protocol: each window is exploration
    # k + 1, as the window node numbers them, and a training window's label names it.
    clf = OnlineClassifier(labels, log_activity=scaling == "log_standardize", standardize=scaling != "none",
                           update=pa_update, average=pa_average)
    protocol: LabelProtocol[np.ndarray] = LabelProtocol()
    out = OfflineReplay(list(steps), X, labels)
    for k, (x, s) in enumerate(zip(X, steps)):
        clf.observe(x)
        guess, _ = clf.predict(x)
        out.predictions.append(guess)
        protocol.add_descriptor(k + 1, x)
        if s.train:
            decision = protocol.add_label(k + 1, s.class_name)
            if decision.action != LEARN:
                raise ConfigError(f"the label protocol did not learn window {k + 1}: {decision.message}")
            clf.learn(decision.item, decision.class_name)
    return out


def compare(offline: OfflineReplay, live_values: Sequence[np.ndarray] | np.ndarray, live_labels: Sequence[str],
            live_predictions: Sequence[str | None]) -> dict:
    """Live run against the offline replay: descriptor difference, prediction agreement, accuracies.

    ``live_labels`` are the live descriptor's layout labels; their quantities (the text after the last
    ``/``) must be the offline labels' in the same order.

    Returns
    -------
    dict
        JSON-ready: ``windows``, ``train_windows``, ``test_windows``, ``live_accuracy``,
        ``offline_accuracy``, ``prediction_agreement``, ``max_relative_descriptor_difference``,
        ``descriptors_match`` (within :data:`DESCRIPTOR_RTOL`), ``predictions_match``,
        ``mismatched_windows`` (the first few, for a report).
    """
    n = len(offline.steps)
    if len(live_values) != n or len(live_predictions) != n:
        raise ConfigError(f"the live run produced {len(live_values)} descriptors and {len(live_predictions)} "
                          f"predictions for {n} windows")
    # Only the quantities are compared: the prefixes (body part, feature group) differ by source.
    off_q = [lab.rsplit("/", 1)[-1] for lab in offline.labels]
    live_q = [lab.rsplit("/", 1)[-1] for lab in live_labels]
    if off_q != live_q:
        diff = next((i for i, (a, b) in enumerate(zip(off_q, live_q)) if a != b), min(len(off_q), len(live_q)))
        raise ConfigError(f"live descriptor layout ({len(live_q)} values) differs from the offline mode's "
                          f"({len(off_q)} values) at value {diff}: the window node and the evaluation describe "
                          "windows differently")
    live = np.asarray(live_values, dtype=np.float64)
    rel = np.abs(live - offline.values) / np.maximum(np.abs(offline.values), 1e-12)
    rel = np.where(np.abs(live - offline.values) <= 1e-12, 0.0, rel)  # equal zeros are equal
    agree = [a == b for a, b in zip(live_predictions, offline.predictions)]
    test = [i for i, s in enumerate(offline.steps) if not s.train]
    live_acc = (sum(live_predictions[i] == offline.steps[i].class_name for i in test) / len(test)
                if test else float("nan"))
    bad = [i for i in range(n) if not agree[i] or float(rel[i].max()) > DESCRIPTOR_RTOL]
    return {
        "windows": n,
        "train_windows": n - len(test),
        "test_windows": len(test),
        "live_accuracy": live_acc,
        "offline_accuracy": offline.test_accuracy,
        "prediction_agreement": float(np.mean(agree)),
        "max_relative_descriptor_difference": float(rel.max()),
        "descriptors_match": bool(float(rel.max()) <= DESCRIPTOR_RTOL),
        "predictions_match": bool(all(agree)),
        "mismatched_windows": [
            {"material": offline.steps[i].material, "trial": offline.steps[i].trial,
             "live": live_predictions[i], "offline": offline.predictions[i],
             "max_relative_difference": float(rel[i].max())} for i in bad[:10]],
    }
