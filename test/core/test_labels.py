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


# ------------------------------------------------------- a hostile or careless domain
def test_class_names_are_nfkc_normalised_and_controls_and_mixed_alphabets_refused():
    p = LabelProtocol()
    for eid in range(1, 8):
        p.add_descriptor(eid, f"d{eid}")
    assert (p.add_label(1, "ｃｏｒｋ").class_name, p.counts["labels_learned"]) == ("cork", 1)  # fullwidth: cork
    for eid, name in ((2, "cork\x00felt"), (3, "\u202ecork"), (4, "\u0441ork"), (5, "cork\u200b")):
        d = p.add_label(eid, name)  # NUL, a bidi override, a Cyrillic es in Latin, a zero-width space
        assert (d.action, d.reason) == (REFUSED, "bad_class_name"), name
    assert p.add_label(6, "日本語テキスト").action == LEARN and p.add_label(7, " Ölfarbe ").class_name == "Ölfarbe"


def test_a_new_class_beyond_max_classes_is_refused_counted():
    p = LabelProtocol(max_classes=3)
    p.known_classes(["cork", "felt"])  # a loaded model's
    for eid in range(1, 6):
        p.add_descriptor(eid, f"d{eid}")
    assert p.add_label(1, "steel").action == LEARN
    d = p.add_label(2, "wood")
    assert (d.action, d.reason) == (REFUSED, "too_many_classes") and "max_classes (3)" in d.message
    assert p.add_label(3, "cork").action == LEARN  # a known class is always taken
    assert p.add_label(9, "glass").reason == "too_many_classes"  # a held label would promise a class too


def test_one_spoofed_huge_exploration_id_switches_nothing_off():
    p = LabelProtocol()
    for eid in (1, 2, 3):
        p.add_descriptor(eid, f"d{eid}")
    assert p.add_descriptor(2**63 - 1, "spoof") == [] and p.counts["exploration_id_out_of_range"] == 1
    assert p.add_label(5, "cork").action == HELD  # still early, not "too far behind"
    p.add_descriptor(4, "d4")
    (d,) = p.add_descriptor(5, "d5")
    assert (d.action, d.item) == (LEARN, "d5")
    far = p.add_label(5 + 1001, "felt")
    assert (far.action, far.reason) == (REFUSED, "exploration_id_too_far")
    # a window node restarted with other ids: two in a row rebase, and labels work there again
    assert p.add_descriptor(50_000, "r1") == [] and p.add_descriptor(50_001, "r2") == []
    assert p.counts["exploration_ids_rebased"] == 1
    assert p.add_label(50_003, "glass").action == HELD and p.add_label(50_001, "glass").action == LEARN


def test_held_labels_expire_by_time_as_well_as_by_id():
    p = LabelProtocol(horizon=100, hold_s=10.0)
    p.add_descriptor(1, "d1", now_s=0.0)
    for eid in range(2, 102):  # labels for 100 explorations that never come fill the hold
        assert p.add_label(eid, "cork", now_s=1.0).action == HELD
    assert p.add_label(102, "felt", now_s=2.0).reason == "held_full"
    assert p.expire(10.9) == []
    expired = p.expire(11.0)
    assert len(expired) == 100 and {d.reason for d in expired} == {"label_expired"} and p.held == 0
    assert "10 s" in expired[0].message
    assert p.add_label(3, "felt", now_s=12.0).action == HELD  # early labels work again


def test_decisions_carry_the_labels_token_through_a_hold():
    p = LabelProtocol()
    p.add_descriptor(1, "d1")
    assert p.add_label(2, "cork", token="call-7").token == "call-7"
    (d,) = p.add_descriptor(2, "d2")
    assert (d.action, d.token) == (LEARN, "call-7")


@pytest.mark.parametrize("bad", [
    {"horizon": 2**62}, {"max_classes": 0}, {"max_id_step": 2**62}, {"hold_s": float("inf")},
    {"hold_s": float("nan")}, {"hold_s": 1e300}, {"max_class_name_chars": 10**6}])
def test_every_protocol_setting_is_checked_completely(bad):
    with pytest.raises(ConfigError):
        LabelProtocol(**bad)


@pytest.mark.parametrize("bad", [{"wait_s": 1e300}, {"wait_s": float("nan")}, {"jump_s": 0.0},
                                 {"jump_s": float("inf")}])
def test_every_stamp_order_setting_is_checked_completely(bad):
    with pytest.raises(ConfigError):
        StampOrder(LabelProtocol(), lambda d: d, lambda d: None, **bad)


# ----------------------------------------------------------- predictions at once
def _race(hold: bool) -> tuple[list, list, list]:
    """Exploration 2's label overtaken by exploration 3's descriptor; (predicted on arrival, predicted, learned)."""
    predictions, learned = [], []
    p = LabelProtocol()
    order = StampOrder(p, lambda eid: predictions.append(eid) or eid,
                       lambda d: learned.append((d.item, d.class_name)) if d.action == LEARN else None,
                       wait_s=30.0, hold_descriptors=hold)
    order.add_descriptor(1, 2 * _S, 1, 0.0)
    order.add_label(0, "cork", 0, 0.1)            # exploration 1 labelled: labels are being given
    order.add_descriptor(2, 12 * _S, 2, 1.0)
    order.add_descriptor(3, 22 * _S, 3, 2.0)     # exploration 2's label is due, and not here yet
    at_arrival = list(predictions)
    order.add_label(0, "felt", 13 * _S, 3.0)      # stamped after 2 ended, before 3 ended
    return at_arrival, predictions, learned


def test_immediate_prediction_never_waits_and_the_late_label_still_teaches_its_exploration():
    """Exploration 1's label (id 0, stamped after 1 ended) reaches the node after exploration 2's descriptor:
    predicted on arrival, exploration 2 does not wait for it, and the label still teaches exploration 1."""
    runs = {hold: _race(hold) for hold in (False, True)}
    at_arrival, predictions, learned = runs[False]
    assert at_arrival == [1, 2, 3] and learned == [(1, "cork"), (2, "felt")]
    at_arrival, predictions, learned = runs[True]  # stamp order: 3 waits for the label due before it
    assert at_arrival == [1, 2] and predictions == [1, 2, 3] and learned == [(1, "cork"), (2, "felt")]


# ------------------------------------------------------------------ jumps back
def _session(first_id: int, ids_from_bag: bool, n: int = 5) -> list[tuple]:
    """A bag's explorations and labels: exploration k ends at 10 k + 2 s, its label half a second later
    (id 0, or the recorded id when ``ids_from_bag``)."""
    events = []
    for k in range(1, n + 1):
        events.append(("d", first_id + k - 1, (10 * k + 2) * _S))
        events.append(("l", k if ids_from_bag else 0, (10 * k + 2) * _S + _S // 2, f"class{k}"))
    return events


@pytest.mark.parametrize("label_first", [False, True])
@pytest.mark.parametrize("hold", [False, True])
def test_a_replay_started_again_is_a_new_session_and_its_labels_teach_the_new_explorations(label_first, hold):
    """The same bag twice through live nodes: the window node's ids go on (6..10), the stamps jump back.
    Every second-pass label (id 0, stamped) teaches its second-pass exploration, whether the first label or
    the first descriptor of the second pass comes first."""
    first, second = _session(1, False), _session(6, False)
    if label_first:  # the second pass's first label overtakes its descriptor
        second[0], second[1] = second[1], second[0]
    predictions, learned = [], []
    p = LabelProtocol()
    order = StampOrder(p, lambda eid: predictions.append(eid) or eid,
                       lambda d: learned.append((d.item, d.class_name)) if d.action == LEARN else None,
                       wait_s=30.0, hold_descriptors=hold)
    now = 0.0
    for ev in first + second:
        now += 0.1
        if ev[0] == "d":
            order.add_descriptor(ev[1], ev[2], ev[1], now)
        else:
            order.add_label(ev[1], ev[3], ev[2], now)
    order.poll(now + 100)
    assert learned == [(k, f"class{k}") for k in range(1, 6)] + [(k + 5, f"class{k}") for k in range(1, 6)]
    assert order.counts["clock_jumps_back"] == 1 and predictions == list(range(1, 11))
    refused = {k for k in p.counts if k in ("duplicate_label", "conflicting_label", "unknown_exploration")}
    assert refused == set()


def test_a_bag_of_descriptors_and_explicit_id_labels_looped_teaches_both_passes():
    """A bag holding the descriptors (ids 1..5) and labels naming them, looped into the classifier: the second
    pass's labels teach the second pass's descriptors instead of being refused as duplicates."""
    learned = []
    p = LabelProtocol()
    order = StampOrder(p, lambda eid: eid, lambda d: learned.append((d.item, d.class_name))
                       if d.action == LEARN else None, wait_s=30.0)
    now = 0.0
    for ev in _session(1, True) + _session(1, True):
        now += 0.1
        if ev[0] == "d":
            order.add_descriptor(ev[1], ev[2], ev[1], now)
        else:
            order.add_label(ev[1], ev[3], ev[2], now)
    order.poll(now + 100)
    assert learned == [(k, f"class{k}") for k in range(1, 6)] * 2
    assert p.counts["duplicate_label"] == 0 and order.counts["clock_jumps_back"] == 1
