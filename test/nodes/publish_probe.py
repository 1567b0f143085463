"""A node run by ``run_node`` whose timer callback publishes after Ctrl-C has shut its context down
(test_shutdown.py): the moment a user's Ctrl-C lands while a callback is about to publish.

The callback prints ``in callback`` on stdout, waits until the context is no longer valid (the test sends
SIGINT when it reads that line), then publishes, which fails; it writes ``publish failed`` on stderr and lets the
exception go, as any node's callback would.
"""

import os
import sys
import time

from rclpy.node import Node
from std_msgs.msg import Empty

from tactile_descriptors_ros.nodes.common import StopsQuietly, run_node

WAIT_S = 60.0


class Probe(StopsQuietly, Node):
    def __init__(self, node_name: str = "publish_probe") -> None:
        super().__init__(node_name)
        self.pub = self.create_publisher(Empty, "probe", 1)
        self.timer = self.create_timer(0.01, self.tick)

    def tick(self) -> None:
        self.timer.cancel()
        print("in callback", flush=True)
        deadline = time.monotonic() + WAIT_S
        # until Ctrl-C has shut the context down; polled: rclpy's SIGINT handler runs no on_shutdown
        # callback (an event set by one waited the whole WAIT_S)
        while self.context.ok() and time.monotonic() < deadline:
            time.sleep(0.005)
        try:
            self.pub.publish(Empty())
        except Exception:
            os.write(2, b"publish failed\n")
            raise

    def close(self) -> None:
        os.write(2, b"closed\n")


if __name__ == "__main__":
    sys.exit(run_node(Probe, sys.argv))
