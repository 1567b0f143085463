"""The topic names of the node graph, in one place.

Names are relative, so a node's namespace applies (``/left/tactile/descriptor``
for a node in ``/left``); a bag written outside any namespace holds the
absolute forms (:func:`absolute`).  Remap them per node as usual
(``-r tactile/descriptor:=/hand/descriptor``) or with the robot description's
``graph.remappings``.
"""

from __future__ import annotations

__all__ = ["FRAMES_TOPIC", "DESCRIPTOR_TOPIC", "LABEL_TOPIC", "PREDICTION_TOPIC", "absolute", "frames_topic"]

#: Frames of one body part (``{body_part}`` filled in): ``BioTacFrameBatch`` or ``SkinPartFrames``.
FRAMES_TOPIC = "tactile/{body_part}/frames"
#: Descriptors of the window node (``Descriptor``).
DESCRIPTOR_TOPIC = "tactile/descriptor"
#: True labels for the classifier (``Label``).
LABEL_TOPIC = "tactile/label"
#: Predictions of the classifier (``Prediction``).
PREDICTION_TOPIC = "tactile/prediction"


def frames_topic(body_part: str, fmt: str = FRAMES_TOPIC) -> str:
    """The frames topic of ``body_part`` (``fmt`` holds ``{body_part}``)."""
    return fmt.format(body_part=body_part)


def absolute(topic: str) -> str:
    """``topic`` as seen from the root namespace (``tactile/label`` -> ``/tactile/label``)."""
    return topic if topic.startswith("/") else "/" + topic
