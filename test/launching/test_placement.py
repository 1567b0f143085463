"""The launcher starts a node under a command prefix (where it runs) with its own environment."""

from __future__ import annotations

import sys

import pytest

from tactile_descriptors_ros.errors import ConfigError
from tactile_descriptors_ros.launching import graph, processes
from tactile_descriptors_ros.launching.graph import NodeSpec
from tactile_descriptors_ros.launching.processes import GraphProcesses

REPORT = "import os; print(os.getpid(), os.environ.get('PLACED'), os.environ.get('OWN'), os.environ.get('SHARED'))"


def test_a_prefixed_node_keeps_its_process_id_and_gets_its_own_environment(monkeypatch, tmp_path):
    monkeypatch.setattr(processes, "node_command", lambda spec, params_file, python=None: [sys.executable, "-c", REPORT])
    specs = [NodeSpec("a", "window_node"), NodeSpec("b", "window_node")]
    procs = GraphProcesses(specs, env={"SHARED": "s", "PATH": "/usr/bin:/bin"}, output=None, workdir=tmp_path,
                           prefix={"a": ["env", "PLACED=yes"]}, node_env={"a": {"OWN": "1"}})
    procs.start()
    for n in procs.nodes:
        assert n.process.wait(30) == 0
    procs.stop()
    a, b = procs.nodes
    assert a.lines == [f"{a.process.pid} yes 1 s"]  # env execs the command: the pid signals reach is the node's
    assert b.lines == [f"{b.process.pid} None None s"]


def test_placing_a_node_that_is_not_in_the_graph_is_refused():
    with pytest.raises(ConfigError, match="no node named 'c'"):
        GraphProcesses([NodeSpec("a", "window_node")], output=None, prefix={"c": ["env"]})


def test_a_node_whose_message_package_is_missing_is_left_out_and_named(monkeypatch, tmp_path, capsys):
    # a venv of PyPI wheels alone has no tf2_msgs: tf_publisher would end at once with an ImportError and, ending,
    # stop the graph; the launcher starts the others and says which node it left out and which package is missing
    monkeypatch.setitem(graph.NOT_ON_PYPI, "tf_publisher", "tactile_no_such_msgs")
    monkeypatch.setattr(processes, "node_command", lambda spec, params_file, python=None: [sys.executable, "-c", REPORT])
    procs = GraphProcesses([NodeSpec("a", "window_node"), NodeSpec("frames", "tf_publisher")],
                           env={"PATH": "/usr/bin:/bin"}, output=None, workdir=tmp_path)
    assert [s.name for s in procs.specs] == ["a"]
    procs.start()
    assert [n.spec.name for n in procs.nodes] == ["a"]
    assert procs.nodes[0].process.wait(30) == 0
    procs.stop()
    said = capsys.readouterr().err  # output=None keeps the nodes' lines quiet, not the note
    assert "frames (tf_publisher) left out" in said and "tactile_no_such_msgs" in said, said


def test_an_installed_message_package_keeps_its_node(monkeypatch):
    specs = [NodeSpec("frames", "tf_publisher"), NodeSpec("a", "window_node")]
    monkeypatch.setitem(graph.NOT_ON_PYPI, "tf_publisher", "yaml")  # an installed top-level package
    assert graph.unrunnable(specs) == {}
    monkeypatch.setitem(graph.NOT_ON_PYPI, "tf_publisher", "tactile_no_such_msgs")
    assert list(graph.unrunnable(specs)) == ["frames"]


def test_a_graph_of_only_unrunnable_nodes_is_refused(monkeypatch):
    monkeypatch.setitem(graph.NOT_ON_PYPI, "tf_publisher", "tactile_no_such_msgs")
    with pytest.raises(ConfigError, match="no node can start here: frames .*tactile_no_such_msgs"):
        GraphProcesses([NodeSpec("frames", "tf_publisher")], output=None)
