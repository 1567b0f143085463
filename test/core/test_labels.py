"""The classifier's label protocol (core.labels): matching, holding, expiry, duplicates, name limits."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_descriptors_ros.core.labels import EXPIRED, HELD, LEARN, REFUSED, LabelProtocol, StampOrder
from tactile_descriptors_ros.errors import ConfigError


def test_late_label_learns_its_own_descriptor_and_zero_means_the_most_recent():
    p = LabelProtocol()
    assert p.add_descriptor(1, "d1") == [] and p.add_descriptor(2, "d2") == []
    d = p.add_label(1, " cork ")
    assert (d.action, d.item, d.class_name) == (LEARN, "d1", "cork")
    d = p.add_label(0, "felt")
    assert (d.action, d.item) == (LEARN, "d2")


def test_early_label_is_held_and_learned_right_after_its_descriptor():
    p = LabelProtocol()
    p.add_descriptor(1, "d1")
    assert p.add_label(3, "cork").action == HELD and p.held == 1
    assert p.add_descriptor(2, "d2") == []
    (d,) = p.add_descriptor(3, "d3")
    assert (d.action, d.item, d.class_name) == (LEARN, "d3", "cork") and p.held == 0


def test_label_for_an_exploration_that_never_comes_expires_counted():
    p = LabelProtocol(expiry_explorations=3)
    p.add_descriptor(1, "d1")
    assert p.add_label(2, "cork").action == HELD   # exploration 2 is dropped (too short)
    assert p.add_descriptor(3, "d3") == [] and p.add_descriptor(4, "d4") == []
    (d,) = p.add_descriptor(5, "d5")                 # three ids past it: it will not come
    assert (d.action, d.exploration_id, d.reason) == (EXPIRED, 2, "label_expired") and "expired" in d.message
    assert p.held == 0 and p.counts["label_expired"] == 1
    late = p.add_label(2, "cork")                    # now too far behind to hold
    assert (late.action, late.reason) == (REFUSED, "unknown_exploration")


def test_second_label_of_one_exploration_is_refused_and_counted():
    p = LabelProtocol()
    p.add_descriptor(4, "d4")
    assert p.add_label(4, "cork").action == LEARN
    same, other, latest = p.add_label(4, "cork"), p.add_label(4, "felt"), p.add_label(0, "felt")
    assert (same.action, same.reason) == (REFUSED, "duplicate_label")
    assert (other.action, other.reason) == (REFUSED, "conflicting_label") and "'cork'" in other.message
    assert (latest.action, latest.reason) == (REFUSED, "conflicting_label")  # 0 names exploration 4 too
    # held labels: the first one wins as well
    assert p.add_label(9, "cork").action == HELD
    assert p.add_label(9, "felt").reason == "conflicting_label"
    (d,) = p.add_descriptor(9, "d9")
    assert d.class_name == "cork"
    assert p.counts["duplicate_label"] == 1 and p.counts["conflicting_label"] == 3


def test_class_names_too_long_empty_or_unprintable_are_refused_and_counted():
    p = LabelProtocol(max_class_name_chars=8)
    p.add_descriptor(1, "d1")
    assert p.add_label(1, "x" * 9).reason == "class_name_too_long"
    assert p.add_label(1, "   ").reason == "empty_label"
    assert p.add_label(1, "a\nb").reason == "bad_class_name"
    assert p.add_label(1, "x" * 8).action == LEARN  # the limit itself is fine, and the refusals left it unlabelled
    assert {k: p.counts[k] for k in ("class_name_too_long", "empty_label", "bad_class_name")} == \
        {"class_name_too_long": 1, "empty_label": 1, "bad_class_name": 1}


def test_unknown_exploration_and_full_hold_are_refused():
    p = LabelProtocol(horizon=2, expiry_explorations=5)
    assert p.add_label(0, "cork").reason == "unknown_exploration"  # nothing seen yet
    for eid in (1, 2, 3):
        p.add_descriptor(eid, f"d{eid}")
    assert p.add_label(1, "cork").action == HELD   # left the horizon but within expiry: held, then expires
    assert p.add_label(4, "cork").action == HELD and p.held == 2
    assert p.add_label(5, "felt").reason == "held_full" and p.held == 2


def test_bad_settings_name_the_parameter():
    with pytest.raises(ConfigError, match="label_expiry_explorations"):
        LabelProtocol(expiry_explorations=0)
    with pytest.raises(ConfigError, match="max_class_name_chars"):
        LabelProtocol(max_class_name_chars=True)


_events = st.lists(st.one_of(
    st.tuples(st.just("d"), st.integers(0, 40)),
    st.tuples(st.just("l"), st.integers(0, 40), st.sampled_from(["a", "b", "", "x" * 70]))), max_size=300)


@settings(max_examples=200, deadline=None)
@given(_events)
def test_every_label_ends_learned_held_or_counted(events):
    """Conservation: each label is learned (at once or later), still held, or counted exactly once."""
    p = LabelProtocol(horizon=5, expiry_explorations=4)
    labels = learned = 0
    for ev in events:
        if ev[0] == "d":
            for d in p.add_descriptor(ev[1], ev[1]):
                learned += d.action == LEARN
                assert d.action in (LEARN, EXPIRED)
        else:
            labels += 1
            d = p.add_label(ev[1], ev[2])
            learned += d.action == LEARN
    refused = sum(p.counts[k] for k in ("empty_label", "class_name_too_long", "bad_class_name",
                                        "unknown_exploration", "duplicate_label", "conflicting_label",
                                        "held_full", "label_expired"))
    assert labels == learned + p.held + refused
    assert learned == p.counts["labels_learned"]


# ---------------------------------------------------------------- StampOrder
_S = 1_000_000_000  # ns per s


def _labelled_session(n: int = 6) -> list[tuple]:
    """Exploration k ends at 10 k + 2 s; its label (id 0, the most recent) is stamped half a second later."""
    events = []
    for k in range(1, n + 1):
        events.append(("d", k, (10 * k + 2) * _S))
        events.append(("l", 0, (10 * k + 2) * _S + _S // 2, f"class{k % 3}"))
    return events


def _run(arrivals: list[tuple[float, tuple]], wait_s: float, tail_s: float = 100.0):
    """Feed ``(arrival_s, event)`` to a StampOrder; return (predictions, updates, protocol, order).

    A prediction is the exploration id with the labels learned before it (what a model would know);
    an update is the exploration id learned with its class."""
    protocol: LabelProtocol = LabelProtocol()
    learned: list[tuple[int, str]] = []
    predictions: list[tuple[int, tuple]] = []

    def predict(eid):
        predictions.append((eid, tuple(learned)))
        return eid

    def apply(decision):
        if decision.action == LEARN:
            learned.append((decision.item, decision.class_name))

    order = StampOrder(protocol, predict, apply, wait_s=wait_s)
    now = 0.0
    for now, ev in arrivals:
        if ev[0] == "d":
            order.add_descriptor(ev[1], ev[2], ev[1], now)
        else:
            order.add_label(ev[1], ev[3], ev[2], now)
    order.poll(now + tail_s)
    return predictions, learned, protocol, order


def _shuffled_arrivals(events: list[tuple], rng, max_delay_s: float) -> list[tuple[float, tuple]]:
    """Each message delayed at random by up to ``max_delay_s`` after its stamp; each stream keeps its order."""
    last = {"d": 0.0, "l": 0.0}
    out = []
    for ev in events:
        t = max(last[ev[0]], ev[2] / _S + rng.uniform(0, max_delay_s))
        last[ev[0]] = t
        out.append((t, ev))
    return sorted(out, key=lambda a: a[0])


def test_stamp_order_gives_one_outcome_whichever_of_a_label_and_a_descriptor_arrives_first():
    import random

    events = _labelled_session()
    in_stamp_order = _run([(e[2] / _S, e) for e in events], wait_s=0.0)
    assert in_stamp_order[1] == [(k, f"class{k % 3}") for k in range(1, 7)]  # every label taught its exploration
    rng = random.Random(7)
    orders = [_shuffled_arrivals(events, rng, max_delay_s=12.0) for _ in range(300)]
    # the orders include each race: a label after the next descriptor, and a label before its own descriptor
    position = [{(e[0], e[2]): i for i, (_, e) in enumerate(o)} for o in orders]
    d, lab = ("d", 22 * _S), ("l", 22 * _S + _S // 2)
    assert any(p[lab] > p[("d", 32 * _S)] for p in position) and any(p[lab] < p[d] for p in position)
    arrival_order = set()
    for arrivals in orders:
        predictions, learned, protocol, order = _run(arrivals, wait_s=30.0)
        assert (predictions, learned) == in_stamp_order[:2]
        assert order.waiting == 0 and order.counts["descriptor_wait_expired"] == 0
        assert order.counts["label_wait_expired"] == 0
        predictions, learned, _, _ = _run(arrivals, wait_s=0.0)  # arrival order, as without StampOrder
        arrival_order.add((tuple(predictions), tuple(learned)))
    # arrival order alone gives other predictions and updates for some of these orders
    assert len(arrival_order) > 1


def test_stamp_order_predicts_at_once_when_no_label_is_due():
    labelled = _run([(0.0, ("d", 1, 2 * _S)), (0.1, ("l", 0, 3 * _S, "cork")), (0.2, ("d", 2, 12 * _S))],
                    wait_s=30.0, tail_s=0.0)
    assert [p[0] for p in labelled[0]] == [1, 2]  # exploration 1 is labelled: 2 is predicted on arrival
    # without labels the second descriptor waits once for a label of the first (it may be in flight); then
    # labels are not being given and nothing waits
    arrivals = [(float(k), ("d", k, (10 * k + 2) * _S)) for k in range(1, 6)]
    predictions, _, _, order = _run(arrivals[:2], wait_s=30.0, tail_s=0.0)
    assert [p[0] for p in predictions] == [1] and order.waiting == 1
    predictions, _, _, order = _run(arrivals, wait_s=3.0, tail_s=0.0)
    assert [p[0] for p in predictions] == [1, 2, 3, 4, 5] and order.waiting == 0
    assert order.counts["descriptor_wait_expired"] == 1


def test_stamp_order_unstamped_labels_apply_on_arrival_and_stamped_id0_names_by_stamp():
    p = LabelProtocol()
    learned = []
    order = StampOrder(p, lambda eid: eid, lambda d: learned.append((d.item, d.class_name)) if d.action == LEARN
                       else None, wait_s=30.0)
    order.add_descriptor(1, 2 * _S, 1, 0.0)
    order.add_label(0, "cork", 0, 0.1)          # unstamped: the most recent descriptor, now
    assert learned == [(1, "cork")]
    order.add_descriptor(2, 12 * _S, 2, 0.2)
    order.add_descriptor(3, 22 * _S, 3, 0.3)     # predicted after 2's wait ran out (no label came)
    order.poll(31.0)
    order.add_label(0, "felt", 13 * _S, 31.1)    # stamped after 2 ended, before 3 ended: names 2, not 3
    assert learned == [(1, "cork"), (2, "felt")]
    assert p.target(0, 23 * _S)[:2] == (3, 22 * _S) and p.target(0, _S)[:2] == (3, 22 * _S)  # before all: ignored


def test_stamp_order_reset_drops_waiting_labels_counted_and_bad_wait_is_refused():
    p = LabelProtocol()
    order = StampOrder(p, lambda eid: eid, lambda d: None, wait_s=30.0)
    order.add_label(0, "cork", 5 * _S, 0.0)      # no descriptor yet: it waits for one
    assert order.waiting == 1
    order.reset()
    assert order.waiting == 0 and order.counts["labels_dropped_by_reset"] == 1
    for bad in (-1.0, float("inf"), float("nan"), True):
        with pytest.raises(ConfigError, match="label_wait_s"):
            StampOrder(p, lambda eid: eid, lambda d: None, wait_s=bad)
