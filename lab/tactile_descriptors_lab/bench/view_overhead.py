"""The views' CPU cost on the NAO graph at full rate (docs/view.md): ``python -m tactile_descriptors_lab.bench.view_overhead``.

Two runs of the simulated NAO graph (``touch_nao``, every body part's frames
at 10 ms batches, real time), measured with psutil over the same stretch:

1. the graph as shipped (the contact node draws markers, images and
   ``tactile/contacts`` at the display rate) with ``tactile view`` serving
   one page that reads every frame;
2. the same graph with the contact node's display off (``view.rate_hz: 0``)
   and no ``tactile view``.

The view's overhead is the contact node's CPU difference plus the
``tactile view`` process's CPU, as a share of one core; the contact node's
own frame-rate work (contact and wrench per message) is reported beside it.
A ratio on one machine in one run, never a timed assertion: the machine is
shared and its load is printed.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
import urllib.request
from typing import Any

__all__ = ["measure", "main"]


def _children(pid: int) -> list:
    import psutil

    return psutil.Process(pid).children(recursive=True)


def _node_process(pid: int, executable: str):
    for p in _children(pid):
        try:
            if any(f"nodes.{executable}" in a for a in p.cmdline()):
                return p
        except Exception:  # noqa: BLE001 - a process that ended meanwhile
            continue
    return None


def _cpu_s(proc) -> float:
    t = proc.cpu_times()
    return t.user + t.system


def _read_page(url: str, stop: threading.Event, counts: dict) -> None:
    """A page that reads every frame of the event stream (as a browser tab in view does)."""
    with urllib.request.urlopen(url + "events", timeout=30) as r:
        while not stop.is_set():
            line = r.readline()
            if not line:
                return
            if line.startswith(b"event: frame"):
                counts["frames"] = counts.get("frames", 0) + 1


def _run(seconds: float, display: bool, warm_s: float) -> dict[str, Any]:
    import psutil

    cmd = [sys.executable, "-m", "tactile_descriptors_ros.tools.cli", "launch", "nao", "--sim", "touch_nao"]
    if not display:
        cmd += ["--set", "contact_node.view.rate_hz=0"]
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    graph = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
                             env=env)
    view = None
    stop = threading.Event()
    counts: dict = {}
    try:
        deadline = time.monotonic() + 120
        contact = None
        while contact is None and time.monotonic() < deadline:
            contact = _node_process(graph.pid, "contact_node")
            time.sleep(0.2)  # waiting for a process to appear: psutil offers no event
        if contact is None:
            raise RuntimeError("the contact node did not start")
        if display:
            view = subprocess.Popen([sys.executable, "-m", "tactile_descriptors_ros.tools.cli", "view", "--port", "0"],
                                    stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                                    start_new_session=True, env=env)
            url = re.search(r"http://\S+/", view.stdout.readline()).group(0)
            threading.Thread(target=_read_page, args=(url, stop, counts), daemon=True).start()
        time.sleep(warm_s)  # the graph's start-up (kernel load, discovery) is not what is measured
        procs = {"contact_node": contact}
        if view is not None:
            procs["tactile_view"] = psutil.Process(view.pid)
        before = {k: _cpu_s(p) for k, p in procs.items()}
        wall0 = time.monotonic()
        time.sleep(seconds)  # the measured stretch
        wall = time.monotonic() - wall0
        after = {k: _cpu_s(p) for k, p in procs.items()}
        return {"wall_s": wall, "cpu_core_percent": {k: 100 * (after[k] - before[k]) / wall for k in procs},
                "page_frames": counts.get("frames", 0), "load_avg": list(os.getloadavg())}
    finally:
        stop.set()
        for p in (view, graph):
            if p is not None and p.poll() is None:
                os.killpg(p.pid, signal.SIGINT)
                try:
                    p.wait(timeout=30)
                except subprocess.TimeoutExpired:
                    os.killpg(p.pid, signal.SIGKILL)
                    p.wait()


def measure(seconds: float = 20.0, warm_s: float = 10.0) -> dict[str, Any]:
    """Both runs and the view's overhead [% of one core] (see the module docstring)."""
    on = _run(seconds, True, warm_s)
    off = _run(seconds, False, warm_s)
    display = on["cpu_core_percent"]["contact_node"] - off["cpu_core_percent"]["contact_node"]
    server = on["cpu_core_percent"]["tactile_view"]
    return {"with_view": on, "without_view": off, "contact_node_display_percent": display,
            "tactile_view_percent": server, "view_overhead_percent": display + server,
            "contact_node_frame_rate_percent": off["cpu_core_percent"]["contact_node"],
            "target_percent": 10.0, "met": display + server < 10.0}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m tactile_descriptors_lab.bench.view_overhead", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seconds", type=float, default=20.0, help="measured stretch of each run")
    p.add_argument("--warm", type=float, default=10.0, help="start-up left out of each run [s]")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    r = measure(args.seconds, args.warm)
    if args.json:
        print(json.dumps(r))
    else:
        print(f"view overhead on the NAO graph: {r['view_overhead_percent']:.1f} % of one core "
              f"(contact node's display {r['contact_node_display_percent']:.1f} %, tactile view "
              f"{r['tactile_view_percent']:.1f} %; target 10 %: {'met' if r['met'] else 'not met'}); the contact "
              f"node's frame-rate work {r['contact_node_frame_rate_percent']:.1f} %; load "
              f"{r['with_view']['load_avg'][0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
