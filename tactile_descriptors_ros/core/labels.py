"""The label protocol of the online classifier: which descriptor a label teaches, and when.

A label names an exploration id (0 = the most recent descriptor) and a class
name.  The classifier predicts every descriptor first and learns from its
label afterwards (Kaboli et al. 2018, section VI-A: predict, then update with
eq. 30-32), so labels and descriptors meet in either order.
:class:`LabelProtocol` decides, from the calls alone (no clock of its own,
no ROS), what every label does:

* **Late label** (its descriptor already seen): learned at once, if the
  descriptor is among the last ``horizon`` kept (or it is the most recent
  one, for id 0).
* **Early label** (an exploration not seen yet, fewer than
  ``expiry_explorations`` ids behind the latest seen and at most
  ``max_id_step`` ids ahead of it): held, and learned right after that
  exploration's descriptor is predicted, so the prediction stays honest.
  At most ``horizon`` labels are held.
* **Expiry**: a held label expires once a descriptor ``expiry_explorations``
  ids past it has arrived (exploration ids only grow, so the exploration it
  names was dropped, e.g. too short, or never comes), or once it has been
  held ``hold_s`` seconds (an id that is never reached); it is counted
  (``label_expired``) and reported.  A label whose exploration is already
  that far behind is refused at once (``unknown_exploration``), one more
  than ``max_id_step`` ahead too (``exploration_id_too_far``).
* **Exploration ids out of range**: a descriptor whose id is more than
  ``max_id_step`` from the latest (one spoofed id of 2^63 - 1, say) is kept
  for its own label but moves nothing (``exploration_id_out_of_range``); a
  second one right after it, within ``max_id_step`` past it, starts the ids
  anew there (``exploration_ids_rebased``: a window node restarted with
  other ids).
* **Duplicates**: the first label of a descriptor wins.  A second label for
  the same descriptor (the same exploration, or id 0 naming a descriptor
  already labelled) is refused and counted (``duplicate_label`` for the same
  class, ``conflicting_label`` for another class): an online update cannot
  be taken back, and learning one touch twice would weigh it double.
* **Class names**: NFKC-normalised (a fullwidth ``ｃｏｒｋ`` is ``cork``) and
  stripped of surrounding white space; an empty name, one longer than
  ``max_class_name_chars``, one with a control, format or other
  non-printable character (NUL included), or one mixing letters of two
  alphabets (a Cyrillic ``с`` in a Latin ``cork``) is refused and counted
  (``empty_label``, ``class_name_too_long``, ``bad_class_name``).  A new
  name beyond ``max_classes`` classes is refused (``too_many_classes``).

Every label ends in exactly one of: learned, held (and later learned or
expired), or refused with a counter; :attr:`LabelProtocol.counts` holds the
counters.  The protocol is deterministic: the same calls in the same order
(and times) give the same decisions.  A decision carries the ``token`` its
label was given, so a caller can answer whoever sent it.

:class:`StampOrder` makes the order of the calls that of the stamps, so
that a replay gives the same updates however a label and a descriptor that
arrive together are served: labels are applied in the order of their stamps
(label header, window end), each waiting a bounded time for the descriptor
it may name; descriptors are predicted at once, or, for bit-identical
replays, in stamp order too.  A jump back in the stamps (a replay started
again, ``/clock`` going back) starts a new session.
"""

from __future__ import annotations

import unicodedata
from bisect import insort
from collections import Counter, OrderedDict, deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

from ..errors import ConfigError

__all__ = ["LabelDecision", "LabelProtocol", "StampOrder", "LEARN", "HELD", "REFUSED", "EXPIRED",
           "REFUSAL_REASONS", "normalise_class_name", "check_label_wait_s", "check_label_hold_s",
           "check_clock_jump_s", "DEFAULT_MAX_CLASS_NAME_CHARS", "DEFAULT_MAX_CLASSES", "DEFAULT_MAX_ID_STEP",
           "DEFAULT_LABEL_HOLD_S", "DEFAULT_LABEL_WAIT_S", "DEFAULT_CLOCK_JUMP_S", "MAX_WAIT_S"]

T = TypeVar("T")

#: What a decision asks of the caller.
LEARN, HELD, REFUSED, EXPIRED = "learn", "held", "refused", "expired"

#: Counter names of refused labels.
REFUSAL_REASONS: tuple[str, ...] = ("empty_label", "class_name_too_long", "bad_class_name", "too_many_classes",
                                    "unknown_exploration", "exploration_id_too_far", "duplicate_label",
                                    "conflicting_label", "held_full")

#: Longest class name accepted by default (characters).
DEFAULT_MAX_CLASS_NAME_CHARS = 64
#: Most classes a model takes by default.
DEFAULT_MAX_CLASSES = 1000
#: Farthest an exploration id may be from the latest one, by default.
DEFAULT_MAX_ID_STEP = 1000
#: Longest time a label is held for an exploration not seen yet, by default [s].
DEFAULT_LABEL_HOLD_S = 60.0
#: Longest settable wait or hold [s]: an hour (a longer one is a typo, and holds predictions or labels for ever).
MAX_WAIT_S = 3600.0

# Scripts whose letters mix in one name (Japanese, Chinese, Korean writing; UTS #39 "highly restrictive")
_HAN_GROUP = frozenset({"CJK", "HIRAGANA", "KATAKANA", "HANGUL", "BOPOMOFO"})


def normalise_class_name(name: str) -> tuple[str, str | None]:
    """A class name as the protocol keeps it, and why it is refused (None: accepted).

    NFKC normal form (compatibility characters such as fullwidth letters
    become the plain ones), stripped.  Refused: empty, a character that is
    not printable (controls, NUL, format and bidirectional marks, private
    use, unassigned), or letters of more than one alphabet (Latin with
    Cyrillic or Greek, ...; Latin with Chinese, Japanese or Korean
    characters is fine).  The script of a letter is the first word of its
    Unicode name: Python's ``unicodedata`` has no script property, and this
    is enough to refuse the homoglyphs that mix alphabets.

    Returns
    -------
    (str, str or None)
        The normalised name, and ``"empty_label"`` or ``"bad_class_name"`` when refused.
    """
    text = unicodedata.normalize("NFKC", str(name)).strip()
    if not text:
        return text, "empty_label"
    if not text.isprintable():
        return text, "bad_class_name"
    scripts = {unicodedata.name(c, "?").split(" ", 1)[0] for c in text if unicodedata.category(c).startswith("L")}
    scripts -= {"MODIFIER"}
    if len(scripts - _HAN_GROUP) > 1:
        return text, "bad_class_name"
    return text, None


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
        The class name, normalised.
    item : object or None
        The descriptor (whatever the caller passed to
        :meth:`LabelProtocol.add_descriptor`) to learn, for ``learn``.
    reason : str or None
        Counter name of a refusal or expiry.
    message : str
        One line for a log.
    token : object or None
        What the caller gave with the label (e.g. a service call to answer).
    """

    action: str
    exploration_id: int
    class_name: str
    item: T | None = None
    reason: str | None = None
    message: str = ""
    token: Any = None


@dataclass
class _Kept(Generic[T]):
    serial: int
    exploration_id: int
    item: T
    learned_as: str | None = None
    stamp_ns: int = 0


@dataclass
class _Held:
    name: str
    since_s: float
    token: Any = None


def _int_setting(key: str, value: int, maximum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= maximum:
        raise ConfigError(f"must be an integer from 1 to {maximum}, got {value!r}", key=key)
    return value


def _seconds(key: str, value: float, minimum: float, maximum: float) -> float:
    """A finite number of seconds in [minimum, maximum] (NaN and infinities refused)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not minimum <= value <= maximum:
        raise ConfigError(f"must be a number of seconds from {minimum:g} to {maximum:g}, got {value!r}", key=key)
    return float(value)


def check_label_hold_s(value: float) -> float:
    """``label_hold_s``: from 0.1 s to an hour."""
    return _seconds("label_hold_s", value, 0.1, MAX_WAIT_S)


#: Largest horizon, expiry, class count, name length and id step accepted (memory and time stay bounded).
MAX_HORIZON = 100_000
MAX_CLASSES = 100_000
MAX_CLASS_NAME_CHARS = 1024
MAX_ID_STEP = 1 << 40


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
    max_classes : int, default 1000
        Most classes: a label naming a new class beyond them is refused.
    max_id_step : int, default 1000
        Farthest an exploration id may lie from the latest one.
    hold_s : float, default 60
        Longest a label is held for an exploration not seen yet [s].

    Raises
    ------
    ConfigError
        For a setting out of its range (naming the node parameter).
    """

    def __init__(self, horizon: int = 100, expiry_explorations: int = 10,
                 max_class_name_chars: int = DEFAULT_MAX_CLASS_NAME_CHARS, max_classes: int = DEFAULT_MAX_CLASSES,
                 max_id_step: int = DEFAULT_MAX_ID_STEP, hold_s: float = DEFAULT_LABEL_HOLD_S) -> None:
        self.horizon = _int_setting("label_horizon", horizon, MAX_HORIZON)
        self.expiry_explorations = _int_setting("label_expiry_explorations", expiry_explorations, MAX_HORIZON)
        self.max_class_name_chars = _int_setting("max_class_name_chars", max_class_name_chars, MAX_CLASS_NAME_CHARS)
        self.max_classes = _int_setting("max_classes", max_classes, MAX_CLASSES)
        self.max_id_step = _int_setting("max_exploration_id_step", max_id_step, MAX_ID_STEP)
        self.hold_s = check_label_hold_s(hold_s)
        self.counts: Counter[str] = Counter()
        self._classes: set[str] = set()
        self.reset()

    def reset(self) -> list[LabelDecision[T]]:
        """A new model: forget every descriptor, held label and class (the counters stay).

        Returns the held labels dropped (``expired``, reason ``labels_dropped_by_reset``).
        """
        self._classes = set()
        return self._forget("labels_dropped_by_reset", "the model was reset")

    def restart(self) -> list[LabelDecision[T]]:
        """A new session of stamps and ids (a replay started again): forget every descriptor and held label.

        The classes stay.  Returns the held labels dropped (``expired``, reason
        ``labels_dropped_by_time_jump``).
        """
        return self._forget("labels_dropped_by_time_jump", "the stamps jumped back (a new session)")

    def _forget(self, reason: str, why: str) -> list[LabelDecision[T]]:
        dropped = [LabelDecision(EXPIRED, eid, h.name, reason=reason, token=h.token,
                                 message=f"label {h.name!r} for exploration {eid} dropped: {why}")
                   for eid, h in getattr(self, "_held", {}).items()]
        if dropped:
            self.counts[reason] += len(dropped)
        self._kept: OrderedDict[int, _Kept[T]] = OrderedDict()  # exploration id -> descriptor
        self._latest: _Kept[T] | None = None
        self._previous: _Kept[T] | None = None  # the descriptor before the latest
        self._recent: deque[_Kept[T]] = deque(maxlen=self.horizon)  # every kept one, for stamped id-0 labels
        self._latest_id = 0
        self._candidate_id: int | None = None  # an out-of-range id that a next one may confirm
        self._serial = 0
        self._held: OrderedDict[int, _Held] = OrderedDict()  # exploration id -> held label
        return dropped

    def known_classes(self, names) -> None:
        """The classes the model already has (a loaded model): they count towards ``max_classes``."""
        self._classes = set(names)

    def set_horizon(self, horizon: int) -> list[LabelDecision[T]]:
        """Change the horizon while running; a smaller one forgets the oldest kept descriptors now.

        Held labels beyond the new horizon are dropped and counted
        (``label_dropped_by_horizon``), never silently; they are returned.

        Raises
        ------
        ConfigError
            For a horizon out of range.
        """
        self.horizon = _int_setting("label_horizon", horizon, MAX_HORIZON)
        self._recent = deque(self._recent, maxlen=horizon)
        while len(self._kept) > horizon:
            self._kept.popitem(last=False)
        dropped = []
        while len(self._held) > horizon:
            eid, h = self._held.popitem(last=False)
            dropped.append(LabelDecision(EXPIRED, eid, h.name, reason="label_dropped_by_horizon", token=h.token,
                                         message=f"label {h.name!r} for exploration {eid} dropped: label_horizon "
                                                 f"{horizon}"))
        if dropped:
            self.counts["label_dropped_by_horizon"] += len(dropped)
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
    def classes(self) -> int:
        """Classes known or promised to labels learned or held."""
        return len(self._classes)

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
    def add_descriptor(self, exploration_id: int, item: T, stamp_ns: int = 0,
                       now_s: float = 0.0) -> list[LabelDecision[T]]:
        """Register a descriptor *after* it was predicted; return what to do now.

        The list holds, in order, the held label of this exploration (``learn``)
        and any held labels that expire because of it (``expired``).  ``stamp_ns``
        (the window end) lets a stamped label with id 0 find it; ``now_s`` (any
        monotonic clock) expires labels held too long.
        """
        eid = int(exploration_id)
        self._serial += 1
        kept = _Kept(self._serial, eid, item, stamp_ns=int(stamp_ns))
        self._previous, self._latest = self._latest, kept
        self._recent.append(kept)
        out: list[LabelDecision[T]] = []
        if eid:
            self._track_id(eid)
            previous = self._kept.pop(eid, None)
            if previous is not None:
                kept.learned_as = previous.learned_as  # the same exploration again: still labelled
            self._kept[eid] = kept
            while len(self._kept) > self.horizon:
                self._kept.popitem(last=False)
            held = self._held.pop(eid, None)
            if held is not None:
                out.append(self._learn(kept, held.name, eid, held.token))
        for held_id in [h for h in self._held if self._latest_id - h >= self.expiry_explorations]:
            out.append(self._expire(held_id, f"exploration {self._latest_id} arrived and {held_id} never did"))
        return out + self.expire(now_s)

    def _track_id(self, eid: int) -> None:
        """Move the latest id, unless ``eid`` is out of range (see the module docstring)."""
        if abs(eid - self._latest_id) <= self.max_id_step:
            self._latest_id = max(self._latest_id, eid)
            self._candidate_id = None
        elif self._candidate_id is not None and 0 < eid - self._candidate_id <= self.max_id_step:
            self._latest_id = eid
            self._candidate_id = None
            self.counts["exploration_ids_rebased"] += 1
        else:
            self._candidate_id = eid
            self.counts["exploration_id_out_of_range"] += 1

    def expire(self, now_s: float) -> list[LabelDecision[T]]:
        """Expire the labels held ``hold_s`` or longer (call it now and then; :class:`StampOrder` does)."""
        old = [eid for eid, h in self._held.items() if now_s - h.since_s >= self.hold_s]
        return [self._expire(eid, f"held {self.hold_s:g} s and it never came") for eid in old]

    def _expire(self, eid: int, why: str) -> LabelDecision[T]:
        h = self._held.pop(eid)
        self.counts["label_expired"] += 1
        return LabelDecision(EXPIRED, eid, h.name, reason="label_expired", token=h.token,
                             message=f"label {h.name!r} for exploration {eid} expired: {why}")

    # ----------------------------------------------------------------- labels
    def add_label(self, exploration_id: int, class_name: str, stamp_ns: int = 0, now_s: float = 0.0,
                  token: Any = None) -> LabelDecision[T]:
        """Decide what a label does (``learn`` now, ``held``, or ``refused``).

        With id 0 and a ``stamp_ns`` (the label's header stamp), the label names the most recent descriptor
        stamped at or before it (see :meth:`target`); unstamped (0), the most recent descriptor.  ``now_s``
        starts a held label's time; ``token`` comes back in every decision about this label.
        """
        eid = int(exploration_id)
        raw = str(class_name)
        name, bad = normalise_class_name(raw)
        where = f"exploration {eid}" if eid else "the most recent exploration"
        if bad == "empty_label":
            return self._refuse("empty_label", eid, name, f"label for {where} has an empty class name", token)
        if len(name) > self.max_class_name_chars:
            return self._refuse("class_name_too_long", eid, name[:self.max_class_name_chars],
                                f"label for {where}: class name of {len(name)} characters (at most "
                                f"{self.max_class_name_chars}): {name[:self.max_class_name_chars]!r}...", token)
        if bad:
            return self._refuse("bad_class_name", eid, name,
                                f"label for {where}: class name {raw!r} has a control or other non-printable "
                                "character, or letters of two alphabets", token)
        if name not in self._classes and len(self._classes) >= self.max_classes:
            return self._refuse("too_many_classes", eid, name, f"label {name!r} for {where}: a new class, and the "
                                f"model has max_classes ({self.max_classes}) already", token)
        kept = self._find(eid, int(stamp_ns))
        if kept is not None:
            return self._learn(kept, name, eid, token)
        if eid == 0:
            return self._refuse("unknown_exploration", eid, name,
                                f"label {name!r} for the most recent exploration: no descriptor yet", token)
        if eid in self._held:
            first = self._held[eid].name
            reason = "duplicate_label" if first == name else "conflicting_label"
            return self._refuse(reason, eid, name, f"label {name!r} for exploration {eid}: already labelled "
                                                   f"{first!r} (the first label wins)", token)
        if eid <= self._latest_id - self.expiry_explorations:
            return self._refuse("unknown_exploration", eid, name,
                                f"label {name!r} for exploration {eid}: no such descriptor with contact among the "
                                f"last {self.horizon} kept (latest {self._latest_id})", token)
        if eid > self._latest_id + self.max_id_step:
            return self._refuse("exploration_id_too_far", eid, name,
                                f"label {name!r} for exploration {eid}: more than max_exploration_id_step "
                                f"({self.max_id_step}) past the latest ({self._latest_id})", token)
        if len(self._held) >= self.horizon:
            return self._refuse("held_full", eid, name, f"label {name!r} for exploration {eid}: already "
                                                        f"{len(self._held)} labels held for explorations not seen",
                                token)
        self._held[eid] = _Held(name, float(now_s), token)
        self._classes.add(name)
        self.counts["early_labels"] += 1
        return LabelDecision(HELD, eid, name, token=token, message=(
            f"label {name!r} for exploration {eid} held until it arrives (latest {self._latest_id}; it expires "
            f"{self.expiry_explorations} explorations or {self.hold_s:g} s from now)"))

    def _learn(self, kept: _Kept[T], name: str, eid: int, token: Any) -> LabelDecision[T]:
        if kept.learned_as is not None:
            reason = "duplicate_label" if kept.learned_as == name else "conflicting_label"
            what = f"exploration {kept.exploration_id}" if kept.exploration_id else "the most recent descriptor"
            return self._refuse(reason, eid, name, f"label {name!r} for {what}: already learned as "
                                                   f"{kept.learned_as!r} (the first label wins)", token)
        kept.learned_as = name
        self._classes.add(name)
        self.counts["labels_learned"] += 1
        return LabelDecision(LEARN, eid, name, item=kept.item, token=token)

    def _refuse(self, reason: str, eid: int, name: str, message: str, token: Any) -> LabelDecision[T]:
        self.counts[reason] += 1
        return LabelDecision(REFUSED, eid, name, reason=reason, message=message + "; refused", token=token)


#: How long a stamped label waits, at most, for the descriptor it may name (and, with ``hold_descriptors``, a
#: descriptor for the label due before it) [s].
DEFAULT_LABEL_WAIT_S = 2.0
#: A stamp this far behind the latest of its stream is a jump back: a new session [s].
DEFAULT_CLOCK_JUMP_S = 1.0


def check_label_wait_s(value: float) -> float:
    """``label_wait_s``: from 0 (arrival order) to an hour."""
    return _seconds("label_wait_s", value, 0.0, MAX_WAIT_S)


def check_clock_jump_s(value: float) -> float:
    """``clock_jump_s``: from 1 ms to an hour."""
    return _seconds("clock_jump_s", value, 0.001, MAX_WAIT_S)


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
    token: Any = None


class StampOrder(Generic[T, K]):
    """Apply labels (and, with ``hold_descriptors``, predict descriptors) in the order of their stamps.

    A descriptor's stamp is its window end, a label's its header stamp.  The
    outcome is that of taking every descriptor and label in stamp order
    (a descriptor before a label of the same stamp):

    * a stamped label with id 0 names the most recent exploration whose
      window ended at or before the label's stamp
      (:meth:`LabelProtocol.target`), and is learned once that descriptor is
      there;
    * with ``hold_descriptors``, a descriptor is predicted with the model
      that learned every label stamped before its window end and none
      stamped after it: a replay then gives the same predictions bit for
      bit.  Without it (the default of the node), a descriptor is predicted
      the moment it arrives, with the model as it is: no wait, and the
      labels are still learned on the right explorations.

    Nothing says when a message still in flight will come, so each one
    waits (at most ``wait_s``, counted when it runs out) only while
    something may still come before it:

    * a **stamped label** waits while the descriptor it names may be in
      flight: id 0 whose most recent descriptor up to its stamp is already
      labelled (or there is none), or an id naming a kept exploration
      older than the most recent one; unless a descriptor whose window
      ended after the label's stamp has arrived (descriptors come in stamp
      order);
    * with ``hold_descriptors``, a **descriptor** waits while a label for
      the exploration before it is due (:attr:`LabelProtocol.awaits_label`:
      labels are being given and that exploration has none yet), unless a
      label stamped at or after its window end has arrived (labels come in
      stamp order);
    * an **unstamped label** (stamp 0) is applied when it arrives.

    So the result does not depend on which of two messages ready together
    is served first, as long as descriptors come in stamp order (one
    window node), labels too, and each arrives within ``wait_s`` of what it
    waits for.

    **Jumps back.** A descriptor stamped more than ``jump_s`` before the
    latest descriptor, or a stamped label more than ``jump_s`` before the
    latest label, starts a new session (a bag replayed again, ``/clock``
    going back): what waits is taken at once, the protocol forgets the
    previous session's descriptors and held labels
    (:meth:`LabelProtocol.restart`), the stamp order starts again, and the
    jump is counted (``clock_jumps_back``).

    Pure: the caller passes the time (any monotonic clock, in seconds) and
    calls :meth:`poll` now and then (which also expires labels held too long).

    Parameters
    ----------
    protocol : LabelProtocol
        Decides what each label does; it keeps what ``predict`` returns.
    predict : callable
        ``predict(descriptor) -> kept``: predict (and publish) one descriptor;
        return what the protocol keeps for its label, or None to skip it.
    apply : callable
        ``apply(decision)``: carry out one :class:`LabelDecision` (learn, or
        report a hold, refusal or expiry), before anything later is taken.
    wait_s : float, default 2.0
        Longest wait; 0 takes everything in arrival order.
    hold_descriptors : bool, default True
        Predict descriptors in stamp order (bit-identical replays) rather than
        on arrival.
    jump_s : float, default 1.0
        A stamp this far behind the latest of its stream starts a new session.

    Raises
    ------
    ConfigError
        For a ``wait_s`` or ``jump_s`` out of range (NaN and infinities included).
    """

    def __init__(self, protocol: LabelProtocol[K], predict: Callable[[T], K | None],
                 apply: Callable[[LabelDecision[K]], None], wait_s: float = DEFAULT_LABEL_WAIT_S,
                 hold_descriptors: bool = True, jump_s: float = DEFAULT_CLOCK_JUMP_S) -> None:
        self.protocol = protocol
        self._predict = predict
        self._apply = apply
        self.wait_s = check_label_wait_s(wait_s)
        self.hold_descriptors = bool(hold_descriptors)
        self.jump_ns = int(check_clock_jump_s(jump_s) * 1e9)
        #: ``descriptor_wait_expired`` / ``label_wait_expired``: released because their wait ran out;
        #: ``labels_dropped_by_reset``: labels waiting when the model was reset; ``clock_jumps_back``.
        self.counts: Counter[str] = Counter()
        self._waiting: list[_Waiting[T]] = []
        self._serial = 0
        self._label_mark = -1        # latest stamp of a stamped label received
        self._descriptor_mark = -1   # latest window end of a descriptor received

    def set_wait(self, wait_s: float) -> None:
        """Change the longest wait (from the next :meth:`poll` on)."""
        self.wait_s = check_label_wait_s(wait_s)

    @property
    def waiting(self) -> int:
        """Descriptors and labels waiting for what comes before them."""
        return len(self._waiting)

    def reset(self) -> None:
        """After a model reset: drop the waiting labels and the protocol's (counted, each one applied as
        ``expired``) and forget the stamps seen (a new session, a bag replayed again, may start earlier);
        waiting descriptors stay."""
        labels = [w for w in self._waiting if w.kind]
        if labels:
            self.counts["labels_dropped_by_reset"] += len(labels)
        self._waiting = [w for w in self._waiting if not w.kind]
        for w in labels:
            self._apply(LabelDecision(EXPIRED, w.exploration_id, w.class_name, reason="labels_dropped_by_reset",
                                      token=w.token, message=f"label {w.class_name!r} dropped: the model was reset"))
        for decision in self.protocol.reset():
            self._apply(decision)
        self._label_mark = -1
        self._descriptor_mark = max((w.stamp_ns for w in self._waiting), default=-1)

    # ------------------------------------------------------------------ input
    def add_descriptor(self, exploration_id: int, stamp_ns: int, descriptor: T, now_s: float) -> None:
        """A descriptor arrived (``stamp_ns``: its window end); predict it now, or when its turn has come."""
        stamp = int(stamp_ns)
        if self._jumped_back(stamp, self._descriptor_mark):
            self._restart(now_s)
        self._descriptor_mark = max(self._descriptor_mark, stamp)
        if self.hold_descriptors:
            self._enqueue(_Waiting(stamp, 0, 0, now_s, int(exploration_id), descriptor=descriptor))
        else:
            self._take_descriptor(int(exploration_id), stamp, descriptor, now_s)
        self.poll(now_s)

    def add_label(self, exploration_id: int, class_name: str, stamp_ns: int, now_s: float,
                  token: Any = None) -> None:
        """A label arrived (``stamp_ns``: its header stamp, 0 = none); apply what is due.

        ``token`` comes back in the decision about this label.
        """
        stamp = int(stamp_ns)
        if stamp <= 0:
            self._apply(self.protocol.add_label(exploration_id, class_name, now_s=now_s, token=token))
        else:
            if self._jumped_back(stamp, self._label_mark):
                self._restart(now_s)
            self._label_mark = max(self._label_mark, stamp)
            self._enqueue(_Waiting(stamp, 1, 0, now_s, int(exploration_id), class_name=class_name, token=token))
        self.poll(now_s)

    def poll(self, now_s: float) -> None:
        """Take, in stamp order, everything whose turn has come or whose wait ran out; expire held labels."""
        while self._waiting:
            head = self._waiting[0]
            if not self._due(head):
                if now_s - head.arrival_s < self.wait_s and len(self._waiting) <= self.protocol.horizon:
                    break
                self.counts["label_wait_expired" if head.kind else "descriptor_wait_expired"] += 1
            self._waiting.pop(0)
            self._take(head, now_s)
        for decision in self.protocol.expire(now_s):
            self._apply(decision)

    # --------------------------------------------------------------- internal
    def _take(self, head: _Waiting[T], now_s: float) -> None:
        if head.kind:
            self._apply(self.protocol.add_label(head.exploration_id, head.class_name, head.stamp_ns, now_s,
                                                head.token))
        else:
            self._take_descriptor(head.exploration_id, head.stamp_ns, head.descriptor, now_s)

    def _take_descriptor(self, exploration_id: int, stamp_ns: int, descriptor: T, now_s: float) -> None:
        kept = self._predict(descriptor)
        if kept is not None:
            for decision in self.protocol.add_descriptor(exploration_id, kept, stamp_ns, now_s):
                self._apply(decision)

    def _jumped_back(self, stamp: int, mark: int) -> bool:
        return stamp > 0 and mark >= 0 and stamp < mark - self.jump_ns

    def _restart(self, now_s: float) -> None:
        """A jump back: finish the previous session, then start a new one (see the class docstring)."""
        self.counts["clock_jumps_back"] += 1
        while self._waiting:
            self._take(self._waiting.pop(0), now_s)
        for decision in self.protocol.restart():
            self._apply(decision)
        self._label_mark = self._descriptor_mark = -1

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
