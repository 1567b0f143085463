"""The views' CPU on the NAO graph at full rate, against the same graph without them (``tactile bench --view-overhead``).

What the views add to the NAO's graph is the contact node's display
(markers, images and ``tactile/contacts`` at ``view.rate_hz``, and the
display bookkeeping per frames message) and the ``tactile view`` process.
The frames come at the sensors' full rate, which a loaded machine cannot
guarantee when the simulator and the skin driver must produce it: a probe
(the bench process, as ``tactile bench --latency`` does) publishes the NAO's
frames itself, one ``SkinPartFrames`` per body part every 10 ms of sample
time (the shipped ``batch_s``: 700 messages/s, accelerometer 1 kHz and force
250 Hz per cell), stamped with the wall clock, into the contact node started
as ``tactile launch nao`` starts it (its own process, the robot
description's parameters).  One body part at a time is touched, for
:data:`TOUCH_S` each, its cells pressed with 0.7-1.7 N drawn afresh for
every message, the others resting below the contact floor; at every change
of touch the probe publishes a descriptor and a prediction (the markers'
text, the view's history).  Each run is one of:

* **with the view**: the contact node as shipped (display at 10 Hz) and
  ``tactile view`` serving one page that reads every frame (a reader of its
  event stream, as a browser tab);
* **without**: the contact node with its display off (``view.rate_hz: 0``:
  no markers, images or ``tactile/contacts``, no display bookkeeping) and no
  ``tactile view``.

``rounds`` pairs of runs alternate the two (without, with; with, without;
...) so that a change of the machine's load falls on both.  A run waits
until the contact node answers (its first contacts, and the page's first
frame), lets it settle ``settle_s``, then measures ``seconds``: the CPU
(user + system, psutil) of the contact node and of ``tactile view``, the
contacts the node published per second (or counted: nobody subscribes to
them here, and ``contact.lazy`` neither builds nor publishes them), the
display's own CPU the node
counts (thread time of its display ticks and of its bookkeeping per
message, in its ``/diagnostics``), and how late the probe published.

The overhead is the display's CPU at full rate (the node's own count per
tick times 10 ticks/s plus per message times 700 messages/s: what it costs
whatever rate a loaded machine let the node keep) plus ``tactile view``'s
CPU (driven by the display rate, not the frame rate), as a share of one
core; the target is under :data:`TARGET_PERCENT`.  Beside it, the baseline:
the contact node's CPU with the views less without (mean of the rounds), a
check of the count that is exact only when both runs kept the full rate.
Measured runs on one machine, never a timed assertion: the load average,
the rounds' spread and whether the full rate was kept are part of the
result.
"""

from __future__ import annotations

import array
import json
import os
import random
import re
import signal
import subprocess
import sys
import threading
import time
import urllib.request
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["TARGET_PERCENT", "TOUCH_S", "measure", "format_view_overhead"]

#: The views' overhead on the NAO graph at full rate must stay under this share of one core [%].
TARGET_PERCENT = 10.0
#: How long the probe touches one body part before the next [s].
TOUCH_S = 2.5
#: Force of a touched cell, untared counts (0.7-1.7 N); resting cells 0-20 counts (under 0.05 N).
PRESSED_COUNTS = (300, 700)
RESTING_COUNTS = (0, 20)
#: Longest wait for the contact node's (and the page's) first answer [s].
START_S = 180.0
#: The full rate is kept when the probe offered and the contact node answered at least this share of it.
KEPT_FRACTION = 0.95
#: A run with the views measures until the contact node ticked and the page got a frame this often at least.
MIN_FRAMES = 5
#: The NAO's full rate: 7 body parts, one frames message per 10 ms each [messages/s] (checked in measure).
FULL_RATE = 700
#: The shipped display rate of the NAO (``view.rate_hz``) [Hz] (checked in measure).
RATE_HZ = 10.0


def _published(url: str) -> int:
    """Frames ``tactile view`` has published so far (its ``/api/stats``)."""
    with urllib.request.urlopen(url + "api/stats", timeout=30) as r:
        return int(json.loads(r.read())["published"])


def _read_page(url: str, stop: threading.Event, counts: dict) -> None:
    """A page that reads every frame of the event stream (as a browser tab of ``tactile view`` does)."""
    try:
        with urllib.request.urlopen(url + "events", timeout=60) as r:
            while not stop.is_set():
                line = r.readline()
                if not line:
                    return
                if line.startswith(b"event: frame"):
                    counts["frames"] = counts.get("frames", 0) + 1
    except OSError as exc:  # the view stopped under the reader
        counts["error"] = str(exc)


class _Probe:
    """The bench's node: NAO frames at full rate, a descriptor and a prediction per touch, the diagnostics read."""

    def __init__(self, context, robot, batch_s: float, seed: int) -> None:
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        from tactile_descriptors_msgs.msg import Descriptor, Prediction, SkinPartFrames
        from tactile_descriptors_ros.topics import DESCRIPTOR_TOPIC, FRAMES_TOPIC, PREDICTION_TOPIC

        from .latency import probe_frames

        self.robot, self.batch_s = robot, batch_s
        self.node = rclpy.create_node("tactile_view_overhead_probe", context=context)
        self.frames = {p.name: self.node.create_publisher(SkinPartFrames, FRAMES_TOPIC.format(body_part=p.name),
                                                          QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE))
                       for p in robot.body_parts}
        reliable = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        self.descriptor = self.node.create_publisher(Descriptor, DESCRIPTOR_TOPIC, reliable)
        self.prediction = self.node.create_publisher(Prediction, PREDICTION_TOPIC, reliable)
        self.Descriptor, self.Prediction = Descriptor, Prediction
        self.resting = probe_frames(robot, batch_s, seed, RESTING_COUNTS)
        self.rng = np.random.default_rng(seed)
        self.diagnostics: list[tuple[float, dict[str, float]]] = []  # (arrival, the contact node's counters)
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 50)
        self.ex = SingleThreadedExecutor(context=context)
        self.ex.add_node(self.node)
        self.k = 0
        self.start_ns = (time.time_ns() // self.resting.period_ns + 1) * self.resting.period_ns
        self.lags_ms: list[float] = []
        self.sent = 0

    def _on_diagnostics(self, msg) -> None:
        for st in msg.status:
            if st.name.startswith("contact_node"):
                values = {}
                for kv in st.values:
                    try:
                        values[kv.key] = float(kv.value)
                    except ValueError:
                        continue
                if "contacts_published" in values:
                    self.diagnostics.append((time.monotonic(), values))

    def contacts(self) -> int:
        """The frames messages whose contact the node published or, with nobody subscribed to it
        (``contact.lazy``), counted, by its last report."""
        return int(_contacts(self.diagnostics[-1][1])) if self.diagnostics else 0

    def subscribed(self) -> bool:
        return all(p.get_subscription_count() > 0 for p in self.frames.values())

    def _touch(self, touch: int) -> None:
        """A new touch: its descriptor (the touched part in contact) and its prediction."""
        names = [p.name for p in self.robot.body_parts]
        touched = names[touch % len(names)]
        d = self.Descriptor(robot=self.robot.name, exploration_id=touch + 1, body_parts=names,
                            contact=[n == touched for n in names])
        classes = ["cork", "felt", "steel"]
        p = self.Prediction(exploration_id=touch + 1, has_model=True, class_name=classes[touch % 3],
                            class_names=classes, scores=[1.0 if c == classes[touch % 3] else -1.0 for c in classes])
        d.window_end = p.window_end = self._stamp(time.time_ns())
        self.descriptor.publish(d)
        self.prediction.publish(p)

    @staticmethod
    def _stamp(t_ns: int):
        from tactile_descriptors_ros.nodes.conversions import ns_to_stamp

        return ns_to_stamp(t_ns)

    def run(self, seconds: float, until: Callable[[], bool] | None = None) -> None:
        """Publish at full rate for ``seconds`` (or until ``until()``), answering diagnostics in between."""
        from .latency import set_sequence

        batch_ns = int(round(self.batch_s * 1e9))
        per_touch = int(round(TOUCH_S / self.batch_s))
        end = time.monotonic() + seconds
        while time.monotonic() < end and not (until is not None and until()):
            t0 = self.start_ns + self.k * batch_ns
            delay = (t0 + batch_ns - time.time_ns()) / 1e9  # every sample of the batch has been taken
            if delay > 0:
                self.ex.spin_once(timeout_sec=delay)
                continue
            touch = self.k // per_touch
            if self.k % per_touch == 0:
                self._touch(touch)
            touched = self.robot.body_parts[touch % len(self.robot.body_parts)].name
            stamp = self._stamp(t0)
            sent = time.time_ns()
            for name, msg in self.resting.templates[self.k % len(self.resting.templates)]:
                msg.header.stamp = stamp
                set_sequence(msg, self.k)
                if name == touched:
                    msg = _pressed(msg, self.rng)
                self.frames[name].publish(msg)
            self.lags_ms.append((sent - (t0 + batch_ns)) / 1e6)
            self.sent += len(self.frames)
            self.k += 1
            self.ex.spin_once(timeout_sec=0.0)

    def change(self, t0: float, t1: float) -> tuple[float, dict[str, float]] | None:
        """The contact node's counters from its last report before ``t0`` to its first after ``t1``.

        Returns the seconds between the two reports and each counter's change, None without both.
        """
        before = [s for s in self.diagnostics if s[0] <= t0]
        after = [s for s in self.diagnostics if s[0] >= t1]
        if not before or not after:
            return None
        (a_t, a), (b_t, b) = before[-1], after[0]
        return b_t - a_t, {k: b[k] - a[k] for k in b if k in a}

    def close(self) -> None:
        self.ex.shutdown()
        self.node.destroy_node()


def _contacts(values: dict[str, float]) -> float:
    """A contact node's report (or a change of it): contacts published plus those nobody subscribed to."""
    return values["contacts_published"] + values.get("contacts_unsubscribed", 0.0)


def _pressed(template, rng: np.random.Generator):
    """A copy of a resting message whose cells are pressed, with forces drawn afresh."""
    from tactile_descriptors_msgs.msg import SkinPartFrames

    msg = SkinPartFrames()
    for field in SkinPartFrames.get_fields_and_field_types():
        setattr(msg, field, getattr(template, field))
    n = len(template.force)
    msg.force = array.array("H", rng.integers(*PRESSED_COUNTS, n).astype(np.uint16).tobytes())
    return msg


def _run(display: bool, seconds: float, settle_s: float, context, seed: int,
         progress: Callable[[str], None]) -> dict[str, Any]:
    import psutil

    from tactile_descriptors_ros.core.robot import load_robot
    from tactile_descriptors_ros.launching.graph import build_graph
    from tactile_descriptors_ros.launching.processes import GraphProcesses, localhost_environment

    robot = load_robot("nao")
    batch_s = float(robot.nodes["skin_driver"]["parameters"]["batch_s"])
    overrides = {} if display else {"contact_node": {"view.rate_hz": 0.0}}
    specs = [s for s in build_graph(robot, overrides=overrides) if s.executable == "contact_node"]
    env = localhost_environment()
    graph = GraphProcesses(specs, env=env, output=None)
    probe = _Probe(context, robot, batch_s, seed)
    view = None
    stop = threading.Event()
    counts: dict = {}
    label = "with the view" if display else "without"
    try:
        graph.start()
        contact = psutil.Process(graph.nodes[0].process.pid)
        progress(f"{label}: starting")
        deadline = time.monotonic() + START_S
        while not probe.subscribed() and time.monotonic() < deadline and not graph.exited():
            probe.ex.spin_once(timeout_sec=0.2)
        probe.run(START_S, until=lambda: probe.contacts() > 0 or bool(graph.exited()))
        if graph.exited():
            n = graph.exited()[0]
            raise RuntimeError(f"the contact node exited with {n.returncode}: " + "\n".join(n.lines[-10:]))
        if probe.contacts() <= 0:
            raise RuntimeError(f"the contact node published no contact within {START_S:g} s")
        procs = {"contact_node": contact}
        url = None
        if display:
            view = subprocess.Popen([sys.executable, "-m", "tactile_descriptors_ros.tools.cli", "view", "--port", "0"],
                                    stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env,
                                    start_new_session=True)
            m = re.search(r"http://\S+/", view.stdout.readline())
            if m is None:
                raise RuntimeError("tactile view printed no address")
            url = m.group(0)
            threading.Thread(target=_read_page, args=(url, stop, counts), daemon=True).start()
            probe.run(START_S, until=lambda: counts.get("frames", 0) > 0)
            if not counts.get("frames"):
                raise RuntimeError(f"the page got no frame from tactile view within {START_S:g} s")
            procs["tactile_view"] = psutil.Process(view.pid)
        probe.run(settle_s)
        progress(f"{label}: measuring {seconds:g} s")
        published0 = _published(url) if url else 0
        before = {k: p.cpu_times() for k, p in procs.items()}
        frames0, sent0, lag0 = counts.get("frames", 0), probe.sent, len(probe.lags_ms)
        t0 = time.monotonic()
        ticks0 = probe.diagnostics[-1][1].get("display_ticks", 0.0)
        probe.run(seconds)
        if display:  # a node starved of CPU ticks rarely: measure on until it has shown a few frames
            probe.run(START_S, until=lambda: counts.get("frames", 0) - frames0 >= MIN_FRAMES
                      and probe.diagnostics[-1][1].get("display_ticks", 0.0) - ticks0 >= MIN_FRAMES)
        t1 = time.monotonic()
        after = {k: p.cpu_times() for k, p in procs.items()}
        published = (_published(url) - published0) if url else 0
        frames1, sent1, lags = counts.get("frames", 0), probe.sent, np.array(probe.lags_ms[lag0:])
        probe.run(30.0, until=lambda: probe.diagnostics[-1][0] >= t1)  # the node's first report after the stretch
        cpu = {k: 100.0 * ((after[k].user + after[k].system) - (before[k].user + before[k].system)) / (t1 - t0)
               for k in procs}
        out = {"display": display, "wall_s": t1 - t0, "cpu_core_percent": cpu,
               "probe_messages_per_s": (sent1 - sent0) / (t1 - t0),
               "probe_lag_ms_p95": float(np.percentile(lags, 95)) if lags.size else None,
               "contacts_per_s": None, "page_frames": frames1 - frames0, "load_avg": list(os.getloadavg())}
        if display:
            out["view_frames_per_s"] = published / (t1 - t0)
            out["view_cpu_ms_per_frame"] = (10.0 * cpu["tactile_view"] * (t1 - t0) / published) if published else None
        change = probe.change(t0, t1)
        if change is not None:
            span_s, d = change
            out["contacts_per_s"] = _contacts(d) / span_s
            if display and d.get("display_ticks") and d.get("display_merges"):
                out["display_tick_cpu_ms"] = d["display_tick_cpu_ms"] / d["display_ticks"]
                out["display_merge_cpu_us"] = 1e3 * d["display_merge_cpu_ms"] / d["display_merges"]
                out["display_ticks_per_s"] = d["display_ticks"] / span_s
        return out
    finally:
        stop.set()
        if view is not None and view.poll() is None:
            os.killpg(view.pid, signal.SIGINT)
            try:
                view.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(view.pid, signal.SIGKILL)
                view.wait()
        graph.stop()
        probe.close()


def measure(seconds: float = 30.0, settle_s: float = 5.0, rounds: int = 2,
            progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Both kinds of run, ``rounds`` times each, alternating, and the views' overhead (see the module docstring)."""
    if rounds < 1 or not seconds > 0 or settle_s < 0:
        raise ValueError("rounds and seconds must be positive, settle_s at least 0")
    from tactile_descriptors_ros.core.robot import load_robot

    robot = load_robot("nao")
    batch_s = float(robot.nodes["skin_driver"]["parameters"]["batch_s"])
    if (round(len(robot.body_parts) / batch_s), robot.view.rate_hz) != (FULL_RATE, RATE_HZ):
        raise RuntimeError(f"the NAO's description changed: {len(robot.body_parts)} body parts at batch_s {batch_s}, "
                           f"view.rate_hz {robot.view.rate_hz}; update FULL_RATE and RATE_HZ")
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 100)))
    import rclpy

    say = progress or (lambda _text: None)
    context = rclpy.Context()
    rclpy.init(context=context)
    runs: list[dict[str, Any]] = []
    try:
        for r in range(rounds):
            for display in ((False, True) if r % 2 == 0 else (True, False)):
                runs.append(_run(display, seconds, settle_s, context, seed=len(runs),
                                 progress=lambda text, r=r: say(f"round {r + 1}/{rounds}, {text}")))
    finally:
        rclpy.shutdown(context=context)
    on = [r for r in runs if r["display"]]
    off = [r for r in runs if not r["display"]]
    diffs = [a["cpu_core_percent"]["contact_node"] - b["cpu_core_percent"]["contact_node"] for a, b in zip(on, off)]
    own = [r for r in on if "display_tick_cpu_ms" in r]
    served = [r["view_cpu_ms_per_frame"] for r in on if r["view_cpu_ms_per_frame"] is not None]
    if not own or not served:
        raise RuntimeError("the contact node reported no display ticks, or tactile view published no frame, while "
                           "they were measured")
    tick_ms = float(np.mean([r["display_tick_cpu_ms"] for r in own]))
    merge_us = float(np.mean([r["display_merge_cpu_us"] for r in own]))
    frame_ms = float(np.mean(served))
    # at full rate: every display tick (view.rate_hz) and a merge per frames message in the contact node, a
    # frame per display tick in tactile view ([ms per s] / 10 = % of one core)
    display = (tick_ms * RATE_HZ + merge_us * 1e-3 * FULL_RATE) / 10.0
    server = frame_ms * RATE_HZ / 10.0
    total = display + server
    kept = all(r["contacts_per_s"] is not None and r["contacts_per_s"] >= KEPT_FRACTION * FULL_RATE
               and r["probe_messages_per_s"] >= KEPT_FRACTION * FULL_RATE for r in runs)
    return {"rounds": rounds, "seconds": seconds, "touch_s": TOUCH_S, "runs": runs,
            "display_tick_cpu_ms": tick_ms, "display_merge_cpu_us": merge_us, "view_cpu_ms_per_frame": frame_ms,
            "contact_node_display_percent": display, "tactile_view_percent": server, "view_overhead_percent": total,
            "tactile_view_measured_percent": float(np.mean([r["cpu_core_percent"]["tactile_view"] for r in on])),
            "contact_node_display_difference_percent": float(np.mean(diffs)),
            "contact_node_display_difference_percent_per_round": diffs,
            "contact_node_without_view_percent": float(np.mean([r["cpu_core_percent"]["contact_node"] for r in off])),
            "full_rate_messages_per_s": FULL_RATE, "kept_full_rate": kept,
            "target_percent": TARGET_PERCENT, "met": bool(total < TARGET_PERCENT)}


def format_view_overhead(r: dict[str, Any]) -> str:
    """The report of :func:`measure` as text."""
    def each(key: str, fmt: str) -> str:
        return ", ".join("-" if x[key] is None else format(x[key], fmt) for x in r["runs"] if key in x)

    per_round = ", ".join(f"{d:.1f}" for d in r["contact_node_display_difference_percent_per_round"])
    return "\n".join([
        f"views' overhead on the NAO graph at full rate ({r['rounds']} rounds of {r['seconds']:g} s with and "
        f"without the views, alternating; one body part touched at a time, {r['touch_s']:g} s each):",
        f"  contact node's display at full rate: {r['contact_node_display_percent']:.1f} % of one core "
        f"({r['display_tick_cpu_ms']:.2f} ms per tick x 10/s, {r['display_merge_cpu_us']:.1f} us per message "
        f"x {r['full_rate_messages_per_s']}/s)",
        f"  tactile view with one page reading every frame, at full rate: {r['tactile_view_percent']:.1f} % "
        f"({r['view_cpu_ms_per_frame']:.2f} ms per frame x 10/s; measured {r['tactile_view_measured_percent']:.1f} % "
        f"at {each('view_frames_per_s', '.1f')} frames/s)",
        f"  overhead: {r['view_overhead_percent']:.1f} % of one core; target < {r['target_percent']:g} %: "
        f"{'met' if r['met'] else 'NOT met'}",
        f"  baseline: contact node with the views less without: {r['contact_node_display_difference_percent']:.1f} % "
        f"(per round: {per_round}); without the views: {r['contact_node_without_view_percent']:.1f} %",
        f"  per run (without/with as run): messages offered/s {each('probe_messages_per_s', '.0f')}; contacts/s "
        f"{each('contacts_per_s', '.0f')} (full rate {r['full_rate_messages_per_s']}: "
        f"{'kept' if r['kept_full_rate'] else 'NOT kept on this machine'}); probe lag p95 ms "
        f"{each('probe_lag_ms_p95', '.1f')}",
        f"  load average (1 min) after each run: {', '.join(format(x['load_avg'][0], '.1f') for x in r['runs'])}",
    ])
