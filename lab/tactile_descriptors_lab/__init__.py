"""The lab beside the robot package: evidence and tooling that never runs on a robot.

* :mod:`.evaluation` -- descriptor modes and the paper's learners scored on
  recordings (``tactile evaluate``, ``tactile report``);
* :mod:`.datasets` -- readers of other labs' recordings and ``tactile import``;
* :mod:`.bench` -- speed, latency, soak, scale and model-save benches (``tactile bench``);
* :mod:`.fuzz` -- the wire codecs fuzzed with injected truth (``tactile fuzz``);
* :mod:`.protocols` -- the paper's protocols on simulated robots (``tactile protocols``);
* :mod:`.textures` -- texture models fitted to recordings and the simulator checked
  against them (``tactile fit-textures``);
* :mod:`.verbs` -- the ``tactile`` subcommands above, registered through the
  ``tactile_descriptors_ros.verbs`` entry-point group.

The lab imports the robot package; the robot package never imports the lab.
"""
