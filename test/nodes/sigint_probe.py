"""A node run by ``run_node`` that Ctrl-C's itself from inside a destructor run by a callback (test_shutdown.py).

Python runs a SIGINT handler at the next bytecode of the main thread: here, inside ``Dropped.__del__``
(as it did inside ``rclpy.task.Future.__del__``).  A handler that raises there can only be printed by
Python ("Exception ignored in ...") and cuts the destructor and the callback short.  Each step writes a line
on stderr once it has run to its end.
"""

import os
import signal
import sys
import time

from rclpy.node import Node

from tactile_descriptors_ros.nodes.common import run_node


class Dropped:
    def __del__(self) -> None:
        os.kill(os.getpid(), signal.SIGINT)
        deadline = time.monotonic() + 0.2
        while time.monotonic() < deadline:  # Python code for the handler to land in
            pass
        os.write(2, b"destructor finished\n")


class Probe(Node):
    def __init__(self, node_name: str = "sigint_probe") -> None:
        super().__init__(node_name)
        self.timer = self.create_timer(0.01, self.tick)

    def tick(self) -> None:
        self.timer.cancel()
        Dropped()
        os.write(2, b"callback finished\n")

    def close(self) -> None:
        os.write(2, b"closed\n")


if __name__ == "__main__":
    sys.exit(run_node(Probe, sys.argv))
