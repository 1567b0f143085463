"""Wrapping counters made whole: the one place where sequence numbers and device clocks are unwrapped.

Every stream of this package numbers its frames with a short wrapping
counter: 8 bits per skin cell and modality (a 1 kHz accelerometer wraps every
256 ms), 16 bits per BioTac on the serial bridge, 32 bits per message, and
the bridge's microsecond clock wraps at 2^32.  Unwrapping by the nearest
difference alone (a jump of more than half the modulus counts as a step
back) turns a quiet period longer than half a wrap into a shifted clock: a
skin cell silent for 200 ms comes back 256 ms early.

:func:`unwrap` therefore takes an *expected advance* besides the previous
value: when the arrival times of two frames are known, the elapsed time
divided by the sample period says roughly how many frames should lie between
them, and the unwrapped number is the one congruent to the received number
that is nearest to that expectation.  The answer is exact while the time
error (latency jitter of the time source) stays below half a wrap; without a
time it is the plain nearest unwrapping.

:class:`SequenceTracker` applies this per key (a chip select, a cell and
modality) and classifies each number (:class:`SequenceEvent`): in order, a
gap (lost frames, counted with their length), a duplicate, a late
(reordered) frame, or a restart of the sender's count.  The codecs use it to
drop duplicates; the streams use it to number samples for their time stamps.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable
from enum import IntEnum
from types import ModuleType

import numpy as np

from ..core import fast
from ..errors import ConfigError

__all__ = ["unwrap", "unwrap_array", "Unwrapper", "SequenceEvent", "SequenceTracker"]


def unwrap(raw: int, reference: int, modulus: int, advance: float = 0.0) -> int:
    """The integer congruent to ``raw`` modulo ``modulus`` nearest to ``reference + advance``.

    Parameters
    ----------
    raw : int
        Received counter value (any integer; taken modulo ``modulus``).
    reference : int
        Unwrapped value of an earlier frame.
    modulus : int
        The counter runs ``0..modulus-1``.
    advance : float
        Expected distance from ``reference`` (elapsed time / period); 0
        without a time.

    Notes
    -----
    A tie (exactly half a wrap from the expectation) goes to the earlier
    value, so without a time a jump of ``modulus / 2`` counts as a step back.
    """
    m = int(modulus)
    d = (int(raw) - int(reference)) % m
    j = math.ceil((float(advance) - d) / m - 0.5)
    return int(reference) + d + j * m


def unwrap_array(raw: np.ndarray, reference: np.ndarray, modulus: int,
                 advance: np.ndarray | float = 0.0) -> np.ndarray:
    """:func:`unwrap` element by element (int64 arrays; ``advance`` broadcast)."""
    m = int(modulus)
    d = (np.asarray(raw, dtype=np.int64) - np.asarray(reference, dtype=np.int64)) % m
    j = np.ceil((np.asarray(advance, dtype=np.float64) - d) / m - 0.5).astype(np.int64)
    return np.asarray(reference, dtype=np.int64) + d + j * m


class Unwrapper:
    """One wrapping counter (a device clock, a message sequence) unwrapped to a growing integer.

    Parameters
    ----------
    modulus : int
        The counter runs ``0..modulus-1``.
    """

    def __init__(self, modulus: int) -> None:
        self.modulus = int(modulus)
        self.value: int | None = None

    def __call__(self, raw: int, advance: float = 0.0) -> int:
        """The unwrapped value of ``raw`` (the first value is ``raw`` itself)."""
        if self.value is None:
            self.value = int(raw) % self.modulus
        else:
            self.value = unwrap(raw, self.value, self.modulus, advance)
        return self.value

    def reset(self) -> None:
        """Forget the history (the device restarted)."""
        self.value = None


#: Whether :meth:`SequenceTracker.track_many` may use the compiled backend when it is loaded (the tests switch it
#: off to compare both paths).
COMPILED_TRACKING = True
#: The largest modulus the compiled pass takes (its arithmetic is int64 and its advance float64, exact below).
_COMPILED_MODULUS = 1 << 32


def _tracker_kernel() -> ModuleType | None:
    """The compiled backend's module when the tracker may use it (:data:`COMPILED_TRACKING`), else None."""
    return fast.kernel_module() if COMPILED_TRACKING else None


class SequenceEvent(IntEnum):
    """What one sequence number means relative to those seen before."""

    FIRST = 0  #: first frame of this key
    IN_ORDER = 1  #: exactly the next number
    GAP = 2  #: later than the next number: frames were lost in between
    DUPLICATE = 3  #: seen recently: drop it
    LATE = 4  #: earlier than the newest but not seen: arrived out of order (accept it)
    RESET = 5  #: far earlier than the newest: the sender restarted its count (tracking restarts)


class SequenceTracker:
    """Track wrapping sequence numbers per key (a chip select, a cell and modality, ...).

    Numbers are unwrapped relative to the newest one with :func:`unwrap`.
    Given the frame times (``t_ns``) and the nominal frame period
    (``period_ns``), the elapsed time since the newest frame is the expected
    advance, so a silence of any length is a gap of the right length; without
    times a difference of more than half the modulus counts as "earlier".
    The last ``window`` numbers are remembered so that duplicates are
    recognised even after reordering.  A number more than ``window`` before
    the newest means the sender restarted (a replugged sensor, a rebooted
    bridge): tracking of that key restarts.

    ``lost`` is the net number of frames missing inside the span seen so far:
    it grows on gaps and shrinks when a late frame fills a hole.

    Parameters
    ----------
    modulus : int
        Sequence numbers run ``0..modulus-1`` and wrap.
    window : int
        How many recent numbers are remembered for duplicate detection (and
        how far back a number means a restart); 0 for a stream whose
        duplicates were already removed (no memory kept, nothing is a
        duplicate, a step back of more than ``modulus / 8`` is a restart).
    period_ns : float, optional
        Default frame period of every key (``track_many`` also takes one per
        number); without it times are ignored.

    Notes
    -----
    Each key has a slot in flat arrays: the oldest and newest unwrapped
    numbers and the time of the newest.  What was received is remembered as
    its complement, the *holes*: numbers between the oldest and the newest
    that a gap skipped and no late frame has filled, kept only within
    ``window`` of the newest (a number further back is a restart, so nothing
    older is ever asked).  A number in that span is a duplicate exactly when
    it is not a hole.  Streams in order have no holes, so :meth:`track_many`
    updates all their keys in one compiled pass (array operations where the
    compiled backend does not serve), with no Python work per key (a skin
    driver tracks hundreds of keys on every read).
    """

    def __init__(self, modulus: int, window: int = 64, period_ns: float | None = None) -> None:
        if modulus < 4 or window < 0 or window >= modulus // 2:
            raise ConfigError(f"bad sequence tracker (modulus {modulus}, window {window})")
        self.modulus = int(modulus)
        self.window = int(window)
        self.period_ns = None if period_ns is None else float(period_ns)
        self._slot: dict[Hashable, int] = {}  # key -> slot
        self._code_sorted = np.empty(0, dtype=np.int64)  # integer codes track_many has seen, sorted
        self._code_slot = np.empty(0, dtype=np.int64)  # the slot of each
        self._live = np.zeros(0, dtype=bool)  # the slot's key has a number (not new, not reset)
        self._low = np.zeros(0, dtype=np.int64)  # oldest unwrapped number received
        self._high = np.zeros(0, dtype=np.int64)  # newest unwrapped number received
        self._t_high = np.zeros(0, dtype=np.int64)  # time of the newest [ns]; -1 = unknown
        self._holes: dict[int, set[int]] = {}  # slot -> numbers skipped within window of the newest
        self.gaps = 0
        self.lost = 0
        self.duplicates = 0
        self.late = 0
        self.resets = 0
        self._last_unwrapped = 0

    # ------------------------------------------------------------------ slots
    def _new_slot(self, key: Hashable) -> int:
        s = len(self._slot)
        if s == len(self._live):
            grow = max(16, 2 * s)
            self._live = np.concatenate([self._live, np.zeros(grow, dtype=bool)])
            self._low = np.concatenate([self._low, np.zeros(grow, dtype=np.int64)])
            self._high = np.concatenate([self._high, np.zeros(grow, dtype=np.int64)])
            self._t_high = np.concatenate([self._t_high, np.full(grow, -1, dtype=np.int64)])
        self._slot[key] = s
        return s

    def _slot_of(self, key: Hashable) -> int:
        s = self._slot.get(key)
        return self._new_slot(key) if s is None else s

    def _slots_of_codes(self, codes: np.ndarray, key_of: Callable[[int], Hashable]) -> np.ndarray:
        """The slots of sorted unique ``codes``; a code seen for the first time gets its key's slot."""
        known = self._code_sorted
        i = np.searchsorted(known, codes)
        found = i < len(known)
        found[found] = known[i[found]] == codes[found]
        if found.all():
            return self._code_slot[i]
        fresh = codes[~found]
        fresh_slots = np.array([self._slot_of(key_of(c)) for c in fresh.tolist()], dtype=np.int64)
        merged = np.concatenate([known, fresh])
        order = np.argsort(merged, kind="stable")
        self._code_sorted = merged[order]
        self._code_slot = np.concatenate([self._code_slot, fresh_slots])[order]
        return self._slots_of_codes(codes, key_of)

    def _start(self, s: int, seq: int, t_ns: int) -> None:
        self._live[s] = True
        self._low[s] = self._high[s] = seq
        self._t_high[s] = t_ns
        self._holes.pop(s, None)

    def _add_holes(self, s: int, first: int, stop: int) -> None:
        """Numbers ``first..stop-1`` were skipped; only those within ``window`` of the newest are kept."""
        first = max(first, int(self._high[s]) - self.window)
        if first < stop:
            self._holes.setdefault(s, set()).update(range(first, stop))

    def _prune_holes(self, s: int) -> None:
        holes = self._holes.get(s)
        if holes:
            cut = int(self._high[s]) - self.window
            holes.difference_update([x for x in holes if x < cut])
        if not holes:
            self._holes.pop(s, None)

    # ------------------------------------------------------------- one by one
    def reset(self, key: Hashable | None = None) -> None:
        """Forget one key (e.g. a sensor that was replugged) or all keys."""
        if key is None:
            self._live[:] = False
            self._holes.clear()
        else:
            s = self._slot.get(key)
            if s is not None:
                self._live[s] = False
                self._holes.pop(s, None)

    def newest(self, key: Hashable) -> int | None:
        """The unwrapped newest number of ``key`` (``None`` before its first)."""
        s = self._slot.get(key)
        return None if s is None or not self._live[s] else int(self._high[s])

    def snapshot(self) -> dict[Hashable, tuple[int, int, int | None, frozenset[int]]]:
        """What decides the events to come, per key with a number: the oldest and newest unwrapped numbers,
        the time of the newest [ns] (``None`` unknown) and the holes within ``window`` of the newest."""
        out = {}
        for key, s in self._slot.items():
            if self._live[s]:
                high, t = int(self._high[s]), int(self._t_high[s])
                holes = frozenset(x for x in self._holes.get(s, ()) if x >= high - self.window)
                out[key] = (int(self._low[s]), high, None if t < 0 else t, holes)
        return out

    def update(self, key: Hashable, seq: int, t_ns: int | None = None,
               period_ns: float | None = None) -> SequenceEvent:
        """Register ``seq`` (received at ``t_ns``, optional) for ``key`` and say what it was."""
        event, self._last_unwrapped = self.track(key, seq, t_ns, period_ns)
        return event

    def track(self, key: Hashable, seq: int, t_ns: int | None = None,
              period_ns: float | None = None) -> tuple[SequenceEvent, int]:
        """:meth:`update`, also returning the unwrapped number (meaningless for a duplicate)."""
        return self._track_slot(self._slot_of(key), seq, -1 if t_ns is None else int(t_ns),
                                self.period_ns if period_ns is None else period_ns)

    def _track_slot(self, s: int, seq: int, t_ns: int, period: float | None) -> tuple[SequenceEvent, int]:
        """One number of slot ``s`` (``t_ns`` -1 = unknown); the rules of :meth:`track`."""
        m = self.modulus
        seq = int(seq) % m
        if not self._live[s]:
            self._start(s, seq, t_ns)
            return SequenceEvent.FIRST, seq
        low, high, t_high = int(self._low[s]), int(self._high[s]), int(self._t_high[s])
        advance = (t_ns - t_high) / period if (t_ns >= 0 and t_high >= 0 and period) else 0.0
        u = unwrap(seq, high, m, advance)
        w = self.window
        if u < high - (w or m // 8):
            self.resets += 1
            self._start(s, seq, t_ns)
            return SequenceEvent.RESET, seq
        if w and low <= u <= high and u not in self._holes.get(s, ()):
            self.duplicates += 1
            return SequenceEvent.DUPLICATE, u
        if u > high:
            event = SequenceEvent.IN_ORDER if u == high + 1 else SequenceEvent.GAP
            if u > high + 1:
                self.gaps += 1
                self.lost += u - high - 1
            self._high[s] = u
            self._t_high[s] = t_ns
            if w:
                self._add_holes(s, high + 1, u)
                self._prune_holes(s)
            return event, u
        self.late += 1
        if u < low:
            self.lost += low - u - 1
            if w:
                self._add_holes(s, u + 1, low)
            self._low[s] = u
        else:
            self.lost -= 1
            if w:
                self._holes[s].discard(u)
                self._prune_holes(s)
        return SequenceEvent.LATE, u

    def track_run(self, key: Hashable, first: int, count: int) -> tuple[SequenceEvent, int]:
        """Register a run of ``count`` consecutive numbers from ``first`` (one message of a batch).

        For a tracker without duplicate memory (``window=0``), as the
        messages of one publisher need: they arrive in order, so a run that
        starts at or before the newest number is a restart of the sender's
        count (a node started again, a bag replayed again), never a late run.

        Returns
        -------
        event : SequenceEvent
            What the run's first number was (``GAP``: numbers were lost before it).
        lost : int
            Numbers lost between the previous run and this one (0 unless ``GAP``).
        """
        if self.window:
            raise ConfigError("track_run needs a tracker without duplicate memory (window=0)")
        if count < 1:
            raise ConfigError(f"a run holds at least one number, not {count}")
        m = self.modulus
        first = int(first) % m
        s = self._slot_of(key)
        if not self._live[s]:
            self._start(s, first, -1)
            self._high[s] = first + count - 1
            return SequenceEvent.FIRST, 0
        high = int(self._high[s])
        u = unwrap(first, high + 1, m)
        if u <= high:
            self.resets += 1
            self._start(s, first, -1)
            self._high[s] = first + count - 1
            return SequenceEvent.RESET, 0
        lost = u - high - 1
        if lost:
            self.gaps += 1
            self.lost += lost
        self._high[s] = u + count - 1
        return (SequenceEvent.GAP if lost else SequenceEvent.IN_ORDER), lost

    # ------------------------------------------------------------- many at once
    def update_many(self, codes: np.ndarray, seqs: np.ndarray, key_of: Callable[[int], Hashable],
                    t_ns: np.ndarray | None = None, period_ns: np.ndarray | float | None = None) -> np.ndarray:
        """Register many numbers at once; the events of :meth:`track_many`."""
        return self.track_many(codes, seqs, key_of, t_ns, period_ns)[0]

    def track_many(self, codes: np.ndarray, seqs: np.ndarray, key_of: Callable[[int], Hashable],
                   t_ns: np.ndarray | None = None, period_ns: np.ndarray | float | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
        """Register many numbers at once; the same events, counters and unwrapped numbers as
        :meth:`track` one by one.

        Keys are independent, so the numbers are taken key by key (in their
        order within each key).  Keys whose numbers all move forward (the
        usual case: in order or with gaps) are handled together with array
        operations; any other key (duplicates, late frames, restarts) goes
        through the rules of :meth:`track` number by number.

        Parameters
        ----------
        codes : array of int, shape (n,)
            An integer code of each number's key.
        seqs : array of int, shape (n,)
            The sequence numbers, in arrival order.
        key_of : callable(int) -> hashable
            The key of a code, as :meth:`track` would be given it (so the
            two methods can be mixed on one tracker); called once per code,
            the first time it comes.
        t_ns : array of int, shape (n,), optional
            Arrival (or bus) time of each number [ns]; a negative value
            means unknown.
        period_ns : float or array of float, shape (n,), optional
            Frame period of each number's key (default ``period_ns`` of the
            tracker).

        Returns
        -------
        events : numpy.ndarray of int8, shape (n,)
            The :class:`SequenceEvent` of each number.
        unwrapped : numpy.ndarray of int64, shape (n,)
            The unwrapped number of each (meaningless for a duplicate).
        """
        codes = np.asarray(codes, dtype=np.int64)
        n = codes.size
        events = np.empty(n, dtype=np.int8)
        unwrapped_out = np.empty(n, dtype=np.int64)
        if not n:
            return events, unwrapped_out
        kernel = _tracker_kernel()
        if kernel is not None and self.modulus <= _COMPILED_MODULUS:
            return self._track_compiled(kernel, codes, seqs, key_of, t_ns, period_ns, events, unwrapped_out)
        m = self.modulus
        order = np.argsort(codes, kind="stable")
        sc = codes[order]
        ss = np.asarray(seqs, dtype=np.int64)[order] % m
        starts = np.flatnonzero(np.r_[True, sc[1:] != sc[:-1]])
        ends = np.r_[starts[1:], n]
        lens = ends - starts
        slots = self._slots_of_codes(sc[starts], key_of)
        is_new = ~self._live[slots]
        high = np.where(is_new, 0, self._high[slots])
        # expected advance between neighbours of a key, from their times
        period = self.period_ns if period_ns is None else period_ns
        if t_ns is not None and period is not None:
            tt = np.asarray(t_ns, dtype=np.int64)[order]
            pp = np.broadcast_to(np.asarray(period, dtype=np.float64), (n,))
            pp = pp[order] if np.ndim(period) else pp
            t_prev = np.empty(n, dtype=np.int64)
            t_prev[1:] = tt[:-1]
            t_prev[starts] = np.where(is_new, -1, self._t_high[slots])
            known = (tt >= 0) & (t_prev >= 0) & (pp > 0)
            advance = np.where(known, (tt - t_prev) / np.where(pp > 0, pp, 1.0), 0.0)
        else:
            tt = None
            advance = np.zeros(n)
        prev = np.empty(n, dtype=np.int64)
        prev[1:] = ss[:-1]
        prev[starts] = high
        diff = unwrap_array(ss, prev, m, advance) - prev
        diff[starts[is_new]] = 1  # placeholder, the FIRST number of a new key
        fast = np.minimum.reduceat(diff, starts) > 0
        base = np.where(is_new, ss[starts] - 1, high)
        cs = np.cumsum(diff)
        before = cs[starts] - diff[starts]
        unwrapped = cs + np.repeat(base - before, lens)
        ev = np.where(diff == 1, SequenceEvent.IN_ORDER, SequenceEvent.GAP).astype(np.int8)
        ev[starts[is_new]] = SequenceEvent.FIRST
        in_fast = np.repeat(fast, lens)
        gap = in_fast & (diff > 1)
        self.gaps += int(gap.sum())
        self.lost += int((diff[gap] - 1).sum())
        # keys moving forward: their new state at once
        fs = slots[fast]
        last = ends[fast] - 1
        self._low[fs] = np.where(is_new[fast], ss[starts[fast]], self._low[fs])
        self._live[fs] = True
        self._high[fs] = unwrapped[last]
        self._t_high[fs] = -1 if tt is None else np.where(tt[last] >= 0, tt[last], -1)
        if self.window:
            # the numbers a gap skipped become holes; holes fall behind the window as the newest moves on
            for i in np.flatnonzero(gap).tolist():
                self._add_holes(int(slots[np.searchsorted(starts, i, side="right") - 1]),
                                int(unwrapped[i] - diff[i] + 1), int(unwrapped[i]))
            if self._holes:
                for s in set(fs.tolist()).intersection(self._holes):
                    self._prune_holes(s)
        # any other key: number by number
        if not fast.all():
            s_list = ss.tolist()
            t_list = None if tt is None else tt.tolist()
            p_list = None if tt is None else pp.tolist()
            for g in np.flatnonzero(~fast).tolist():
                s = int(slots[g])
                for i in range(int(starts[g]), int(ends[g])):
                    e, u = self._track_slot(s, s_list[i], -1 if t_list is None else t_list[i],
                                            None if p_list is None else p_list[i])
                    ev[i] = e
                    unwrapped[i] = u
        events[order] = ev
        unwrapped_out[order] = unwrapped
        return events, unwrapped_out

    def _track_compiled(self, kernel: ModuleType, codes: np.ndarray, seqs: np.ndarray,
                        key_of: Callable[[int], Hashable], t_ns: np.ndarray | None,
                        period_ns: np.ndarray | float | None, events: np.ndarray, unwrapped: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`track_many` in one compiled pass in arrival order (:func:`~..core.numba_kernel.track_forward`):
        every key's forward steps there, the rest (duplicates, late frames, restarts) number by number here."""
        n = codes.size
        i = np.searchsorted(self._code_sorted, codes)
        known = i < self._code_sorted.size
        known[known] = self._code_sorted[i[known]] == codes[known]
        if not known.all():  # codes seen for the first time get their keys' slots (in sorted order, as numpy)
            self._slots_of_codes(np.unique(codes[~known]), key_of)
            i = np.searchsorted(self._code_sorted, codes)
        slot = self._code_slot[i]
        seq = np.asarray(seqs, dtype=np.int64) % self.modulus
        period = self.period_ns if period_ns is None else period_ns
        if t_ns is not None and period is not None:
            t = np.array(t_ns, dtype=np.int64)  # copies: writeable and contiguous, the one compiled variant
            p = np.empty(n)
            p[:] = period
        else:  # no times: every advance unknown, as numpy's path (the newest number's time forgotten)
            t = np.full(n, -1, dtype=np.int64)
            p = np.zeros(n)
        gap_slot, gap_from, gap_to = (np.empty(n, dtype=np.int64) for _ in range(3))
        deferred = np.zeros(self._live.size, dtype=bool)
        n_gaps, lost, left = kernel.track_forward(slot, seq, t, p, self.modulus, self._live, self._low, self._high,
                                                  self._t_high, deferred, events, unwrapped, gap_slot, gap_from,
                                                  gap_to)
        self.gaps += int(n_gaps)
        self.lost += int(lost)
        if self.window:
            # the numbers a gap skipped become holes; holes fall behind the window as the newest moves on
            for s, first, stop in zip(gap_slot[:n_gaps].tolist(), gap_from[:n_gaps].tolist(),
                                      gap_to[:n_gaps].tolist()):
                self._add_holes(s, first, stop)
            if self._holes:
                for s in set(np.unique(slot).tolist()).intersection(self._holes):
                    self._prune_holes(s)
        if left:  # any other number: by the rules of track, in arrival order, from where its key stopped
            t_list, p_list = t.tolist(), p.tolist()
            have_period = period is not None
            for k in np.flatnonzero(events < 0).tolist():
                e, u = self._track_slot(int(slot[k]), int(seq[k]), t_list[k], p_list[k] if have_period else None)
                events[k] = e
                unwrapped[k] = u
        return events, unwrapped
