"""The node executables' entry points: Ctrl-C is noted before anything heavy is imported.

A node's module imports rclpy, numpy and its message types: on a busy
machine that takes a second or more, and ``ros2 launch`` may stop the
process during it (another node died at start).  Python's default SIGINT
handler would then raise ``KeyboardInterrupt`` inside some import and print
a traceback.  These entry points install the noting handler of
:func:`note_interrupts` first, import the node's module, and return 0 at
once if Ctrl-C came during the import; after that the node's ``main``
(:func:`~tactile_descriptors_ros.nodes.common.run_node`) checks the same
flag once rclpy's own handler is installed.  This module imports only the
standard library.
"""

from __future__ import annotations

import importlib
import signal
import threading
from collections.abc import Callable

__all__ = ["biotac_driver", "classifier_node", "contact_node", "note_interrupts", "skin_driver", "tf_publisher",
           "window_node"]

_interrupted = threading.Event()
_installed = False


def note_interrupts() -> Callable[[], bool]:
    """Make SIGINT only *noted* by Python; return "did it come?" (since the first call in this process).

    ``rclpy.init`` installs rclpy's own handler for SIGINT and SIGTERM, which
    shuts the contexts down (the executor then returns from ``spin``) and
    then calls the Python handler found at ``init``.  Python's default one
    raises ``KeyboardInterrupt`` at whatever bytecode the main thread runs
    next -- inside a callback, a thread join, or a ``__del__`` (where Python
    can only print "Exception ignored in ..."); a second Ctrl-C (the terminal
    sends one to the process group and ``ros2 launch`` forwards another) would
    cut the clean-up short the same way.  So the handler installed here raises
    nothing: shutdown goes through rclpy's path alone, and every callback,
    ``close()`` and destructor runs to its end.  The returned function tells
    whether SIGINT came (before rclpy started: stop at once; later: a call
    that failed because the context was shut down under it is a clean stop,
    not a fault).
    """
    global _installed
    if threading.current_thread() is not threading.main_thread():
        return _interrupted.is_set  # signal handlers can be set only from the main thread
    if not _installed:
        signal.signal(signal.SIGINT, lambda signum, frame: _interrupted.set())
        _installed = True
    return _interrupted.is_set


def _run(module: str) -> int:
    """Import ``tactile_descriptors_ros.nodes.<module>`` with Ctrl-C noted, then run its ``main``."""
    interrupted = note_interrupts()
    main = importlib.import_module(f"tactile_descriptors_ros.nodes.{module}").main
    if interrupted():
        return 0  # stopped before the node started: nothing to close or save
    return main()


def biotac_driver() -> int:
    """The ``biotac_driver`` executable."""
    return _run("biotac_driver")


def skin_driver() -> int:
    """The ``skin_driver`` executable."""
    return _run("skin_driver")


def window_node() -> int:
    """The ``window_node`` executable."""
    return _run("window_node")


def classifier_node() -> int:
    """The ``classifier_node`` executable."""
    return _run("classifier_node")


def contact_node() -> int:
    """The ``contact_node`` executable."""
    return _run("contact_node")


def tf_publisher() -> int:
    """The ``tf_publisher`` executable."""
    return _run("tf_publisher")
