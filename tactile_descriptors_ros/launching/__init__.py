"""The node graph as data, and the in-repo launcher (no rclpy, no ``launch`` import).

* :mod:`.graph` -- robot description + options -> :class:`~.graph.NodeSpec` list;
  read by ``launch/*.launch.py`` and by ``tactile launch``;
* :mod:`.launch_file` -- the body of ``launch/<robot>.launch.py``
  (imports ``launch``/``launch_ros`` only when called);
* :mod:`.processes` -- start NodeSpecs as subprocesses (``--ros-args
  --params-file ... -r from:=to``), forward their output with a prefix, stop
  them cleanly;
* :mod:`.signals` -- Ctrl-C and SIGTERM as a stop flag whose handler takes no
  lock (the launcher's, the recorder's and the player's).
"""

__all__: list[str] = []
