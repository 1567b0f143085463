"""A stall of every cell (a driver stopped for 8 s, then its body parts' messages one after the other).

The windows after the stall are those of a windower that sees every body
part's message before it polls: the first part back does not make the
others look dead, so no window is cut before their samples are in.  An
exploration held through the stall is closed at its start and a new one
begins after it (never one window across the stall), windows keep coming,
and a poll costs a few state-machine steps whatever the stall's length.
"""

from __future__ import annotations

import numpy as np
import pytest

from tactile_descriptors_ros.core.robot import load_robot
from tactile_descriptors_ros.core.windowing import PartChunk, Windower

MS = 1_000_000
NAO = load_robot("nao")
PARTS = [NAO.body_part(name) for name in ("left_hand", "right_hand", "left_forearm")]
STEP_MS = 50  # one message per body part every 50 ms (accelerometer 1 kHz, force 250 Hz)
BEFORE_MS, STALL_MS, AFTER_MS = 3_000, 7_980, 4_000  # back 20 ms before a window ends


def _message(part, t0_ms: int, force_n, rng) -> PartChunk:
    """``STEP_MS`` of every cell of ``part`` from ``t0_ms``; ``force_n(t_ns)`` the touch of its first cell."""
    ids = np.array([c.id for c in part.cells], np.int64)
    ta = (t0_ms * MS + np.arange(STEP_MS, dtype=np.int64) * MS)
    tf = ta[::4]
    n = ids.size
    force = np.zeros((n, tf.size))
    force[0] = force_n(tf)
    return PartChunk(
        cell_ids=ids, vibration_count=np.full(n, ta.size, np.int64), deformation_count=np.full(n, tf.size, np.int64),
        vibration=rng.integers(-512, 512, (3, n * ta.size)).astype(np.int32), vibration_t_ns=np.tile(ta, n),
        deformation=rng.integers(0, 4096, (3, n * tf.size)).astype(np.int32), deformation_t_ns=np.tile(tf, n),
        force_n=force.ravel(), extra=np.zeros((2, n * tf.size)))


def _schedule(force_n) -> list[list[PartChunk]]:
    """Per time step, the messages of every body part (the driver stopped from BEFORE_MS for STALL_MS)."""
    rng = np.random.default_rng(7)
    steps = list(range(0, BEFORE_MS, STEP_MS)) + list(range(BEFORE_MS + STALL_MS,
                                                            BEFORE_MS + STALL_MS + AFTER_MS, STEP_MS))
    return [[_message(p, t, force_n, rng) for p in PARTS] for t in steps]


def _windows(ws) -> list:
    return [(w.start_ns, w.end_ns, w.exploration_id,
             {cid: (c.vibration_t_ns.tolist(), c.deformation_t_ns.tolist(), c.gap) for cid, c in w.cells.items()})
            for w in ws]


def _run(schedule, poll_each_message: bool, **kw) -> tuple[list, Windower, int]:
    """Windows of the schedule; polls after every message or once per time step (all body parts in)."""
    w = Windower(NAO, **kw)
    out, polls = [], 0
    for messages in schedule:
        for m in messages:
            assert w.add_part(m).all()
            if poll_each_message:
                out += w.poll()
                polls += 1
        if not poll_each_message:
            out += w.poll()
            polls += 1
    return out + w.flush(), w, polls


FIXED = dict(mode="fixed", length_s=1.0, hop_s=0.25, lateness_s=0.0)


def test_fixed_windows_after_a_stall_wait_for_every_body_part():
    schedule = _schedule(lambda t: np.zeros(t.size))
    wins, w, _ = _run(schedule, poll_each_message=True, **FIXED)
    ref, _, _ = _run(schedule, poll_each_message=False, **FIXED)
    assert _windows(wins) == _windows(ref)
    resumed = (BEFORE_MS + STALL_MS) * MS
    after = [x for x in wins if x.start_ns >= resumed]
    assert len(after) >= (AFTER_MS - 1_000) // 250  # windows keep coming after the stall
    every = {c.id for p in PARTS for c in p.cells}
    assert all(set(x.cells) == every and not any(c.gap for c in x.cells.values()) for x in after)
    # the windows inside the stall are counted, those across its edges flagged, none splices it
    assert w.faults["windows_without_samples"] >= (STALL_MS - 1_000) // 250
    assert w.faults["gap"] >= 1
    assert not [x for x in wins if x.start_ns < BEFORE_MS * MS - 1_000 * MS and x.end_ns > resumed]


def test_an_exploration_held_through_a_stall_ends_at_it_and_a_new_one_starts_after(monkeypatch):
    stop, resume = BEFORE_MS * MS, (BEFORE_MS + STALL_MS) * MS
    touch = lambda t: np.where((t >= 1_000 * MS) & (t < resume + 2_000 * MS), 2.0, 0.0)  # noqa: E731
    schedule = _schedule(touch)
    kw = dict(mode="exploration", min_duration_s=0.2, max_duration_s=20.0, release_s=0.1,
              force_threshold_n=1.0, release_threshold_n=0.5)
    steps = []
    real_step = Windower._step

    def counted(self, now):
        steps.append(now)
        return real_step(self, now)

    monkeypatch.setattr(Windower, "_step", counted)
    wins, w, polls = _run(schedule, poll_each_message=True, **kw)
    assert [(x.start_ns, x.end_ns) for x in wins] == [
        (1_000 * MS, pytest.approx(stop, abs=5 * MS)),  # closed at the last sample before the stall
        (resume, resume + 2_000 * MS),  # the touch after the stall, from its first sample to its release
    ]
    assert [x.exploration_id for x in wins] == [1, 2]
    assert w.faults["stall"] == 1
    # bounded work: a few steps per poll (onset, release, the stall's edges), never one per sample
    assert len(steps) <= 2 * polls + 10
    ref, _, _ = _run(schedule, poll_each_message=False, **kw)
    assert _windows(wins) == _windows(ref)
