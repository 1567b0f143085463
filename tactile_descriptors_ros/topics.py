"""The topic names of the node graph, in one place.

Names are relative, so a node's namespace applies (``/left/tactile/descriptor``
for a node in ``/left``); a bag written outside any namespace holds the
absolute forms (:func:`absolute`).  Remap them per node as usual
(``-r tactile/descriptor:=/hand/descriptor``) or with the robot description's
``graph.remappings``.
"""

from __future__ import annotations

__all__ = ["FRAMES_TOPIC", "DESCRIPTOR_TOPIC", "DESCRIPTOR_LAYOUT_TOPIC", "LABEL_TOPIC", "PREDICTION_TOPIC",
           "CONTACT_TOPIC", "WRENCH_TOPIC", "MARKERS_TOPIC", "IMAGE_TOPIC", "CONTACTS_TOPIC", "TF_STATIC_TOPIC",
           "absolute", "frames_topic", "layout_topic"]

#: Frames of one body part (``{body_part}`` filled in): ``BioTacFrameBatch`` or ``SkinPartFrames``.
FRAMES_TOPIC = "tactile/{body_part}/frames"
#: Descriptors of the window node (``Descriptor``).
DESCRIPTOR_TOPIC = "tactile/descriptor"
#: Suffix of the topic of a descriptor topic's layouts.
_LAYOUT_SUFFIX = "_layout"
#: Layouts of the descriptors (``DescriptorLayout``, latched): always the descriptor topic + ``_layout``.
DESCRIPTOR_LAYOUT_TOPIC = DESCRIPTOR_TOPIC + _LAYOUT_SUFFIX
#: True labels for the classifier (``Label``).
LABEL_TOPIC = "tactile/label"
#: Predictions of the classifier (``Prediction``).
PREDICTION_TOPIC = "tactile/prediction"
#: Contact of one body part per frames message (``Contact``, ``geometry_msgs/WrenchStamped``).
CONTACT_TOPIC = "tactile/{body_part}/contact"
WRENCH_TOPIC = "tactile/{body_part}/wrench"
#: rviz2's view of one body part per display period (``visualization_msgs/MarkerArray``, ``sensor_msgs/Image``).
MARKERS_TOPIC = "tactile/{body_part}/markers"
IMAGE_TOPIC = "tactile/{body_part}/image"
#: Every body part's contact per display period (``ContactArray``), what ``tactile view`` draws.
CONTACTS_TOPIC = "tactile/contacts"
#: The geometry's static frames (``tf2_msgs/TFMessage``; absolute, as tf2 has it: a namespace does not move it).
TF_STATIC_TOPIC = "/tf_static"


def frames_topic(body_part: str, fmt: str = FRAMES_TOPIC) -> str:
    """The frames topic of ``body_part`` (``fmt`` holds ``{body_part}``)."""
    return fmt.format(body_part=body_part)


def layout_topic(descriptor_topic: str) -> str:
    """The layout topic of a descriptor topic (``/hand/descriptor`` -> ``/hand/descriptor_layout``).

    Nodes derive it from their descriptor endpoint's resolved name, so a
    remapped descriptor topic takes its layouts along.
    """
    return descriptor_topic + _LAYOUT_SUFFIX


def absolute(topic: str) -> str:
    """``topic`` as seen from the root namespace (``tactile/label`` -> ``/tactile/label``)."""
    return topic if topic.startswith("/") else "/" + topic
