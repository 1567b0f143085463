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
"""

from __future__ import annotations

from collections import Counter, OrderedDict
from dataclasses import dataclass
from typing import Generic, TypeVar

from ..errors import ConfigError

__all__ = ["LabelDecision", "LabelProtocol", "LEARN", "HELD", "REFUSED", "EXPIRED", "REFUSAL_REASONS",
           "DEFAULT_MAX_CLASS_NAME_CHARS"]

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

    # ------------------------------------------------------------ descriptors
    def add_descriptor(self, exploration_id: int, item: T) -> list[LabelDecision[T]]:
        """Register a descriptor *after* it was predicted; return what to do now.

        The list holds, in order, the held label of this exploration (``learn``)
        and any held labels that expire because of it (``expired``).
        """
        eid = int(exploration_id)
        self._serial += 1
        kept = _Kept(self._serial, eid, item)
        self._latest = kept
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
    def add_label(self, exploration_id: int, class_name: str) -> LabelDecision[T]:
        """Decide what a label does (``learn`` now, ``held``, or ``refused``)."""
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
        kept = self._latest if eid == 0 else self._kept.get(eid)
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
