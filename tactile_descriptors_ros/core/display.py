"""What the views show, once per display period: each body part's contact and cells, and the predictions (pure).

The contact node (rviz2 markers and images, ``tactile/contacts``) and
``tactile view`` (live or from a bag) draw from the same objects:

* :class:`PartDisplay` collects a body part's samples over a display period
  (:class:`~.contact.ContactWindow`) and at each tick gives a
  :class:`DisplayFrame`: the contact of the period, each cell's latest force
  (a cell without a sample this period keeps its last one), and which cells
  are stale (no valid sample for ``stale_s`` of sensor time, or the whole
  body part silent for ``stale_s`` of wall time);
* :class:`PredictionHistory` keeps the predictions with their confidence,
  which body parts were touching, and the labels given afterwards.

The confidence of a prediction is the softmax of the classifier's scores
(:func:`softmax_confidence`): a relative measure among the known classes,
not a calibrated probability.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from .contact import CellReduction, ContactEstimate, ContactWindow, RunReductions, locate_contact
from .geometry import Taxels

__all__ = ["DisplayFrame", "PartDisplay", "softmax_confidence", "PredictionEntry", "PredictionHistory"]


@dataclass(frozen=True)
class DisplayFrame:
    """One body part over one display period.

    Attributes
    ----------
    contact : ContactEstimate
        From the cells' latest forces, stale cells left out.
    cell_stale, taxel_stale : numpy.ndarray of bool
        Per cell and per sensing point.
    start_ns, end_ns : int
        Oldest and newest force sample of the period (sensor time); -1 when
        the period brought none.
    """

    contact: ContactEstimate
    cell_stale: np.ndarray
    taxel_stale: np.ndarray
    start_ns: int
    end_ns: int


class PartDisplay:
    """One body part as the views show it (see the module docstring).

    Parameters
    ----------
    taxels : Taxels
    cell_ids : sequence of int
        The body part's cells in the robot description's order.
    n_deformation : int
    threshold_n, floor_n : float
        As :func:`~.contact.locate_contact`.
    stale_s : float
    """

    def __init__(self, taxels: Taxels, cell_ids: Sequence[int], n_deformation: int, *, threshold_n: float,
                 floor_n: float, stale_s: float) -> None:
        self.taxels = taxels
        self.window = ContactWindow(cell_ids, n_deformation)
        self.threshold_n = float(threshold_n)
        self.floor_n = float(floor_n)
        self.stale_s = float(stale_s)
        self.cell_force = np.full(self.window.cell_ids.size, np.nan)
        self.site_change = np.full(len(taxels), np.nan) if taxels.kind == "sites" else None
        self.last_wall_s = -math.inf
        index = {int(c): k for k, c in enumerate(self.window.cell_ids)}
        self._owner = np.array([index[int(c)] for c in taxels.cell_ids], dtype=np.intp)

    def add(self, cell_id: int, reduction: CellReduction, wall_s: float) -> None:
        """One cell's samples of one message, received at ``wall_s`` (a monotonic clock)."""
        if self.window.add(cell_id, reduction):
            self.last_wall_s = wall_s

    def add_runs(self, runs: RunReductions, wall_s: float) -> None:
        """Several cell runs of one message (:func:`~.contact.reduce_skin_runs`), received at ``wall_s``."""
        if self.window.add_runs(runs) < runs.cell_ids.size:
            self.last_wall_s = wall_s

    def merge(self, window: ContactWindow, wall_s: float) -> None:
        """A window of this body part's cells already filled (one message's), received at ``wall_s``.

        The same as :meth:`add` or :meth:`add_runs` of what filled it, without
        reducing the samples twice (:meth:`~.contact.ContactWindow.merge`).
        """
        if self.window.merge(window):
            self.last_wall_s = wall_s

    def tick(self, now_ns: int, wall_s: float) -> DisplayFrame:
        """Close the display period: the frame to show, then start the next period.

        Parameters
        ----------
        now_ns : int
            The newest sensor stamp of the robot (every body part's), for staleness.
        wall_s : float
            Now on the clock :meth:`add` was given.
        """
        w = self.window
        forces = w.cell_force_n()
        fresh = np.isfinite(forces)
        self.cell_force[fresh] = forces[fresh]
        if self.site_change is not None:
            change = w.site_change(self.taxels)
            ok = np.isfinite(change)
            self.site_change[ok] = change[ok]
        stale = w.stale(now_ns, self.stale_s)
        if wall_s - self.last_wall_s > self.stale_s:
            stale = np.ones_like(stale)
        shown = np.where(stale, np.nan, self.cell_force)
        est = locate_contact(self.taxels, w.cell_ids, shown, self.site_change, threshold_n=self.threshold_n,
                             floor_n=self.floor_n, vibration_rms=w.vibration_rms())
        frame = DisplayFrame(est, stale, stale[self._owner], w.start_ns, w.end_ns)
        w.reset()
        return frame


def softmax_confidence(scores: Sequence[float]) -> np.ndarray:
    """Softmax of the classifier's scores ``w_y . x`` (eq. 30): relative confidence per class, summing to 1.

    Empty for no scores; NaN scores give NaN.
    """
    s = np.asarray(scores, dtype=float)
    if s.size == 0:
        return s
    e = np.exp(s - np.max(s))
    return e / e.sum()


@dataclass
class PredictionEntry:
    """One prediction as the views list it."""

    exploration_id: int
    window_end_ns: int
    class_name: str
    confidence: float
    has_model: bool
    body_parts: tuple[str, ...] = ()
    label: str = ""

    @property
    def correct(self) -> bool | None:
        """Whether the label given afterwards names the predicted class (None before a label or a model)."""
        if not self.label or not self.has_model:
            return None
        return self.label == self.class_name

    def to_dict(self) -> dict:
        return {"exploration_id": self.exploration_id, "window_end_s": self.window_end_ns / 1e9,
                "class_name": self.class_name, "confidence": self.confidence, "has_model": self.has_model,
                "body_parts": list(self.body_parts), "label": self.label, "correct": self.correct}


@dataclass
class PredictionHistory:
    """The latest predictions, their touching body parts (from the descriptors) and their labels.

    Parameters
    ----------
    size : int
        Predictions kept.
    """

    size: int = 50
    entries: OrderedDict = field(default_factory=OrderedDict)
    _parts: OrderedDict = field(default_factory=OrderedDict)
    _labels: OrderedDict = field(default_factory=OrderedDict)
    version: int = 0

    @staticmethod
    def _key(exploration_id: int, window_end_ns: int) -> tuple[int, int]:
        # explorations by id; fixed windows (id 0) by their end
        return (int(exploration_id), 0 if exploration_id else int(window_end_ns))

    def _trim(self, d: OrderedDict) -> None:
        while len(d) > self.size:
            d.popitem(last=False)

    def descriptor(self, exploration_id: int, window_end_ns: int, body_parts: Sequence[str],
                   contact: Sequence[bool]) -> None:
        """A descriptor: which body parts were in contact in its window."""
        parts = tuple(p for p, c in zip(body_parts, contact) if c)
        key = self._key(exploration_id, window_end_ns)
        self._parts[key] = parts
        self._trim(self._parts)
        if key in self.entries:
            self.entries[key].body_parts = parts
            self.version += 1

    def prediction(self, exploration_id: int, window_end_ns: int, class_name: str, class_names: Sequence[str],
                   scores: Sequence[float], has_model: bool) -> PredictionEntry:
        """A prediction; its confidence is the softmax score of the predicted class."""
        conf = 0.0
        if has_model and class_name in list(class_names):
            p = softmax_confidence(scores)
            conf = float(p[list(class_names).index(class_name)]) if p.size == len(class_names) else 0.0
        key = self._key(exploration_id, window_end_ns)
        entry = PredictionEntry(int(exploration_id), int(window_end_ns), class_name if has_model else "", conf,
                                bool(has_model), self._parts.get(key, ()), self._labels.get(int(exploration_id), ""))
        self.entries[key] = entry
        self.entries.move_to_end(key)
        self._trim(self.entries)
        self.version += 1
        return entry

    def label(self, exploration_id: int, class_name: str) -> None:
        """A label (``exploration_id`` 0 = the latest exploration, as the classifier node reads it)."""
        eid = int(exploration_id)
        if eid == 0:
            ids = [k[0] for k in self.entries if k[0]]
            if not ids:
                return
            eid = ids[-1]
        self._labels[eid] = class_name.strip()
        self._trim(self._labels)
        for key, entry in self.entries.items():
            if key[0] == eid:
                entry.label = class_name.strip()
        self.version += 1

    @property
    def latest(self) -> PredictionEntry | None:
        return next(reversed(self.entries.values()), None) if self.entries else None

    def recent(self, n: int = 20) -> list[PredictionEntry]:
        """The last ``n`` predictions, newest first."""
        return list(reversed(list(self.entries.values())))[:n]
