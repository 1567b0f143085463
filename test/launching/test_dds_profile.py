"""The graph's nodes take the shipped Fast DDS profile (``config/fastdds.xml``): a 2 MiB shared-memory segment.

With Fast DDS's default segment (512 KiB a participant) a window node of 400 cells lost 2-7 of about 2,100
body-part messages in 20 s (best effort: a message whose buffer is reused before the reader got it is lost
whole); the profile keeps Fast DDS's transports with a larger segment.  Here: which variables carry it and
when a user's own choice wins, what the file says, and that a participant started with them really makes a
segment of that size (Fast DDS's segments are files in ``/dev/shm``), where one without them does not.
"""

from __future__ import annotations

import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from tactile_descriptors_ros.core.yamlreader import config_dir
from tactile_descriptors_ros.launching.graph import build_graph
from tactile_descriptors_ros.launching.processes import (
    DDS_PROFILE,
    DDS_PROFILE_VARIABLES,
    GraphProcesses,
    dds_environment,
    localhost_environment,
)

NS = {"dds": "http://www.eprosima.com"}
SEGMENT_BYTES = 2 * 2**20
SHM = Path("/dev/shm")


def test_the_profile_is_given_unless_the_user_chose_one_or_another_middleware():
    shipped = os.fspath(config_dir() / DDS_PROFILE)
    assert dds_environment({}) == {"FASTDDS_DEFAULT_PROFILES_FILE": shipped, "FASTRTPS_DEFAULT_PROFILES_FILE": shipped}
    assert dds_environment({"RMW_IMPLEMENTATION": "rmw_fastrtps_cpp"}) == dds_environment({})
    assert dds_environment({"RMW_IMPLEMENTATION": "rmw_fastrtps_dynamic_cpp"}) == dds_environment({})
    assert dds_environment({"RMW_IMPLEMENTATION": "rmw_cyclonedds_cpp"}) == {}
    for name in DDS_PROFILE_VARIABLES:  # either variable set (Fast DDS 3 or 2) is the user's profile
        assert dds_environment({name: "/etc/my_profile.xml"}) == {}
    # the launcher's environment carries it, and keeps a user's own
    specs = build_graph("nao")
    assert {k: GraphProcesses(specs, env={}).env[k] for k in DDS_PROFILE_VARIABLES} == dds_environment({})
    own = GraphProcesses(specs, env={"FASTRTPS_DEFAULT_PROFILES_FILE": "/etc/my_profile.xml"}).env
    assert own["FASTRTPS_DEFAULT_PROFILES_FILE"] == "/etc/my_profile.xml" and "FASTDDS_DEFAULT_PROFILES_FILE" not in own


def test_the_shipped_profile_keeps_the_transports_with_a_larger_segment():
    root = ET.parse(config_dir() / DDS_PROFILE).getroot()
    kinds = {d.findtext("dds:transport_id", namespaces=NS): d for d in root.iterfind(".//dds:transport_descriptor", NS)}
    participant = root.find(".//dds:participant", NS)
    assert participant.get("is_default_profile") == "true"
    used = [t.text for t in participant.iterfind("dds:rtps/dds:userTransports/dds:transport_id", NS)]
    assert sorted(kinds[t].findtext("dds:type", namespaces=NS) for t in used) == ["SHM", "UDPv4"]
    shm = next(kinds[t] for t in used if kinds[t].findtext("dds:type", namespaces=NS) == "SHM")
    assert int(shm.findtext("dds:segment_size", namespaces=NS)) == SEGMENT_BYTES
    assert participant.findtext("dds:rtps/dds:useBuiltinTransports", namespaces=NS) == "false"


def _segments() -> dict[str, int]:
    """Fast DDS's shared-memory segments (3.x ``fastdds_<id>``, 2.x ``fastrtps_<id>``; not its ports) -> bytes."""
    out = {}
    for path in SHM.glob("fast*_*"):
        name = path.name
        if name.startswith(("fastdds_", "fastrtps_")) and "port" not in name and not name.endswith("_el"):
            try:
                out[name] = path.stat().st_size
            except FileNotFoundError:  # a stale segment removed meanwhile
                pass
    return out


def _new_segment_sizes(env: dict[str, str]) -> list[int]:
    """Start a participant (an rclpy node) with ``env``; the sizes of the segments that appeared meanwhile."""
    before = _segments()
    code = "import rclpy, sys; rclpy.init(); n = rclpy.create_node('segment_probe'); print('up', flush=True); " \
           "sys.stdin.readline()"
    proc = subprocess.Popen([sys.executable, "-c", code], env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            text=True)
    try:
        assert proc.stdout.readline().strip() == "up"  # the participant exists: its segment was made with it
        return [size for name, size in _segments().items() if name not in before]
    finally:
        proc.stdin.close()
        proc.wait(timeout=60)


@pytest.mark.ros
@pytest.mark.skipif(not SHM.is_dir(), reason="no /dev/shm: Fast DDS's shared-memory transport is not used here")
def test_a_participant_with_the_profile_makes_a_2_mib_segment_and_one_without_it_does_not():
    plain = {k: v for k, v in localhost_environment().items() if k not in DDS_PROFILE_VARIABLES}
    if (plain.get("RMW_IMPLEMENTATION") or "rmw_fastrtps_cpp") != "rmw_fastrtps_cpp":
        pytest.skip(f"RMW_IMPLEMENTATION={plain['RMW_IMPLEMENTATION']}: the profile is for Fast DDS")
    with_profile = _new_segment_sizes({**plain, **dds_environment(plain)})
    without = _new_segment_sizes(plain)
    assert with_profile and max(with_profile) >= SEGMENT_BYTES, with_profile
    assert without and max(without) < SEGMENT_BYTES, without
