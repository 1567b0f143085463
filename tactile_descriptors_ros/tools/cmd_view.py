"""``tactile view``: the skin in a browser, live from the running graph or from a bag (docs/view.md).

Serves a page (``http://127.0.0.1:8765/`` by default, the port from
``TACTILE_VIEW_PORT`` when set; any browser, nothing to install on the
viewing machine) that shows every body part's cells laid out
by the robot description's geometry, coloured by force, the contact, each
body part's vibration trace, and the predictions with their confidence and
the label history; from a bag with a progress bar to click through it.
``--snapshot out.png`` writes one frame as a PNG instead (matplotlib).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

from ..errors import ConfigError

__all__ = ["DEFAULT_PORT", "PORT_ENV", "register", "run"]

#: The port served when neither ``--port`` nor :data:`PORT_ENV` says another.
DEFAULT_PORT = 8765
#: Environment variable naming the default port (two checkouts or users on one machine: one port each).
PORT_ENV = "TACTILE_VIEW_PORT"


def _port(arg: int | None) -> int:
    """``--port``, else ``$TACTILE_VIEW_PORT``, else :data:`DEFAULT_PORT`."""
    if arg is not None:
        return arg
    raw = os.environ.get(PORT_ENV, "")
    if not raw:
        return DEFAULT_PORT
    try:
        port = int(raw)
    except ValueError:
        port = -1
    if not 0 <= port <= 65535:
        raise ConfigError(f"{raw!r} is not a port (0 to 65535)", key=PORT_ENV, source="environment")
    return port


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("view", help="the skin in a browser (live or from a bag), or a PNG snapshot",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--robot", default=None, help="robot name or YAML path (default: the one the graph or bag names)")
    p.add_argument("--bag", default=None, help="play this bag instead of the live graph")
    p.add_argument("--host", default="127.0.0.1", help="address to serve on (0.0.0.0: every interface)")
    p.add_argument("--port", type=int, default=None,
                   help=f"port (default {DEFAULT_PORT}, or ${PORT_ENV} when set; 0: any free one; the URL is printed)")
    p.add_argument("--speed", type=float, default=1.0, help="bag: recorded seconds per wall second")
    p.add_argument("--namespace", default="", help="live: namespace of the graph's topics")
    p.add_argument("--snapshot", default=None, metavar="PNG",
                   help="write one frame as a PNG and exit: live, the first frame with a body part in contact "
                        "(or the last after --wait); bag, the frame at --at")
    p.add_argument("--at", type=float, default=None, help="bag snapshot: seconds from the bag's start (default: end)")
    p.add_argument("--wait", type=float, default=30.0, help="live snapshot: longest wait for a contact [s]")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout at the end")
    p.set_defaults(func=run)


def _say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def run(args: argparse.Namespace) -> int:
    from ..view.server import Hub

    args.port = _port(args.port)  # a bad $TACTILE_VIEW_PORT is reported before anything starts
    hub = Hub()
    if args.bag:
        from ..view.bag import BagPlayer

        player = BagPlayer(args.bag, hub.publish, robot=args.robot, speed=0.0 if args.snapshot else args.speed)
        config = player.model.config()
        hub.publish("config", config)
        _say(f"tactile view: {args.bag}: robot {config['robot'] or '(unknown)'} ({player.robot_found}), "
             f"{player.duration_s:.1f} s" + (f"; {config['notice']}" if config["notice"] else ""))
        if args.snapshot:
            try:
                frame = player.play_until(args.at)
            finally:
                player.reader.close()
            return _snapshot(args, config, frame)
        player.start()
        return _serve(args, hub, lambda: player.model.config(), player.seek,
                      lambda: player.close(), {"faults": player.faults})
    import rclpy

    from ..view.live import LiveView

    context = rclpy.Context()
    rclpy.init(context=context)
    live = LiveView(hub.publish, robot=args.robot, context=context, namespace=args.namespace).start()
    try:
        if args.snapshot:
            return _live_snapshot(args, live)
        return _serve(args, hub, live.config, None, lambda: None, {})
    finally:
        live.close()
        if context.ok():
            rclpy.shutdown(context=context)


def _snapshot(args: argparse.Namespace, config: dict, frame: dict) -> int:
    from ..view.snapshot import write_snapshot

    path = write_snapshot(config, frame, args.snapshot)
    touching = [p["name"] for p in frame["parts"] if p.get("in_contact")]
    _say(f"tactile view: wrote {path} (t = {frame['t'] if frame['t'] is not None else '-'} s, in contact: "
         f"{', '.join(touching) or 'none'})")
    if args.json:
        print(json.dumps({"snapshot": str(path), "t": frame["t"], "in_contact": touching,
                          "prediction": frame["prediction"]}))
    return 0


def _live_snapshot(args: argparse.Namespace, live) -> int:
    from ..topics import CONTACTS_TOPIC

    deadline = time.monotonic() + args.wait
    frame = None
    while time.monotonic() < deadline:
        live.changed.wait(0.2)
        live.changed.clear()
        if live.error:
            _say(f"tactile view: error: {live.error}")
            return 2
        if live.model is not None and live.contact_arrays:
            frame = live.model.frame()
            if any(p.get("in_contact") for p in frame["parts"]):
                break
    if frame is None:
        _say(f"tactile view: error: nothing on {live.node.resolve_topic_name(CONTACTS_TOPIC)} within "
             f"{args.wait:g} s (is the contact node running, in this ROS_DOMAIN_ID?)")
        return 2
    if not any(p.get("in_contact") for p in frame["parts"]):
        _say(f"tactile view: no body part touched within {args.wait:g} s; the last frame is drawn")
    return _snapshot(args, live.model.config(), frame)


def _serve(args: argparse.Namespace, hub, config, seek, close, extra: dict) -> int:
    from ..view.server import ViewServer

    server = ViewServer(hub, config, seek=seek, host=args.host, port=args.port).start()
    source = f"bag {args.bag}" if args.bag else "live from the ROS graph"
    print(f"tactile view: {server.url} ({source}); Ctrl-C stops", flush=True)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        pass
    finally:
        stats = hub.stats()
        close()
        server.close()
    _say(f"tactile view: stopped; {stats['published']} frames published, {stats['dropped']} dropped for slow pages, "
         f"{stats['disconnects']} pages disconnected")
    if args.json:
        print(json.dumps({"url": server.url, **stats, **extra}))
    return 0
