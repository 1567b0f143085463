"""The stream layer: transport -> decode -> sequence/unwrap -> stamp -> tare -> batch, without ROS.

Between the transports (:mod:`..transports`, bytes and CAN frames) and the
ROS nodes sits one pure layer that turns what a device sends into the
batches the nodes publish:

* :mod:`.sequence` -- the one home of counter unwrapping:
  :class:`~.sequence.SequenceTracker` (per key, using frame times as well as
  sequence numbers, so a quiet period longer than a wrap is a gap of the
  right length) and :class:`~.sequence.Unwrapper`;
* :mod:`.link`     -- a device link that reopens an unplugged device by
  itself and reports the time it was gone;
* :mod:`.stamping` -- sample clocks (sequence number times period, anchored
  to the host clock, re-anchored on drift);
* :mod:`.biotac`   -- BioTac sources (SPI sampling, serial bridge) and the
  per-sensor stream (lost frames, stamps, tare, batches of consecutive frames);
* :mod:`.skin`     -- the skin-cell stream (per cell and modality: unwrap,
  lost frames, stamps, tare, ``batch_s`` batches);
* :mod:`.skin_parts` -- one message per body part: the cells' batches as flat
  arrays and back (chunks for the window node), and the gathering of a body
  part's batches into one message.

The drivers in :mod:`..nodes` are thin adapters over these classes:
parameters, publishers, services and diagnostics.  Nothing here imports
``rclpy`` (a test imports the layer with it blocked).  Submodules are
imported by name (the codecs import :mod:`.sequence`, which must not pull
the rest of the layer in).
"""

__all__: list[str] = []
