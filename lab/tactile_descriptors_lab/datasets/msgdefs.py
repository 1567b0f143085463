"""Message definitions of other BioTac drivers, as text, so their bags read without their packages.

rosbags builds a message type from its ``.msg`` text alone
(:func:`rosbags.typesys.get_types_from_msg`), so a bag recorded with another
driver can be decoded without that driver installed.  A bag that stores its
own definitions (every ROS 1 bag, and ROS 2 bags from Iron on) is decoded
with those; these texts are the fallback and what the tests write bags with.

Sources (the public ROS packages that define the messages):

* ``sr_robot_msgs`` (Shadow Robot's hand drivers): ``Biotac`` and
  ``BiotacAll``.  Older releases lack the ``pac`` array (only ``pac0`` and
  ``pac1``, two PAC samples a message); bags of either version read, since
  their own stored definition is used.
* ``biotac_sensors`` (the University of Pennsylvania's BioTac driver):
  ``BioTacHand``, ``BioTacData``, ``BioTacTime``.
"""

from __future__ import annotations

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

__all__ = ["SHADOW_ALL", "SHADOW_BIOTAC", "UPENN_HAND", "FOREIGN_MSGS", "foreign_typestore"]

#: Full type names (ROS 2 spelling; ROS 1 bags name them without ``/msg/``).
SHADOW_ALL = "sr_robot_msgs/msg/BiotacAll"
SHADOW_BIOTAC = "sr_robot_msgs/msg/Biotac"
UPENN_HAND = "biotac_sensors/msg/BioTacHand"

#: ``.msg`` text of each type, from the packages named in the module docstring.
FOREIGN_MSGS: dict[str, str] = {
    SHADOW_BIOTAC: """\
int16 pac0
int16 pac1
int16[] pac
int16 pdc
int16 tac
int16 tdc
int16[] electrodes
""",
    SHADOW_ALL: """\
std_msgs/Header header
sr_robot_msgs/Biotac[5] tactiles
""",
    "biotac_sensors/msg/BioTacData": """\
string bt_serial
uint16 bt_position
uint16 tdc_data
uint16 tac_data
uint16 pdc_data
uint16[22] pac_data
uint16[19] electrode_data
""",
    "biotac_sensors/msg/BioTacTime": """\
time frame_start_time
time frame_end_time
uint32 tdc_ns_offset
uint32 tac_ns_offset
uint32 pdc_ns_offset
uint32[22] pac_ns_offset
uint32[19] electrode_ns_offset
""",
    UPENN_HAND: """\
std_msgs/Header header
string hand_id
biotac_sensors/BioTacData[] bt_data
biotac_sensors/BioTacTime bt_time
""",
}


def foreign_typestore(ros1: bool = False) -> Typestore:
    """A type store (ROS 1 Noetic or ROS 2 Kilted base) with the foreign BioTac messages registered."""
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_KILTED)
    types = {}
    for name, text in FOREIGN_MSGS.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store
