"""``tactile bench --executor-overhead``: the CPU a node pays per message taken, in each executor it can spin in.

A subscriber process spins one node with one subscription in the package's own
:func:`~tactile_descriptors_ros.nodes.common.spin` (``TACTILE_EXECUTOR``:
``single`` or ``events``) and does nothing in its callback but check the
message; the bench process publishes the NAO's real ``SkinPartFrames`` of one
body part (the window node's input, 10 ms batches) at the graph's full rate,
700 messages a second, reliable, every message kept (a subscriber that falls
behind slows the publisher down: ``sent_s`` says how long sending took).  The subscriber's CPU (all its
threads: the executor, DDS's receive threads, rclpy) from its first message
to its last, divided by the messages between, is the cost per message of
taking one message per callback, as a node that keeps up does.  Correct
first: every message must arrive once, in order, and equal to what was sent
(its arrays' sums), else the run fails.  Runs alternate between the
executors, ``rounds`` times each, so drifting load falls on both.

``taken`` adds the way the nodes take skin frames (``frames.serialized``):
``bytes`` subscribes to the serialised message and reads it in one compiled
pass (:func:`~tactile_descriptors_ros.nodes.conversions.skin_part_from_serialized`),
where ``message`` lets rclpy build it; each executor runs each way in turn.
"""

from __future__ import annotations

import json
import os
import random
import resource
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence

__all__ = ["TAKEN", "measure", "format_executor_overhead", "subscribe"]

#: Messages a second: the NAO graph's frames messages (7 body parts x 100 batches a second).
RATE_HZ = 700.0
#: Wait for the subscriber to match before publishing [s] (a bound, not a delay).
MATCH_S = 60.0
_TOPIC = "executor_overhead/frames"
#: How the subscriber takes the messages: built by rclpy, or as their bytes read by the compiled pass.
TAKEN = ("message", "bytes")


def _qos():
    """Reliable and every message kept: a subscriber that falls behind on a busy machine slows the publisher
    down instead of losing messages (the count per message stays what is measured)."""
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)


def _checksum(msg) -> int:
    """A sum over the message's samples (its sequence number aside): equal sums for equal content."""
    import numpy as np

    return int(sum(np.asarray(a, np.int64) @ np.arange(1, len(a) + 1, dtype=np.int64)
                   for a in (msg.accel_x, msg.accel_y, msg.accel_z, msg.force)))


def subscribe(kind: str, expected: int, checksums: Sequence[int], taken: str = "message") -> dict:
    """The subscriber process's work: spin in ``kind`` until ``expected`` messages came or 60 s of silence;
    ``taken`` as :data:`TAKEN`."""
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.node import Node

    from tactile_descriptors_msgs.msg import SkinPartFrames
    from tactile_descriptors_ros.codecs.cdr import load_compiled
    from tactile_descriptors_ros.nodes.common import spin
    from tactile_descriptors_ros.nodes.conversions import skin_part_from_serialized

    rclpy.init()
    node = Node("executor_overhead_subscriber")
    state = {"n": 0, "in_order": True, "equal": True, "first": None, "last": None}

    serialized = taken == "bytes"
    if serialized and not load_compiled():
        raise RuntimeError("frames taken as bytes need the compiled backend")

    def got(msg) -> None:
        if serialized:
            msg = skin_part_from_serialized(msg)
        k = int(msg.sequence[0])
        state["in_order"] &= k == state["n"]
        state["equal"] &= k < expected and _checksum(msg) == checksums[k % len(checksums)]
        state["n"] += 1
        usage = resource.getrusage(resource.RUSAGE_SELF)
        stamp = (time.monotonic(), usage.ru_utime + usage.ru_stime)
        if state["first"] is None:
            state["first"] = stamp
        state["last"] = stamp
        if state["n"] >= expected:
            rclpy.shutdown()

    node.create_subscription(SkinPartFrames, _TOPIC, got, _qos(), raw=serialized)
    watchdog = threading.Timer(MATCH_S + expected / RATE_HZ + 60.0, rclpy.try_shutdown)
    watchdog.daemon = True
    watchdog.start()
    print("ready", flush=True)
    try:
        spin(node, kind)
    except ExternalShutdownException:  # the last message shut the context down while the executor waited
        pass
    watchdog.cancel()
    (t0, c0), (t1, c1) = state["first"] or (0.0, 0.0), state["last"] or (0.0, 0.0)
    between = max(state["n"] - 1, 0)
    return {"executor": kind, "taken": taken, "received": state["n"], "in_order": state["in_order"], "equal": state["equal"],
            "wall_s": t1 - t0, "cpu_s": c1 - c0,
            "cpu_us_per_message": 1e6 * (c1 - c0) / between if between else None}


def _messages(seed: int = 0) -> list:
    """One body part's probe messages of the NAO (the latency bench's), one per 10 ms batch of a period."""
    from tactile_descriptors_lab.bench.latency import probe_frames
    from tactile_descriptors_ros.core.robot import load_robot

    desc = load_robot("nao")
    frames = probe_frames(desc, 0.01, seed)
    part = max(range(len(desc.body_parts)), key=lambda i: len(desc.body_parts[i].cells))
    return [template[part][1] for template in frames.templates]


def _one_run(kind: str, seconds: float, env: dict[str, str], taken: str = "message") -> dict:
    import rclpy
    from rclpy.node import Node

    from tactile_descriptors_lab.bench.latency import set_sequence

    msgs = _messages()
    expected = int(round(seconds * RATE_HZ))
    base = [_checksum(msg) for msg in msgs]
    args = json.dumps({"kind": kind, "expected": expected, "checksums": base, "taken": taken})
    proc = subprocess.Popen([sys.executable, "-m", __name__, args], env=env, stdout=subprocess.PIPE, text=True)
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node("executor_overhead_publisher", context=context)
    try:
        pub = node.create_publisher(type(msgs[0]), _TOPIC, _qos())
        if proc.stdout.readline().strip() != "ready":
            raise RuntimeError(f"the {kind} subscriber did not start (exit {proc.wait()})")
        deadline = time.monotonic() + MATCH_S
        while pub.get_subscription_count() == 0:
            if time.monotonic() > deadline:
                raise RuntimeError(f"the {kind} subscriber did not match within {MATCH_S:.0f} s")
            time.sleep(0.01)  # polling the match count: rclpy has no wait for it
        start = time.monotonic()
        for k in range(expected):
            msg = msgs[k % len(msgs)]
            set_sequence(msg, k)
            pub.publish(msg)
            ahead = start + (k + 1) / RATE_HZ - time.monotonic()
            if ahead > 0:
                time.sleep(ahead)  # pacing the publisher at the full rate
        sent_s = time.monotonic() - start
        out, _ = proc.communicate(timeout=MATCH_S + seconds + 120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    if proc.returncode != 0:
        raise RuntimeError(f"the {kind} subscriber exited {proc.returncode}")
    result = json.loads(out.strip().splitlines()[-1])
    result.update(expected=expected, sent_s=sent_s)
    if not (result["received"] == expected and result["in_order"] and result["equal"]):
        raise RuntimeError(f"the {kind} subscriber received {result['received']} of {expected} messages "
                           f"(in order: {result['in_order']}, equal to what was sent: {result['equal']})")
    return result


def measure(seconds: float = 15.0, rounds: int = 2, kinds: Sequence[str] = ("single", "events"),
            progress: Callable[[str], None] | None = None, taken: Sequence[str] = ("message",)) -> dict:
    """Alternate ``rounds`` runs of each executor in ``kinds``, each way in ``taken`` (:data:`TAKEN`); the
    median CPU per message of each (keyed by the executor, with ``", bytes"`` for the bytes taken) and the
    ratios: events over single, bytes over message per executor."""
    import statistics

    from tactile_descriptors_ros.launching.processes import localhost_environment

    env = localhost_environment()
    env.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 100)))
    os.environ.update({k: env[k] for k in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_DOMAIN_ID")})
    if any(t not in TAKEN for t in taken):
        raise ValueError(f"taken must be among {TAKEN}, got {list(taken)}")
    runs = []
    for r in range(rounds):
        for kind in kinds:
            for way in taken:
                if progress:
                    progress(f"round {r + 1}, {_key(kind, way)}")
                runs.append(_one_run(kind, seconds, env, way))
    per = {_key(k, t): statistics.median(run["cpu_us_per_message"] for run in runs
                                         if (run["executor"], run["taken"]) == (k, t))
           for k in kinds for t in taken}
    report = {"rate_hz": RATE_HZ, "seconds": seconds, "rounds": rounds, "runs": runs,
              "cpu_us_per_message": per, "load_average": os.getloadavg()}
    if "single" in per and "events" in per:
        report["events_over_single"] = per["events"] / per["single"]
    if "bytes" in taken and "message" in taken:
        report["bytes_over_message"] = {k: per[_key(k, "bytes")] / per[k] for k in kinds}
    return report


def _key(kind: str, taken: str) -> str:
    """The report's name of runs of executor ``kind`` taking messages ``taken``."""
    return kind if taken == "message" else f"{kind}, {taken}"


def format_executor_overhead(report: dict) -> str:
    lines = [f"executor overhead: one NAO body part's frames at {report['rate_hz']:.0f} messages/s, "
             f"{report['seconds']:g} s a run, {report['rounds']} round(s), load {report['load_average'][0]:.1f}"]
    for kind, us in report["cpu_us_per_message"].items():
        lines.append(f"  {kind:<14} {us:7.0f} us of CPU per message (median of runs)")
    if "events_over_single" in report:
        lines.append(f"  events / single: {report['events_over_single']:.2f}")
    for kind, ratio in report.get("bytes_over_message", {}).items():
        lines.append(f"  {kind}: bytes / message: {ratio:.2f}")
    return "\n".join(lines)


if __name__ == "__main__":
    spec = json.loads(sys.argv[1])
    print(json.dumps(subscribe(spec["kind"], spec["expected"], spec["checksums"], spec["taken"])), flush=True)
