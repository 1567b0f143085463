"""The label protocol of the online classifier: which descriptor a label teaches, and when.

A label names an exploration id (0 = the most recent descriptor) and a class
name.  The classifier predicts every descriptor first and learns from its
label afterwards (Kaboli et al. 2018, section VI-A: predict, then update with
eq. 30-32), so labels and descriptors meet in either order.
:class:`LabelProtocol` decides, from the order of the calls alone (no clock,
no ROS), what every label does:

* **Late label** (its descriptor already seen): learned at once, if the
  descriptor is among the last ``horizon`` kept (or it is the most recent
  one, for id 0).
* **Early label** (an exploration not seen yet, and fewer than
  ``expiry_explorations`` ids behind the latest seen): held, and learned
  right after that exploration's descriptor is predicted, so the
  prediction stays honest.  At most ``horizon`` labels are held.
* **Expiry**: a held label expires once a descriptor ``expiry_explorations``
  ids past it has arrived (exploration ids only grow, so the exploration it
  names was dropped, e.g. too short, or never comes); it is counted
  (``label_expired``) and reported.  A label whose exploration is already
  that far behind is refused at once (``unknown_exploration``).
* **Duplicates**: the first label of a descriptor wins.  A second label for
  the same descriptor (the same exploration, or id 0 naming a descriptor
  already labelled) is refused and counted (``duplicate_label`` for the same
  class, ``conflicting_label`` for another class): an online update cannot
  be taken back, and learning one touch twice would weigh it double.  Reset
  the model to relabel.
* **Class names**: stripped of surrounding white space; an empty name, one
  longer than ``max_class_name_chars`` characters or one with
  non-printable characters is refused and counted (``empty_label``,
  ``class_name_too_long``, ``bad_class_name``).

Every label ends in exactly one of: learned, held (and later learned or
expired), or refused with a counter; :attr:`LabelProtocol.counts` holds the
counters.  The protocol is deterministic: the same calls in the same order
give the same decisions.

:class:`StampOrder` makes the order of the calls that of the stamps, so
that a replay gives the same predictions and updates however a label and a
descriptor that arrive together are served: descriptors are predicted and
labels applied in the order of their stamps (window end, label header), each
waiting a bounded time for what may still come before it.
"""

from __future__ import annotations

from bisect import insort
from collections import Counter, OrderedDict, deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Generic, TypeVar

from ..errors import ConfigError

__all__ = ["LabelDecision", "LabelProtocol", "StampOrder", "LEARN", "HELD", "REFUSED", "EXPIRED",
           "REFUSAL_REASONS", "DEFAULT_MAX_CLASS_NAME_CHARS", "DEFAULT_LABEL_WAIT_S"]

T = TypeVar("T")

#: What a decision asks of the caller.
LEARN, HELD, REFUSED, EXPIRED = "learn", "held", "refused", "expired"

#: Counter names of refused labels.
REFUSAL_REASONS: tuple[str, ...] = ("empty_label", "class_name_too_long", "bad_class_name", "unknown_exploration",
                                    "duplicate_label", "conflicting_label", "held_full")

#: Longest class name accepted by default (characters).
DEFAULT_MAX_CLASS_NAME_CHARS = 64


@dataclass(frozen=True)
class LabelDecision(Generic[T]):
    """What to do with one label.

    Attributes
    ----------
    action : {"learn", "held", "refused", "expired"}
        ``learn``: learn ``item`` as ``class_name`` now; ``held``: nothing yet;
        ``refused`` / ``expired``: nothing, counted under ``reason``.
    exploration_id : int
        The id the label named (0 = the most recent).
    class_name : str
        The class name, stripped.
    item : object or None
        The descriptor (whatever the caller passed to
        :meth:`LabelProtocol.add_descriptor`) to learn, for ``learn``.
    reason : str or None
        Counter name of a refusal or expiry.
    message : str
        One line for a log.
    """

    action: str
    exploration_id: int
    class_name: str
    item: T | None = None
    reason: str | None = None
    message: str = ""


@dataclass
class _Kept(Generic[T]):
    serial: int
    exploration_id: int
    item: T
    learned_as: str | None = None
    stamp_ns: int = 0


class LabelProtocol(Generic[T]):
    """Match labels to descriptors (see the module docstring for the rules).

    Parameters
    ----------
    horizon : int, default 100
        Descriptors kept for late labels, and most labels held for early ones.
    expiry_explorations : int, default 10
        A held label expires when a descriptor this many ids past it arrives.
        With several window nodes interleaving ids (``exploration_id_stride``)
        choose it above the stride.
    max_class_name_chars : int, default 64
        Longest class name accepted.

    Raises
    ------
    ConfigError
        For a horizon, expiry or name limit below 1.
    """

    def __init__(self, horizon: int = 100, expiry_explorations: int = 10,
                 max_class_name_chars: int = DEFAULT_MAX_CLASS_NAME_CHARS) -> None:
        for key, value in (("label_horizon", horizon), ("label_expiry_explorations", expiry_explorations),
                           ("max_class_name_chars", max_class_name_chars)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(f"must be an integer >= 1, got {value!r}", key=key)
        self.horizon = horizon
        self.expiry_explorations = expiry_explorations
        self.max_class_name_chars = max_class_name_chars
        self.counts: Counter[str] = Counter()
        self.reset()

    def reset(self) -> None:
        """Forget every descriptor and held label (the counters stay)."""
        self._kept: OrderedDict[int, _Kept[T]] = OrderedDict()  # exploration id -> descriptor
        self._latest: _Kept[T] | None = None
        self._previous: _Kept[T] | None = None  # the descriptor before the latest
        self._recent: deque[_Kept[T]] = deque(maxlen=self.horizon)  # every kept one, for stamped id-0 labels
        self._latest_id = 0
        self._serial = 0
        self._held: OrderedDict[int, str] = OrderedDict()  # exploration id -> class name

    def set_horizon(self, horizon: int) -> int:
        """Change the horizon while running; a smaller one forgets the oldest kept descriptors now.

        Held labels beyond the new horizon are dropped and counted
        (``label_dropped_by_horizon``), never silently.  Returns how many were dropped.

        Raises
        ------
        ConfigError
            For a horizon below 1.
        """
        if isinstance(horizon, bool) or not isinstance(horizon, int) or horizon < 1:
            raise ConfigError(f"must be an integer >= 1, got {horizon!r}", key="label_horizon")
        self.horizon = horizon
        self._recent = deque(self._recent, maxlen=horizon)
        while len(self._kept) > horizon:
            self._kept.popitem(last=False)
        dropped = 0
        while len(self._held) > horizon:
            self._held.popitem(last=False)
            dropped += 1
        self.counts["label_dropped_by_horizon"] += dropped
        return dropped

    @property
    def held(self) -> int:
        """Labels held for explorations not seen yet."""
        return len(self._held)

    @property
    def kept(self) -> int:
        """Descriptors kept for late labels."""
        return len(self._kept)

    @property
    def latest(self) -> tuple[int, int, bool] | None:
        """The most recent descriptor as ``(exploration_id, stamp_ns, labelled)``, None before any."""
        k = self._latest
        return None if k is None else (k.exploration_id, k.stamp_ns, k.learned_as is not None)

    @property
    def awaits_label(self) -> bool:
        """Whether a label for the most recent exploration is due: it has none yet, and labels are being
        given (the exploration before it was labelled, or there was none since the start or a reset).

        Fixed windows (exploration id 0) await nothing.
        """
        latest, previous = self._latest, self._previous
        return (latest is not None and latest.exploration_id != 0 and latest.learned_as is None
                and (previous is None or previous.learned_as is not None))

    def target(self, exploration_id: int, stamp_ns: int = 0) -> tuple[int, int, bool] | None:
        """The descriptor a label would teach now, as :attr:`latest` gives it (None: none seen, or not kept).

        A stamped label with id 0 names the most recent descriptor whose stamp is at or before the label's;
        a stamp before every kept descriptor (another clock) is ignored.
        """
        k = self._find(int(exploration_id), int(stamp_ns))
        return None if k is None else (k.exploration_id, k.stamp_ns, k.learned_as is not None)

    def _find(self, eid: int, stamp_ns: int) -> _Kept[T] | None:
        if eid:
            return self._kept.get(eid)
        if stamp_ns > 0:
            for kept in reversed(self._recent):
                if kept.stamp_ns <= stamp_ns:
                    return kept
        return self._latest

    # ------------------------------------------------------------ descriptors
    def add_descriptor(self, exploration_id: int, item: T, stamp_ns: int = 0) -> list[LabelDecision[T]]:
        """Register a descriptor *after* it was predicted; return what to do now.

        The list holds, in order, the held label of this exploration (``learn``)
        and any held labels that expire because of it (``expired``).  ``stamp_ns``
        (the window end) lets a stamped label with id 0 find it.
        """
        eid = int(exploration_id)
        self._serial += 1
        kept = _Kept(self._serial, eid, item, stamp_ns=int(stamp_ns))
        self._previous, self._latest = self._latest, kept
        self._recent.append(kept)
        out: list[LabelDecision[T]] = []
        if eid:
            self._latest_id = max(self._latest_id, eid)
            previous = self._kept.pop(eid, None)
            if previous is not None:
                kept.learned_as = previous.learned_as  # the same exploration again: still labelled
            self._kept[eid] = kept
            while len(self._kept) > self.horizon:
                self._kept.popitem(last=False)
            name = self._held.pop(eid, None)
            if name is not None:
                out.append(self._learn(kept, name, eid))
        for held_id in [h for h in self._held if self._latest_id - h >= self.expiry_explorations]:
            name = self._held.pop(held_id)
            self.counts["label_expired"] += 1
            out.append(LabelDecision(EXPIRED, held_id, name, reason="label_expired", message=(
                f"label {name!r} for exploration {held_id} expired: exploration {self._latest_id} arrived and "
                f"{held_id} never did")))
        return out

    # ----------------------------------------------------------------- labels
    def add_label(self, exploration_id: int, class_name: str, stamp_ns: int = 0) -> LabelDecision[T]:
        """Decide what a label does (``learn`` now, ``held``, or ``refused``).

        With id 0 and a ``stamp_ns`` (the label's header stamp), the label names the most recent descriptor
        stamped at or before it (see :meth:`target`); unstamped (0), the most recent descriptor.
        """
        eid = int(exploration_id)
        name = str(class_name).strip()
        where = f"exploration {eid}" if eid else "the most recent exploration"
        if not name:
            return self._refuse("empty_label", eid, name, f"label for {where} has an empty class name")
        if len(name) > self.max_class_name_chars:
            return self._refuse("class_name_too_long", eid, name[:self.max_class_name_chars],
                                f"label for {where}: class name of {len(name)} characters (at most "
                                f"{self.max_class_name_chars}): {name[:self.max_class_name_chars]!r}...")
        if not name.isprintable():
            return self._refuse("bad_class_name", eid, name,
                                f"label for {where}: class name {name!r} has non-printable characters")
        kept = self._find(eid, int(stamp_ns))
        if kept is not None:
            return self._learn(kept, name, eid)
        if eid == 0:
            return self._refuse("unknown_exploration", eid, name,
                                f"label {name!r} for the most recent exploration: no descriptor yet")
        if eid in self._held:
            first = self._held[eid]
            reason = "duplicate_label" if first == name else "conflicting_label"
            return self._refuse(reason, eid, name, f"label {name!r} for exploration {eid}: already labelled "
                                                   f"{first!r} (the first label wins)")
        if eid <= self._latest_id - self.expiry_explorations:
            return self._refuse("unknown_exploration", eid, name,
                                f"label {name!r} for exploration {eid}: no such descriptor with contact among the "
                                f"last {self.horizon} kept (latest {self._latest_id})")
        if len(self._held) >= self.horizon:
            return self._refuse("held_full", eid, name, f"label {name!r} for exploration {eid}: already "
                                                        f"{len(self._held)} labels held for explorations not seen")
        self._held[eid] = name
        self.counts["early_labels"] += 1
        return LabelDecision(HELD, eid, name, message=f"label {name!r} for exploration {eid} held until it arrives")

    def _learn(self, kept: _Kept[T], name: str, eid: int) -> LabelDecision[T]:
        if kept.learned_as is not None:
            reason = "duplicate_label" if kept.learned_as == name else "conflicting_label"
            what = f"exploration {kept.exploration_id}" if kept.exploration_id else "the most recent descriptor"
            return self._refuse(reason, eid, name, f"label {name!r} for {what}: already learned as "
                                                   f"{kept.learned_as!r} (the first label wins)")
        kept.learned_as = name
        self.counts["labels_learned"] += 1
        return LabelDecision(LEARN, eid, name, item=kept.item)

    def _refuse(self, reason: str, eid: int, name: str, message: str) -> LabelDecision[T]:
        self.counts[reason] += 1
        return LabelDecision(REFUSED, eid, name, reason=reason, message=message + "; refused")


#: How long a descriptor or a stamped label waits, at most, for what comes before it in stamp order [s].
DEFAULT_LABEL_WAIT_S = 2.0

K = TypeVar("K")


@dataclass
class _Waiting(Generic[T]):
    stamp_ns: int
    kind: int  # 0: descriptor, 1: label (a descriptor goes before a label of the same stamp: predict first)
    serial: int
    arrival_s: float
    exploration_id: int
    descriptor: T | None = None
    class_name: str = ""


class StampOrder(Generic[T, K]):
    """Predict descriptors and apply labels in the order of their stamps, whatever order they arrive in.

    A descriptor's stamp is its window end, a label's its header stamp.  The
    outcome is that of taking every descriptor and label in stamp order
    (a descriptor before a label of the same stamp):

    * a descriptor is predicted with the model that learned every label
      stamped before its window end and none stamped after it;
    * a stamped label with id 0 names the most recent exploration whose
      window ended at or before the label's stamp
      (:meth:`LabelProtocol.target`).

    Nothing says when a message still in flight will come, so each one
    waits (at most ``wait_s``, counted when it runs out) only while
    something may still come before it:

    * a **descriptor** waits while a label for the exploration before it is
      due (:attr:`LabelProtocol.awaits_label`: labels are being given and
      that exploration has none yet), unless a label stamped at or after
      its window end has arrived (labels come in stamp order);
    * a **stamped label** waits while the descriptor it names may be in
      flight: id 0 whose most recent descriptor up to its stamp is already
      labelled (or there is none), or an id naming a kept exploration
      older than the most recent one; unless a descriptor whose window
      ended after the label's stamp has arrived (descriptors come in stamp
      order);
    * an **unstamped label** (stamp 0) is applied when it arrives.

    So the result does not depend on which of two messages ready together
    is served first, as long as descriptors come in stamp order (one
    window node), labels too, and each arrives within ``wait_s`` of what it
    waits for.  Pure: the caller passes the time (any monotonic clock, in
    seconds) and calls :meth:`poll` now and then.

    Parameters
    ----------
    protocol : LabelProtocol
        Decides what each label does; it keeps what ``predict`` returns.
    predict : callable
        ``predict(descriptor) -> kept``: predict (and publish) one descriptor;
        return what the protocol keeps for its label, or None to skip it.
    apply : callable
        ``apply(decision)``: carry out one :class:`LabelDecision` (learn, or
        report a refusal or expiry), before anything later is predicted.
    wait_s : float, default 2.0
        Longest wait; 0 takes everything in arrival order.

    Raises
    ------
    ConfigError
        For a negative or non-finite ``wait_s``.
    """

    def __init__(self, protocol: LabelProtocol[K], predict: Callable[[T], K | None],
                 apply: Callable[[LabelDecision[K]], None], wait_s: float = DEFAULT_LABEL_WAIT_S) -> None:
        self.protocol = protocol
        self._predict = predict
        self._apply = apply
        self.wait_s = self._check_wait(wait_s)
        #: ``descriptor_wait_expired`` / ``label_wait_expired``: released because their wait ran out;
        #: ``labels_dropped_by_reset``: labels waiting when the model was reset.
        self.counts: Counter[str] = Counter()
        self._waiting: list[_Waiting[T]] = []
        self._serial = 0
        self._label_mark = -1        # latest stamp of a stamped label received
        self._descriptor_mark = -1   # latest window end of a descriptor received

    @staticmethod
    def _check_wait(wait_s: float) -> float:
        if isinstance(wait_s, bool) or not isinstance(wait_s, (int, float)) or not 0 <= wait_s < float("inf"):
            raise ConfigError(f"must be a finite number >= 0, got {wait_s!r}", key="label_wait_s")
        return float(wait_s)

    def set_wait(self, wait_s: float) -> None:
        """Change the longest wait (from the next :meth:`poll` on)."""
        self.wait_s = self._check_wait(wait_s)

    @property
    def waiting(self) -> int:
        """Descriptors and labels waiting for what comes before them."""
        return len(self._waiting)

    def reset(self) -> None:
        """After a model reset: drop the waiting labels (counted) and forget the stamps seen (a new
        session, a bag replayed again, may start earlier); waiting descriptors stay."""
        labels = [w for w in self._waiting if w.kind]
        self.counts["labels_dropped_by_reset"] += len(labels)
        self._waiting = [w for w in self._waiting if not w.kind]
        self._label_mark = -1
        self._descriptor_mark = max((w.stamp_ns for w in self._waiting), default=-1)

    # ------------------------------------------------------------------ input
    def add_descriptor(self, exploration_id: int, stamp_ns: int, descriptor: T, now_s: float) -> None:
        """A descriptor arrived (``stamp_ns``: its window end); predict what is due."""
        stamp = int(stamp_ns)
        self._descriptor_mark = max(self._descriptor_mark, stamp)
        self._enqueue(_Waiting(stamp, 0, 0, now_s, int(exploration_id), descriptor=descriptor))
        self.poll(now_s)

    def add_label(self, exploration_id: int, class_name: str, stamp_ns: int, now_s: float) -> None:
        """A label arrived (``stamp_ns``: its header stamp, 0 = none); apply what is due."""
        stamp = int(stamp_ns)
        if stamp <= 0:
            self._apply(self.protocol.add_label(exploration_id, class_name))
        else:
            self._label_mark = max(self._label_mark, stamp)
            self._enqueue(_Waiting(stamp, 1, 0, now_s, int(exploration_id), class_name=class_name))
        self.poll(now_s)

    def poll(self, now_s: float) -> None:
        """Predict and apply, in stamp order, everything whose turn has come or whose wait ran out."""
        while self._waiting:
            head = self._waiting[0]
            due = self._due(head)
            if not due:
                if now_s - head.arrival_s < self.wait_s and len(self._waiting) <= self.protocol.horizon:
                    return
                self.counts["label_wait_expired" if head.kind else "descriptor_wait_expired"] += 1
            self._waiting.pop(0)
            if head.kind:
                self._apply(self.protocol.add_label(head.exploration_id, head.class_name, head.stamp_ns))
                continue
            kept = self._predict(head.descriptor)
            if kept is not None:
                for decision in self.protocol.add_descriptor(head.exploration_id, kept, head.stamp_ns):
                    self._apply(decision)

    # --------------------------------------------------------------- internal
    def _enqueue(self, item: _Waiting[T]) -> None:
        self._serial += 1
        item.serial = self._serial
        insort(self._waiting, item, key=lambda w: (w.stamp_ns, w.kind, w.serial))

    def _due(self, head: _Waiting[T]) -> bool:
        """Whether nothing can still come before ``head`` in stamp order (see the class docstring)."""
        if self.wait_s == 0:
            return True
        if not head.kind:
            return self._label_mark >= head.stamp_ns or not self.protocol.awaits_label
        if self._descriptor_mark > head.stamp_ns:
            return True
        target = self.protocol.target(head.exploration_id, head.stamp_ns)
        if head.exploration_id == 0:
            return target is not None and not target[2]
        latest = self.protocol.latest
        return target is None or target[2] or (latest is not None and target[0] == latest[0])
