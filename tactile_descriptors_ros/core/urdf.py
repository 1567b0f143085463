"""The robot description's geometry as URDF: a xacro macro to add to the robot's URDF, or a standalone tree (pure).

``tactile urdf ROBOT --xacro`` writes a macro (``<robot>_tactile``, with a
``prefix`` parameter, as Shadow's ``rh_`` prefix needs) holding a link and a
fixed joint for every cell frame on its body part's link and for every
sensing site on its cell: include it in the robot's xacro and call it, and
``robot_state_publisher`` publishes the frames this package's messages name.
Without ``--xacro`` it writes a standalone URDF: the root, the body parts'
links at their rest pose, the cells and the sites, a tree any URDF parser
reads.  The frames are exactly :meth:`~.geometry.RobotGeometry.frames`.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from ..errors import ConfigError
from .geometry import Frame
from .robot import RobotDescription

__all__ = ["urdf_text", "XACRO_NS"]

XACRO_NS = "http://www.ros.org/wiki/xacro"


def _num(v: float) -> str:
    text = f"{v:.9g}"
    return "0" if text in ("-0", "0") else text


def _joint(parent: ET.Element, f: Frame, prefix: str) -> None:
    ET.SubElement(parent, "link", name=f"{prefix}{f.child}")
    j = ET.SubElement(parent, "joint", name=f"{prefix}{f.child}_joint", type="fixed")
    ET.SubElement(j, "parent", link=f"{prefix}{f.parent}")
    ET.SubElement(j, "child", link=f"{prefix}{f.child}")
    ET.SubElement(j, "origin", xyz=" ".join(_num(v) for v in f.pose.xyz),
                  rpy=" ".join(_num(v) for v in f.pose.rpy))


def urdf_text(robot: RobotDescription, *, xacro: bool = False, sites: bool = True) -> str:
    """The URDF (or xacro macro) of ``robot``'s geometry, as text.

    Parameters
    ----------
    robot : RobotDescription
    xacro : bool
        A macro of the cell and site frames to call from the robot's own
        xacro (its links are the robot's); else a standalone URDF with the
        root and the links' rest pose.
    sites : bool
        Include a link per sensing site.

    Raises
    ------
    ConfigError
        For a robot without a geometry section.
    """
    geo = robot.geometry
    if geo is None:
        raise ConfigError(f"robot {robot.name!r} has no geometry section: nothing to write as URDF",
                          key="geometry", source=robot.source)
    # (an XML comment may not hold a double hyphen: the option is named in words)
    head = (f" Frames of {robot.name}'s cells, written by tactile urdf {robot.name}"
            f"{' (xacro macro)' if xacro else ''} from {Path(robot.source).name or 'its robot description'}. ")
    if xacro:
        ET.register_namespace("xacro", XACRO_NS)
        root = ET.Element("robot", {"name": f"{robot.name}_tactile"})
        macro = ET.SubElement(root, f"{{{XACRO_NS}}}macro", name=f"{robot.name}_tactile", params="prefix:=''")
        for f in geo.frames(robot, links=False, sites=sites):
            _joint(macro, f, "${prefix}")
    else:
        root = ET.Element("robot", name=robot.name)
        ET.SubElement(root, "link", name=geo.root_frame)
        for f in geo.frames(robot, links=True, sites=sites):
            _joint(root, f, "")
    ET.indent(root, space="  ")
    return '<?xml version="1.0"?>\n<!--' + head + "-->\n" + ET.tostring(root, encoding="unicode") + "\n"
