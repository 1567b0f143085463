"""The classifier's label protocol (core.labels): matching, holding, expiry, duplicates, name limits."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_descriptors_ros.core.labels import EXPIRED, HELD, LEARN, REFUSED, LabelProtocol
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
