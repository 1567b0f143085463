"""The launcher starts a node under a command prefix (where it runs) with its own environment."""

from __future__ import annotations

import sys

import pytest

from tactile_descriptors_ros.errors import ConfigError
from tactile_descriptors_ros.launching import processes
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
