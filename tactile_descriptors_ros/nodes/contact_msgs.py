"""Messages of the geometry and the contact: ``/tf_static``, Contact, WrenchStamped, rviz2 markers, images.

Conversions only (the core computes): :class:`~..core.geometry.Frame` to
``tf2_msgs/TFMessage``, :class:`~..core.contact.ContactEstimate` to
``Contact`` and ``geometry_msgs/WrenchStamped``, a body part's display frame
to ``visualization_msgs/MarkerArray`` and an RGB array to ``sensor_msgs/Image``.
"""

from __future__ import annotations

import array
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..core.colormap import force_colours
from ..core.contact import ContactEstimate, contact_wrench
from ..core.display import DisplayFrame
from ..core.geometry import Frame, Pose, Taxels
from .conversions import ns_to_stamp

__all__ = ["frames_to_tf_message", "contact_to_msg", "wrench_to_msg", "contact_from_msg", "MarkerStyle",
           "PartMarkers", "image_to_msg", "MARKER_NAMESPACES"]

#: Namespaces of a body part's markers.
MARKER_NAMESPACES = ("cells", "sites", "contact_point", "contact_normal", "prediction")


def frames_to_tf_message(frames: Sequence[Frame], stamp_ns: int):
    """The TF tree's edges as one ``tf2_msgs/TFMessage`` (what ``/tf_static`` carries)."""
    from geometry_msgs.msg import TransformStamped
    from tf2_msgs.msg import TFMessage

    stamp = ns_to_stamp(stamp_ns)
    out = []
    for f in frames:
        t = TransformStamped()
        t.header.stamp = stamp
        t.header.frame_id = f.parent
        t.child_frame_id = f.child
        t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = f.pose.xyz
        q = t.transform.rotation
        q.x, q.y, q.z, q.w = f.pose.quat_xyzw
        out.append(t)
    return TFMessage(transforms=out)


def _f32(values) -> array.array:
    out = array.array("f")
    out.frombytes(np.ascontiguousarray(values, dtype=np.float32).tobytes())
    return out


def _u32(values) -> array.array:
    out = array.array("I")
    out.frombytes(np.ascontiguousarray(values, dtype=np.uint32).tobytes())
    return out


def contact_to_msg(est: ContactEstimate, *, body_part: str, frame_id: str, cell_ids: np.ndarray, start_ns: int,
                   end_ns: int, threshold_n: float, taxels: Taxels | None = None, vibration_unit: str = ""):
    """A ``Contact`` (see ``msg/Contact.msg``); site fields are filled for ``"sites"`` taxels."""
    from tactile_descriptors_msgs.msg import Contact

    msg = Contact()
    msg.header.stamp = ns_to_stamp(max(end_ns, 0))
    msg.header.frame_id = frame_id
    msg.window_start = ns_to_stamp(max(start_ns, 0))
    msg.body_part = body_part
    msg.in_contact = bool(est.in_contact)
    msg.force_n = float(est.force_n)
    msg.force_threshold_n = float(threshold_n)
    msg.centre_of_pressure.x, msg.centre_of_pressure.y, msg.centre_of_pressure.z = map(float, est.centre_of_pressure)
    msg.normal.x, msg.normal.y, msg.normal.z = map(float, est.normal)
    msg.active_cell_ids = _u32(est.active_cells)
    msg.cell_ids = _u32(cell_ids)
    msg.cell_force_n = _f32(est.cell_force_n)
    if taxels is not None and taxels.kind == "sites":
        msg.site_names = list(taxels.names)
        msg.site_force_n = _f32(est.taxel_force_n)
    msg.vibration_rms = float(est.vibration_rms)
    msg.vibration_unit = vibration_unit
    return msg


def contact_from_msg(msg) -> dict:
    """A ``Contact`` (rclpy or rosbags) as plain data for the views."""
    def arr(v, dtype):
        return np.frombuffer(v, dtype=dtype).copy() if isinstance(v, array.array) else np.asarray(v, dtype=dtype)

    return {
        "body_part": str(msg.body_part), "frame_id": str(msg.header.frame_id),
        "stamp_ns": int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec),
        "in_contact": bool(msg.in_contact), "force_n": float(msg.force_n),
        "centre_of_pressure": [float(msg.centre_of_pressure.x), float(msg.centre_of_pressure.y),
                               float(msg.centre_of_pressure.z)],
        "normal": [float(msg.normal.x), float(msg.normal.y), float(msg.normal.z)],
        "active_cell_ids": arr(msg.active_cell_ids, np.uint32).astype(np.int64),
        "cell_ids": arr(msg.cell_ids, np.uint32).astype(np.int64),
        "cell_force_n": arr(msg.cell_force_n, np.float32).astype(float),
        "site_names": list(msg.site_names), "site_force_n": arr(msg.site_force_n, np.float32).astype(float),
        "vibration_rms": float(msg.vibration_rms), "vibration_unit": str(msg.vibration_unit),
    }


def wrench_to_msg(est: ContactEstimate, *, frame_id: str, stamp_ns: int):
    """The contact as a ``geometry_msgs/WrenchStamped`` at the body part frame's origin.

    The force and moment are :func:`~..core.contact.contact_wrench`'s.
    """
    from geometry_msgs.msg import WrenchStamped

    f, tau = contact_wrench(est)
    msg = WrenchStamped()
    msg.header.stamp = ns_to_stamp(max(stamp_ns, 0))
    msg.header.frame_id = frame_id
    msg.wrench.force.x, msg.wrench.force.y, msg.wrench.force.z = map(float, f)
    msg.wrench.torque.x, msg.wrench.torque.y, msg.wrench.torque.z = map(float, tau)
    return msg


@dataclass(frozen=True)
class MarkerStyle:
    """Sizes of a body part's markers [m], from its sensing points' spacing.

    Attributes
    ----------
    taxel_m : float
        Diameter of a cell's disc or a site's sphere (0.8 of the nearest spacing, at least 2 mm).
    text_m : float
        Height of the prediction text.
    label_at : numpy.ndarray, shape (3,)
        Where the prediction text stands: above the points' centre along their mean normal.
    """

    taxel_m: float
    text_m: float
    label_at: np.ndarray

    @classmethod
    def of(cls, taxels: Taxels) -> MarkerStyle:
        pos = taxels.positions
        if len(pos) > 1:
            d = np.linalg.norm(pos[:, None, :] - pos[None, :, :], axis=2)
            d[np.diag_indices_from(d)] = np.inf
            spacing = float(d.min())
        else:
            spacing = 0.01
        size = max(0.8 * spacing, 0.002)
        n = taxels.normals.mean(axis=0)
        n = n / np.linalg.norm(n) if np.linalg.norm(n) > 0.3 else np.array([0.0, 0.0, 1.0])
        extent = float(np.ptp(pos, axis=0).max()) if len(pos) > 1 else 0.01
        return cls(size, max(0.008, 0.25 * extent), pos.mean(axis=0) + n * (0.6 * extent + 0.01))


def _colour(rgb: Sequence[float], alpha: float = 1.0):
    from std_msgs.msg import ColorRGBA

    return ColorRGBA(r=float(rgb[0]), g=float(rgb[1]), b=float(rgb[2]), a=float(alpha))


class PartMarkers:
    """A body part's ``visualization_msgs/MarkerArray`` for rviz2 (no plugin needed), updated in place.

    * ``cells``: skin cells as discs facing along their normals, or, for a
      part whose sites locate the contact (a BioTac), the cell itself as a
      translucent sphere; coloured by force (viridis on ``[0,
      force_max_n]``), grey when stale;
    * ``sites``: the sites as spheres, coloured by the force they carry;
    * ``contact_point`` (red sphere) and ``contact_normal`` (arrow along the
      outward normal, 1 cm plus 1 cm per newton) while in contact, deleted otherwise;
    * ``prediction``: the text (class and confidence) above the part, deleted when empty.

    Every marker is in the body part's link frame (``taxels.frame_id``).  The
    markers' poses do not change: they are built once, and :meth:`update`
    only sets the colours, the contact and the text.  rviz2 keeps a marker
    until it is replaced or deleted, so :meth:`update` returns only the
    markers that changed since the last array it returned (a cell's colour,
    the contact, the text), every marker when asked for a ``full`` array (a
    viewer that subscribed later gets the whole body part from it), and None
    when nothing changed: most of a skin is untouched most of the time, and
    converting its unchanged markers for every display period was most of
    the contact node's display cost.
    """

    def __init__(self, taxels: Taxels, style: MarkerStyle, cell_poses: Sequence[Pose] = ()) -> None:
        from visualization_msgs.msg import Marker, MarkerArray

        self.taxels, self.style = taxels, style
        self.msg = MarkerArray()
        self.cells: list = []
        self.sites: list = []

        def marker(ns: str, mid: int, mtype: int) -> Marker:
            m = Marker()
            m.header.frame_id = taxels.frame_id
            m.ns, m.id, m.type, m.action = ns, mid, mtype, Marker.ADD
            m.pose.orientation.w = 1.0
            self.msg.markers.append(m)
            return m

        if taxels.kind == "sites":
            for k, pose in enumerate(cell_poses):
                m = marker("cells", k, Marker.SPHERE)
                m.pose.position.x, m.pose.position.y, m.pose.position.z = pose.xyz
                m.scale.x = m.scale.y = m.scale.z = 0.02
                self.cells.append(m)
            for k in range(len(taxels)):
                m = marker("sites", k, Marker.SPHERE)
                m.pose.position.x, m.pose.position.y, m.pose.position.z = map(float, taxels.positions[k])
                m.scale.x = m.scale.y = m.scale.z = style.taxel_m
                self.sites.append(m)
        else:
            for k in range(len(taxels)):
                m = marker("cells", k, Marker.CYLINDER)
                p = Pose.from_normal(taxels.positions[k], taxels.normals[k])
                m.pose.position.x, m.pose.position.y, m.pose.position.z = p.xyz
                q = m.pose.orientation
                q.x, q.y, q.z, q.w = p.quat_xyzw
                m.scale.x = m.scale.y = style.taxel_m
                m.scale.z = 0.002
                self.cells.append(m)
        self.point = marker("contact_point", 0, Marker.SPHERE)
        self.point.scale.x = self.point.scale.y = self.point.scale.z = max(0.5 * style.taxel_m, 0.003)
        self.point.color = _colour((1.0, 0.1, 0.1))
        self.arrow = marker("contact_normal", 0, Marker.ARROW)
        self.arrow.scale.x, self.arrow.scale.y, self.arrow.scale.z = 0.002, 0.004, 0.004
        self.arrow.color = _colour((1.0, 0.1, 0.1))
        self.label = marker("prediction", 0, Marker.TEXT_VIEW_FACING)
        self.label.pose.position.x, self.label.pose.position.y, self.label.pose.position.z = map(float,
                                                                                                 style.label_at)
        self.label.scale.z = style.text_m
        self.label.color = _colour((1.0, 1.0, 1.0))
        # what the last returned array showed: 8-bit colours per marker (-1: never sent), contact, text
        self._rgb = {"cells": np.full((len(self.cells), 3), -1), "sites": np.full((len(self.sites), 3), -1)}
        self._contact: tuple | None = None
        self._text: str | None = None

    def update(self, frame: DisplayFrame, *, stamp_ns: int, force_max_n: float, text: str = "",
               full: bool = False):
        """The markers of one display frame that changed, every marker when ``full``; None when none changed.

        Returns
        -------
        visualization_msgs.msg.MarkerArray or None
            Holding the markers themselves (updated in place, stamped
            ``stamp_ns``); :attr:`msg` holds all of them.
        """
        from geometry_msgs.msg import Point
        from visualization_msgs.msg import Marker, MarkerArray

        changed: list = []
        est = frame.contact
        taxel_rgb = force_colours(np.where(frame.taxel_stale, np.nan, est.taxel_force_n), force_max_n)
        if self.taxels.kind == "sites":
            cell_rgb = force_colours(np.where(frame.cell_stale, np.nan, est.cell_force_n), force_max_n)
            groups = (("cells", self.cells, cell_rgb, 0.25), ("sites", self.sites, taxel_rgb, 1.0))
        else:
            groups = (("cells", self.cells, taxel_rgb, 1.0),)
        for name, markers, rgb, alpha in groups:
            last = self._rgb[name]
            new = np.flatnonzero(np.any(last != rgb, axis=1))
            for k in new:
                markers[k].color = _colour(rgb[k] / 255.0, alpha)
            last[new] = rgb[new]
            changed += markers if full else [markers[k] for k in new]
        touching = bool(est.in_contact and est.force_n > 0)
        contact = (touching, *(np.round(est.centre_of_pressure, 6) if touching else ()),
                   *(np.round(est.normal, 6) if touching else ()), round(float(est.force_n), 4) if touching else 0)
        if full or contact != self._contact:
            self.point.action = self.arrow.action = Marker.ADD if touching else Marker.DELETE
            if touching:
                cop = [float(v) for v in est.centre_of_pressure]
                self.point.pose.position.x, self.point.pose.position.y, self.point.pose.position.z = cop
                tip = np.asarray(cop) + np.asarray(est.normal) * (0.01 + 0.01 * est.force_n)
                self.arrow.points = [Point(x=cop[0], y=cop[1], z=cop[2]),
                                     Point(x=float(tip[0]), y=float(tip[1]), z=float(tip[2]))]
            self._contact = contact
            changed += [self.point, self.arrow]
        if full or text != self._text:
            self.label.action = Marker.ADD if text else Marker.DELETE
            self.label.text = text
            self._text = text
            changed.append(self.label)
        if not changed:
            return None
        stamp = ns_to_stamp(max(stamp_ns, 0))
        for m in changed:
            m.header.stamp = stamp
        return MarkerArray(markers=changed)


def image_to_msg(rgb: np.ndarray, *, frame_id: str, stamp_ns: int):
    """An ``rgb8`` ``sensor_msgs/Image`` of an (height, width, 3) uint8 array."""
    from sensor_msgs.msg import Image

    img = np.ascontiguousarray(rgb, dtype=np.uint8)
    if img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"expected (height, width, 3) RGB, got {img.shape}")
    msg = Image()
    msg.header.stamp = ns_to_stamp(max(stamp_ns, 0))
    msg.header.frame_id = frame_id
    msg.height, msg.width = int(img.shape[0]), int(img.shape[1])
    msg.encoding = "rgb8"
    msg.is_bigendian = 0
    msg.step = 3 * msg.width
    msg.data = img.tobytes()
    return msg
