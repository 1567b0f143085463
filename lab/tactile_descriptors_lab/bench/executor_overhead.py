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

``layouts`` says what a message holds (:data:`LAYOUTS`): ``part`` the NAO's
largest body part at 700 messages a second (the first measure); ``parts``
every body part in turn, 700 a second, the NAO's samples as the shipped graph
sends them; ``robot`` every cell of the robot in one message a batch, 100 a
second, the same samples.  For the last two the report gives the CPU per
cell and second of data, and ``robot_over_parts``: what taking one message
a batch for the whole robot would cost beside one per body part, in the
subscriber (executor, DDS, rclpy, conversion; not what a node does with the
samples).
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

__all__ = ["TAKEN", "LAYOUTS", "measure", "format_executor_overhead", "subscribe"]

#: Messages a second: the NAO graph's frames messages (7 body parts x 100 batches a second).
RATE_HZ = 700.0
#: Batches a second (10 ms batches, the skin driver's shipped ``batch_s``).
BATCHES_HZ = 100.0
#: What one message holds (module docstring).
LAYOUTS = ("part", "parts", "robot")
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


def subscribe(kind: str, expected: int, checksums: Sequence[int], taken: str = "message",
              rate_hz: float = RATE_HZ) -> dict:
    """The subscriber process's work: spin in ``kind`` until ``expected`` messages came or 60 s of silence;
    ``taken`` as :data:`TAKEN`; ``rate_hz`` the messages a second sent (bounds the wait)."""
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
    watchdog = threading.Timer(MATCH_S + expected / rate_hz + 60.0, rclpy.try_shutdown)
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


def _messages(layout: str = "part", seed: int = 0) -> tuple[list, float, int]:
    """The NAO's probe messages (the latency bench's) of a layout (:data:`LAYOUTS`) over a period of 10 ms
    batches, sent in this order; the messages a second that are the graph's full rate; cells a batch."""
    from tactile_descriptors_lab.bench.latency import probe_frames
    from tactile_descriptors_ros.core.robot import load_robot

    if layout not in LAYOUTS:
        raise ValueError(f"layout must be one of {', '.join(LAYOUTS)}, got {layout!r}")
    desc = load_robot("nao")
    frames = probe_frames(desc, 1.0 / BATCHES_HZ, seed, whole_robot=layout == "robot")
    cells = sum(len(p.cells) for p in desc.body_parts)
    if layout == "part":
        part = max(range(len(desc.body_parts)), key=lambda i: len(desc.body_parts[i].cells))
        return [template[part][1] for template in frames.templates], RATE_HZ, len(desc.body_parts[part].cells)
    msgs = [msg for template in frames.templates for _, msg in template]
    return msgs, BATCHES_HZ * len(frames.templates[0]), cells


def _one_run(kind: str, seconds: float, env: dict[str, str], taken: str = "message", layout: str = "part") -> dict:
    import rclpy
    from rclpy.node import Node

    from tactile_descriptors_lab.bench.latency import set_sequence

    msgs, rate_hz, cells = _messages(layout)
    expected = int(round(seconds * rate_hz))
    base = [_checksum(msg) for msg in msgs]
    args = json.dumps({"kind": kind, "expected": expected, "checksums": base, "taken": taken, "rate_hz": rate_hz})
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
        start, cpu0 = time.monotonic(), time.process_time()
        for k in range(expected):
            msg = msgs[k % len(msgs)]
            set_sequence(msg, k)
            pub.publish(msg)
            ahead = start + (k + 1) / rate_hz - time.monotonic()
            if ahead > 0:
                time.sleep(ahead)  # pacing the publisher at the full rate
        sent_s, pub_cpu_s = time.monotonic() - start, time.process_time() - cpu0
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
    result.update(expected=expected, sent_s=sent_s, layout=layout, rate_hz=rate_hz, cells_per_batch=cells,
                  publisher_cpu_s=pub_cpu_s, publisher_cpu_us_per_message=1e6 * pub_cpu_s / expected)
    if not (result["received"] == expected and result["in_order"] and result["equal"]):
        raise RuntimeError(f"the {kind} subscriber received {result['received']} of {expected} messages "
                           f"(in order: {result['in_order']}, equal to what was sent: {result['equal']})")
    for side in ("", "publisher_"):  # messages a second x CPU a message / cells = CPU per cell and second of data
        # (the largest body part alone is not a second of the robot's data)
        result[f"{side}cpu_ms_per_cell_second"] = (result[f"{side}cpu_us_per_message"] * rate_hz / cells / 1e3
                                                   if layout != "part" else None)
    return result


def measure(seconds: float = 15.0, rounds: int = 2, kinds: Sequence[str] = ("single", "events"),
            progress: Callable[[str], None] | None = None, taken: Sequence[str] = ("message",),
            layouts: Sequence[str] = ("part",)) -> dict:
    """Alternate ``rounds`` runs of each executor in ``kinds``, each way in ``taken`` (:data:`TAKEN`), each
    layout in ``layouts`` (:data:`LAYOUTS`); the median CPU per message of each (keyed by the executor, with
    ``", bytes"`` for the bytes taken and ``", <layout>"`` for a layout other than ``part``) and the ratios:
    events over single, bytes over message per executor; with ``parts`` and ``robot``, the CPU per cell and
    second of data of each and robot over parts per executor and way."""
    import statistics

    from tactile_descriptors_ros.launching.processes import localhost_environment

    env = localhost_environment()
    env.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 100)))
    os.environ.update({k: env[k] for k in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_DOMAIN_ID")})
    if any(t not in TAKEN for t in taken):
        raise ValueError(f"taken must be among {TAKEN}, got {list(taken)}")
    if not layouts or any(la not in LAYOUTS for la in layouts):
        raise ValueError(f"layouts must be among {LAYOUTS}, got {list(layouts)}")
    runs = []
    for r in range(rounds):
        for kind in kinds:
            for way in taken:
                for layout in layouts:
                    if progress:
                        progress(f"round {r + 1}, {_key(kind, way, layout)}")
                    runs.append(_one_run(kind, seconds, env, way, layout))
    combos = [(k, t, la) for k in kinds for t in taken for la in layouts]

    def median_of(field: str, combo: tuple[str, str, str]) -> float:
        return statistics.median(run[field] for run in runs
                                 if (run["executor"], run["taken"], run["layout"]) == combo)

    per = {_key(*c): median_of("cpu_us_per_message", c) for c in combos}
    report = {"rate_hz": RATE_HZ, "seconds": seconds, "rounds": rounds, "layouts": list(layouts), "runs": runs,
              "cpu_us_per_message": per, "load_average": os.getloadavg()}
    if "single" in per and "events" in per:
        report["events_over_single"] = per["events"] / per["single"]
    if "bytes" in taken and "message" in taken and "part" in layouts:
        report["bytes_over_message"] = {k: per[_key(k, "bytes")] / per[k] for k in kinds}
    whole = [c for c in combos if c[2] != "part"]
    if whole:
        for side in ("", "publisher_"):
            report[f"{side}cpu_ms_per_cell_second"] = {_key(*c): median_of(f"{side}cpu_ms_per_cell_second", c)
                                                       for c in whole}
    if "parts" in layouts and "robot" in layouts:
        for side in ("", "publisher_"):
            cs = report[f"{side}cpu_ms_per_cell_second"]
            report[f"{side}robot_over_parts"] = {_key(k, t): cs[_key(k, t, "robot")] / cs[_key(k, t, "parts")]
                                                 for k in kinds for t in taken}
    return report


def _key(kind: str, taken: str, layout: str = "part") -> str:
    """The report's name of runs of executor ``kind`` taking messages ``taken`` of ``layout``."""
    return ", ".join([kind] + ([taken] if taken != "message" else []) + ([layout] if layout != "part" else []))


def format_executor_overhead(report: dict) -> str:
    layouts = report.get("layouts", ["part"])
    what = {"part": f"one NAO body part's frames at {report['rate_hz']:.0f} messages/s",
            "parts": f"each NAO body part's frames in turn at {report['rate_hz']:.0f} messages/s",
            "robot": f"the whole NAO's frames in one message a batch at {BATCHES_HZ:.0f} messages/s"}
    lines = [f"executor overhead: {'; '.join(what[la] for la in layouts)}, "
             f"{report['seconds']:g} s a run, {report['rounds']} round(s), load {report['load_average'][0]:.1f}"]
    cell_s, pub_s = report.get("cpu_ms_per_cell_second", {}), report.get("publisher_cpu_ms_per_cell_second", {})
    for kind, us in report["cpu_us_per_message"].items():
        extra = (f", {cell_s[kind]:.2f} ms per cell-second (the publisher's {pub_s[kind]:.2f})"
                 if kind in cell_s else "")
        lines.append(f"  {kind:<22} {us:7.0f} us of CPU per message (median of runs){extra}")
    if "events_over_single" in report:
        lines.append(f"  events / single: {report['events_over_single']:.2f}")
    for kind, ratio in report.get("bytes_over_message", {}).items():
        lines.append(f"  {kind}: bytes / message: {ratio:.2f}")
    for kind, ratio in report.get("robot_over_parts", {}).items():
        lines.append(f"  {kind}: one message for the robot / one per body part, per cell-second: {ratio:.2f} "
                     f"(the publisher's {report['publisher_robot_over_parts'][kind]:.2f})")
    return "\n".join(lines)


if __name__ == "__main__":
    spec = json.loads(sys.argv[1])
    print(json.dumps(subscribe(spec["kind"], spec["expected"], spec["checksums"], spec["taken"], spec["rate_hz"])),
          flush=True)
