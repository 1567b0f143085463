"""One parameter schema per node (:mod:`.schema`): the one place a parameter is named, typed, bounded, described.

:data:`SCHEMAS` maps each executable of the package to its
:class:`~.schema.NodeSchema`.  A new node adds ``params/<executable>.py``
with its schema and one line here (docs/architecture.md, "Parameters").

Plain data: no rclpy import.
"""

from __future__ import annotations

from .biotac_driver import BIOTAC_DRIVER
from .classifier_node import CLASSIFIER_NODE
from .contact_node import CONTACT_NODE
from .schema import NodeSchema, Param, check_value
from .skin_driver import SKIN_DRIVER
from .tf_publisher import TF_PUBLISHER
from .window_node import WINDOW_NODE

__all__ = ["SCHEMAS", "NodeSchema", "Param", "check_value", "schema_of"]

#: executable -> its parameter schema
SCHEMAS: dict[str, NodeSchema] = {s.executable: s for s in (BIOTAC_DRIVER, SKIN_DRIVER, WINDOW_NODE,
                                                            CLASSIFIER_NODE, CONTACT_NODE, TF_PUBLISHER)}


def schema_of(executable: str) -> NodeSchema:
    """The schema of ``executable`` (KeyError naming the known ones)."""
    try:
        return SCHEMAS[executable]
    except KeyError:
        raise KeyError(f"no parameter schema for {executable!r} (known: {', '.join(SCHEMAS)})") from None
