"""The lab's verbs plug into the robot's ``tactile`` through the entry-point group."""

from __future__ import annotations

import importlib.metadata

import pytest

from tactile_descriptors_ros.tools.cli import LAB_VERBS, VERBS_GROUP, build_parser, main


def test_every_lab_verb_the_robot_names_is_an_entry_point_of_the_lab():
    eps = {e.name: e for e in importlib.metadata.entry_points(group=VERBS_GROUP)}
    lab = {n for n, e in eps.items() if e.value.startswith("tactile_descriptors_lab.")}
    assert lab == set(LAB_VERBS)
    assert all(e.dist.name == "tactile_descriptors_lab" for e in eps.values() if e.name in lab)


@pytest.mark.parametrize("verb", LAB_VERBS)
def test_lab_verbs_parse_their_own_options_when_the_lab_is_installed(verb, capsys):
    parser = build_parser()
    with pytest.raises(SystemExit) as stop:
        parser.parse_args([verb, "--help"])
    assert stop.value.code == 0
    help_text = capsys.readouterr().out
    assert help_text.startswith(f"usage: tactile {verb}") and "not installed" not in help_text


def test_a_lab_verb_runs_through_tactile(capsys):
    assert main(["fuzz", "--inputs", "200", "--json"]) == 0
    assert '"violations"' in capsys.readouterr().out
