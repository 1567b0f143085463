"""Where the cells are: links, cell and site poses, the TF tree and 2-D layouts (pure, no ROS).

A robot description (``config/<robot>.yaml``) places its cells on the
robot's links, by the links' names in the robot's URDF (the Shadow Hand's
``ffdistal`` ... ``thdistal``, the NAO's REP-120 ``torso``, ``LBicep``,
``LForeArm``, ``l_wrist`` ...)::

    geometry:
      root_frame: forearm            # every frame resolves to it
      links:                         # rest pose of each link the body parts are on (parent first)
        - {name: palm, parent: forearm, xyz: [0.0, -0.01, 0.247], rpy: [0, 0, 0]}
    cell_types:
      biotac:
        sites:                       # sensing sites in a cell's own frame
          - {name: e1, channels: [e1], xyz: [0.000993, -0.004855, -0.001116], normal: [0.196, -0.956, -0.22]}
    body_parts:
      - name: index
        link: ffdistal               # the body part's frame
        cells:
          - {id: 1, name: biotac_index, xyz: [0, 0, 0.015], rpy: [1.5708, 0, 1.5708]}

A pose is ``xyz`` [m] and either ``rpy`` [rad] (URDF's fixed-axis roll,
pitch, yaw) or ``normal`` (the frame's z axis; a skin cell faces along it).
The TF tree is ``root_frame`` -> links (their rest pose, for a robot whose
links no ``robot_state_publisher`` publishes) -> cell frames (each cell's
``frame_id``, default its name) -> site frames (``<cell frame>_<site>``).

Validation is strict and names the file and dotted key: a cell without a
pose names the body part and the cell; two cells (or sites) of one link less
than :data:`MIN_SEPARATION_M` apart, a normal of length zero, a link whose
parent is unknown, a frame name used twice are refused.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import ConfigError
from .cell_types import CellType
from .yamlreader import YamlReader

__all__ = [
    "CellLike",
    "BodyPartLike",
    "RobotLike",
    "MIN_SEPARATION_M",
    "POSE_KEYS",
    "Pose",
    "Site",
    "LinkPose",
    "Frame",
    "Taxels",
    "RobotGeometry",
    "parse_geometry",
    "parse_sites",
    "layout_2d",
]


# The geometry sits below the robot description (robot.py builds a
# RobotGeometry while it parses the file), so it names what it reads of a
# robot by these protocols instead of importing robot.py.


class CellLike(Protocol):
    """What the geometry reads of a cell (:class:`~.robot.Cell`)."""

    @property
    def id(self) -> int: ...
    @property
    def name(self) -> str: ...
    @property
    def extra(self) -> Mapping[str, Any]: ...


class BodyPartLike(Protocol):
    """What the geometry reads of a body part (:class:`~.robot.BodyPart`)."""

    @property
    def name(self) -> str: ...
    @property
    def cell_type(self) -> str: ...
    @property
    def cells(self) -> Sequence[CellLike]: ...


class RobotLike(Protocol):
    """What the geometry reads of a robot description (:class:`~.robot.RobotDescription`)."""

    @property
    def name(self) -> str: ...
    @property
    def body_parts(self) -> Sequence[BodyPartLike]: ...
    @property
    def cell_types(self) -> Mapping[str, CellType]: ...

    def body_part(self, name: str) -> BodyPartLike: ...


#: Closest two cells (or two sites of a cell) of one link may be [m]: closer is "one spot twice".
MIN_SEPARATION_M = 1e-3
#: Keys of a cell entry that give its pose (not kept in :attr:`~.robot.Cell.extra`).
POSE_KEYS = ("xyz", "rpy", "normal")
_Z = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class Pose:
    """A rigid transform: translation ``xyz`` [m] and rotation ``quat_xyzw`` (ROS order).

    The pose of a child frame in its parent's frame: a point ``p`` of the
    child maps to ``R p + xyz`` in the parent.
    """

    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    quat_xyzw: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)

    @classmethod
    def from_rotation(cls, xyz: Sequence[float], rotation: Rotation) -> Pose:
        q = rotation.as_quat()  # x, y, z, w
        if q[3] < 0:  # one of the two equal quaternions, so equal poses compare equal
            q = -q
        return cls(tuple(float(v) for v in xyz), tuple(float(v) for v in q))

    @classmethod
    def from_rpy(cls, xyz: Sequence[float], rpy: Sequence[float]) -> Pose:
        """URDF's ``<origin xyz rpy>``: fixed-axis roll (x), pitch (y), yaw (z), i.e. ``Rz(y) Ry(p) Rx(r)``."""
        return cls.from_rotation(xyz, Rotation.from_euler("xyz", rpy))

    @classmethod
    def from_normal(cls, xyz: Sequence[float], normal: Sequence[float]) -> Pose:
        """The frame at ``xyz`` whose z axis is ``normal`` (the shortest rotation from z; any length > 0)."""
        n = np.asarray(normal, dtype=float)
        n = n / np.linalg.norm(n)
        # about z x n = (-n_y, n_x, 0) by the angle between them; written out rather than scipy's
        # align_vectors, which near -z picks an arbitrary axis and, snapped to it there, leaves normals within
        # 1e-8 of -z off by that much.  hypot, not a sum of squares: those underflow for n_x, n_y near 1e-160.
        # The axis is scaled to its larger component before it is made a unit vector: divided by the hypot of
        # denormal components (5e-324 has one significant bit) it came out up to sqrt(2) long.
        nx, ny = float(n[0]), float(n[1])
        big = max(abs(nx), abs(ny))
        if big == 0.0:  # along z, or exactly opposite: then z -> -z about x
            rotvec = [math.pi, 0.0, 0.0] if n[2] < 0 else [0.0, 0.0, 0.0]
        else:
            ax, ay = -ny / big, nx / big  # one of them is +-1
            length = math.hypot(ax, ay)
            rotvec = np.array([ax / length, ay / length, 0.0]) * math.atan2(math.hypot(nx, ny), float(n[2]))
        return cls.from_rotation(xyz, Rotation.from_rotvec(rotvec))

    @property
    def rotation(self) -> Rotation:
        return Rotation.from_quat(self.quat_xyzw)

    @property
    def rpy(self) -> tuple[float, float, float]:
        """Roll, pitch, yaw as URDF writes them (at pitch +-90 deg scipy's choice of roll and yaw, the same rotation)."""
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "gimbal lock": the angles still give the rotation
            return tuple(float(v) for v in self.rotation.as_euler("xyz"))

    @property
    def normal(self) -> np.ndarray:
        """The frame's z axis in the parent's frame."""
        return self.rotation.apply(_Z)

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Points of this frame, shape (..., 3), in the parent's frame."""
        return self.rotation.apply(np.asarray(points, dtype=float).reshape(-1, 3)).reshape(np.shape(points)) \
            + np.asarray(self.xyz)

    def rotate(self, vectors: np.ndarray) -> np.ndarray:
        """Directions of this frame, shape (..., 3), in the parent's frame."""
        return self.rotation.apply(np.asarray(vectors, dtype=float).reshape(-1, 3)).reshape(np.shape(vectors))

    def __mul__(self, other: Pose) -> Pose:
        """``self * other``: ``other`` (given in this frame) in this frame's parent."""
        return Pose.from_rotation(self.apply(np.asarray(other.xyz)), self.rotation * other.rotation)


@dataclass(frozen=True)
class Site:
    """A sensing site of a cell type (a BioTac electrode, its pressure transducer), in the cell's frame."""

    name: str
    channels: tuple[str, ...]
    pose: Pose


@dataclass(frozen=True)
class LinkPose:
    """A link the body parts are on and its rest pose in its parent."""

    name: str
    parent: str
    pose: Pose


@dataclass(frozen=True)
class Frame:
    """One edge of the TF tree: ``child``'s pose in ``parent``."""

    child: str
    parent: str
    pose: Pose


@dataclass(frozen=True)
class Taxels:
    """The sensing points of one body part, in its link's frame, for contact location and views.

    A body part whose cell type declares sites for its deformation channels
    (a BioTac's electrodes) has one taxel per cell and site (``kind ==
    "sites"``): their deformation locates the contact on the cell.  Otherwise
    each cell is a taxel (``kind == "cells"``, a skin cell): its force locates it.

    Attributes
    ----------
    body_part, frame_id : str
        The body part and its link (the frame of ``positions`` and ``normals``).
    kind : str
        ``"cells"`` or ``"sites"``.
    names : tuple of str
        The TF frame of each taxel.
    cell_ids : numpy.ndarray of int64, shape (n,)
        The cell of each taxel (in the robot description's order).
    channels : tuple of tuple of int
        ``"sites"``: indices into the cell type's deformation channels that each
        site measures; ``"cells"``: empty tuples.
    positions, normals : numpy.ndarray, shape (n, 3)
        [m] and unit vectors.
    """

    body_part: str
    frame_id: str
    kind: str
    names: tuple[str, ...]
    cell_ids: np.ndarray
    channels: tuple[tuple[int, ...], ...]
    positions: np.ndarray
    normals: np.ndarray

    def __len__(self) -> int:
        return len(self.names)


@dataclass(frozen=True)
class RobotGeometry:
    """Where a robot's cells are (see the module docstring for the YAML).

    Attributes
    ----------
    root_frame : str
    links : tuple of LinkPose
        Parent first.
    part_links : dict of str to str
        Body part -> the link it is on (its frame).
    cell_frames : dict of int to str
        Cell id -> its TF frame.
    cell_poses : dict of int to Pose
        Cell id -> its pose in its body part's link.
    sites : dict of str to tuple of Site
        Cell type -> its sites (empty for a cell type without sites).
    source : str
    """

    root_frame: str
    links: tuple[LinkPose, ...]
    part_links: Mapping[str, str]
    cell_frames: Mapping[int, str]
    cell_poses: Mapping[int, Pose]
    sites: Mapping[str, tuple[Site, ...]] = field(default_factory=dict)
    source: str = ""

    def site_frame(self, cell_id: int, site: Site) -> str:
        """TF frame of ``site`` on cell ``cell_id``."""
        return f"{self.cell_frames[cell_id]}_{site.name}"

    def frames(self, robot: RobotLike, *, links: bool = True, sites: bool = True) -> list[Frame]:
        """The TF tree's edges: links' rest poses (when ``links``), cells, then sites (when ``sites``)."""
        out = [Frame(lp.name, lp.parent, lp.pose) for lp in self.links] if links else []
        for part in robot.body_parts:
            link = self.part_links[part.name]
            for cell in part.cells:
                out.append(Frame(self.cell_frames[cell.id], link, self.cell_poses[cell.id]))
            if sites:
                for cell in part.cells:
                    for site in self.sites.get(part.cell_type, ()):
                        out.append(Frame(self.site_frame(cell.id, site), self.cell_frames[cell.id], site.pose))
        return out

    def frame_names(self, robot: RobotLike) -> set[str]:
        """Every frame of the tree, the root included."""
        return {self.root_frame} | {f.child for f in self.frames(robot)}

    def rest_pose(self, frame: str, robot: RobotLike) -> Pose:
        """``frame``'s pose in the root frame with every link at its rest pose.

        Raises
        ------
        ConfigError
            For a frame that is not in the tree.
        """
        edges = {f.child: f for f in self.frames(robot)}
        pose = Pose()
        seen = 0
        while frame != self.root_frame:
            edge = edges.get(frame)
            if edge is None or seen > len(edges):
                raise ConfigError(f"frame {frame!r} is not in the TF tree of {robot.name}", source=self.source)
            pose = edge.pose * pose
            frame = edge.parent
            seen += 1
        return pose

    def taxels(self, robot: RobotLike, part_name: str) -> Taxels:
        """The sensing points of body part ``part_name`` in its link's frame (see :class:`Taxels`)."""
        part = robot.body_part(part_name)
        ct = robot.cell_types[part.cell_type]
        deformation = ct.deformation.channels
        sensing = [s for s in self.sites.get(part.cell_type, ()) if any(c in deformation for c in s.channels)]
        names, ids, channels, pos, nrm = [], [], [], [], []
        for cell in part.cells:
            pose = self.cell_poses[cell.id]
            if sensing:
                for site in sensing:
                    p = pose * site.pose
                    names.append(self.site_frame(cell.id, site))
                    ids.append(cell.id)
                    channels.append(tuple(deformation.index(c) for c in site.channels if c in deformation))
                    pos.append(p.xyz)
                    nrm.append(p.normal)
            else:
                names.append(self.cell_frames[cell.id])
                ids.append(cell.id)
                channels.append(())
                pos.append(pose.xyz)
                nrm.append(pose.normal)
        return Taxels(part.name, self.part_links[part.name], "sites" if sensing else "cells", tuple(names),
                      np.asarray(ids, dtype=np.int64), tuple(channels), np.asarray(pos, dtype=float).reshape(-1, 3),
                      np.asarray(nrm, dtype=float).reshape(-1, 3))


# --------------------------------------------------------------------------- parsing


def _vector(r: YamlReader, name: str, *, nonzero: bool = False) -> np.ndarray:
    value = r.get(name, kind=list)
    if len(value) != 3 or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        raise r.error(name, f"expected three numbers, got {value!r}")
    vec = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(vec)):
        raise r.error(name, f"must be finite, got {value!r}")
    if nonzero and np.linalg.norm(vec) < 1e-9:
        raise r.error(name, f"a normal of length zero ({value!r}) gives no direction")
    return vec


def _pose(r: YamlReader, what: str) -> Pose:
    """``xyz`` plus ``rpy`` or ``normal`` of the mapping ``r`` (``what`` names it in the missing-pose error)."""
    has_rpy, has_normal = "rpy" in r.data, "normal" in r.data
    if "xyz" not in r.data or not (has_rpy or has_normal):
        missing = "xyz" if "xyz" not in r.data else "rpy or normal"
        raise r.error_class(f"{what} has no pose: give xyz [m] and rpy [rad] or normal (missing {missing})",
                            key=r.key, source=r.source)
    if has_rpy and has_normal:
        raise r.error("normal", "give either rpy or normal, not both")
    xyz = _vector(r, "xyz")
    if has_normal:
        return Pose.from_normal(xyz, _vector(r, "normal", nonzero=True))
    return Pose.from_rpy(xyz, _vector(r, "rpy"))


def _check_spread(points: Sequence[tuple[str, str, np.ndarray]], where: str, source: str) -> None:
    """Refuse two points closer than :data:`MIN_SEPARATION_M` (``(key, name, xyz)`` each)."""
    if len(points) < 2:
        return
    from scipy.spatial import cKDTree

    xyz = np.array([p[2] for p in points])
    pairs = sorted(cKDTree(xyz).query_pairs(MIN_SEPARATION_M))
    if pairs:
        i, j = pairs[0]
        d = float(np.linalg.norm(xyz[i] - xyz[j]))
        raise ConfigError(f"{points[j][1]} and {points[i][1]} are {1e3 * d:.2f} mm apart {where}: two at one spot "
                          f"(at least {1e3 * MIN_SEPARATION_M:g} mm apart)", key=points[j][0], source=source)


def parse_sites(raw: Any, cell_type: CellType, key: str, source: str) -> tuple[Site, ...]:
    """The ``sites`` list of a cell type (each ``{name, channels, xyz, rpy | normal}``), validated.

    Raises
    ------
    ConfigError
        For a site without a pose, an unknown channel, a name used twice, two
        sites at one spot, or (when any site is given) a deformation channel
        without a site.
    """
    if not isinstance(raw, list):
        raise ConfigError(f"expected a list of sites, got {raw!r}", key=key, source=source)
    known = set(cell_type.channels)
    sites: list[Site] = []
    spots = []
    for i, item in enumerate(raw):
        r = YamlReader(item, f"{key}[{i}]", source)
        name = r.get("name", kind=str)
        if not name or any(s.name == name for s in sites):
            raise r.error("name", f"site name {name!r} is empty or used twice")
        channels = r.get("channels", kind=list)
        if not channels or not all(isinstance(c, str) for c in channels):
            raise r.error("channels", "needs a non-empty list of channel names")
        for c in channels:
            if c not in known:
                raise r.error("channels", f"cell type {cell_type.name!r} has no channel {c!r}")
        pose = _pose(r, f"site {name!r}")
        r.check_unknown()
        sites.append(Site(name, tuple(channels), pose))
        spots.append((r.path("xyz"), f"site {name!r}", np.asarray(pose.xyz)))
    _check_spread(spots, f"on a {cell_type.name} cell", source)
    if sites:
        covered = {c for s in sites for c in s.channels}
        for ch in cell_type.deformation.channels:
            if ch not in covered:
                raise ConfigError(f"deformation channel {ch!r} of cell type {cell_type.name!r} has no site "
                                  "(give every deformation channel a site, or no sites at all)", key=key, source=source)
    return tuple(sites)


def parse_geometry(data: Mapping[str, Any], body_parts: Sequence[BodyPartLike], cell_types: Mapping[str, CellType],
                   source: str) -> RobotGeometry | None:
    """The ``geometry`` section and the poses of every cell, or None when the file gives no geometry.

    Parameters
    ----------
    data : mapping
        The whole parsed robot description (its structure already checked by
        :func:`~.robot.parse_robot`).
    body_parts, cell_types
        As parsed by :func:`~.robot.parse_robot` (same order as ``data``).
    source : str
        File named in errors.

    Raises
    ------
    ConfigError
        Naming the file and the dotted key (see the module docstring).
    """
    raw_parts = data.get("body_parts") or []
    raw_sites = {name: (ct.get("sites") if isinstance(ct, Mapping) else None)
                 for name, ct in (data.get("cell_types") or {}).items()}
    if "geometry" not in data:
        for i, rp in enumerate(raw_parts):
            if "link" in rp:
                raise ConfigError("a body part link needs the geometry section (root_frame, links)",
                                  key=f"body_parts[{i}].link", source=source)
            for j, rc in enumerate(rp.get("cells") or []):
                if any(k in rc for k in POSE_KEYS):
                    raise ConfigError("a cell pose needs the geometry section (root_frame, links)",
                                      key=f"body_parts[{i}].cells[{j}]", source=source)
        for name, sites in raw_sites.items():
            if sites:
                raise ConfigError("sites need the geometry section (root_frame, links)",
                                  key=f"cell_types.{name}.sites", source=source)
        return None
    g = YamlReader(data["geometry"], "geometry", source)
    root = g.get("root_frame", kind=str)
    if not root:
        raise g.error("root_frame", "needs the name of the robot's root link")
    links: list[LinkPose] = []
    known_frames = {root}
    for i, item in enumerate(g.get("links", [], list)):
        r = YamlReader(item, f"geometry.links[{i}]", source)
        name = r.get("name", kind=str)
        parent = r.get("parent", kind=str)
        if not name or name in known_frames:
            raise r.error("name", f"link {name!r} is empty or already a frame")
        if parent not in known_frames:
            raise r.error("parent", f"unknown parent {parent!r}: the root frame {root!r} or a link listed before "
                                    "this one")
        links.append(LinkPose(name, parent, _pose(r, f"link {name!r}")))
        r.check_unknown()
        known_frames.add(name)
    g.check_unknown()

    sites = {name: parse_sites(raw, cell_types[name], f"cell_types.{name}.sites", source)
             for name, raw in raw_sites.items() if raw is not None}
    part_links: dict[str, str] = {}
    cell_frames: dict[int, str] = {}
    cell_poses: dict[int, Pose] = {}
    frame_keys: dict[str, str] = {f: "geometry" for f in known_frames}
    by_link: dict[str, list[tuple[str, str, np.ndarray]]] = {}
    for i, (part, rp) in enumerate(zip(body_parts, raw_parts)):
        if "link" not in rp:
            raise ConfigError(f"body part {part.name!r} needs the link it is on (a link of geometry.links or "
                              f"the root frame {root!r})", key=f"body_parts[{i}]", source=source)
        link = rp["link"]
        if not isinstance(link, str) or link not in known_frames:
            raise ConfigError(f"unknown link {link!r} (known: {', '.join(sorted(known_frames))}); declare it under "
                              "geometry.links with its parent", key=f"body_parts[{i}].link", source=source)
        part_links[part.name] = link
        for j, (cell, rc) in enumerate(zip(part.cells, rp.get("cells") or [])):
            key = f"body_parts[{i}].cells[{j}]"
            r = YamlReader(rc, key, source)
            pose = _pose(r, f"body part {part.name!r}: cell {cell.name!r} (id {cell.id})")
            frame = str(cell.extra.get("frame_id", cell.name))
            if not frame or frame in frame_keys:
                raise ConfigError(f"frame {frame!r} of cell {cell.name!r} is already used ({frame_keys.get(frame)})",
                                  key=key, source=source)
            frame_keys[frame] = key
            cell_frames[cell.id] = frame
            cell_poses[cell.id] = pose
            by_link.setdefault(link, []).append((f"{key}.xyz", f"cell {cell.name!r}", np.asarray(pose.xyz)))
            for site in sites.get(part.cell_type, ()):
                sf = f"{frame}_{site.name}"
                if sf in frame_keys:
                    raise ConfigError(f"site frame {sf!r} clashes with {frame_keys[sf]}", key=key, source=source)
                frame_keys[sf] = key
    for link, points in by_link.items():
        _check_spread(points, f"on link {link!r}", source)
    return RobotGeometry(root, tuple(links), part_links, cell_frames, cell_poses, sites, source)


# --------------------------------------------------------------------------- layouts


def _principal_axes(points: np.ndarray) -> np.ndarray:
    """Rows: the principal axes of ``points`` (largest spread first), each signed so its largest component is positive."""
    centred = points - points.mean(axis=0)
    _, _, vt = np.linalg.svd(centred, full_matrices=True)
    for k in range(3):
        if vt[k, np.argmax(np.abs(vt[k]))] < 0:
            vt[k] = -vt[k]
    return vt


def _unroll_axis(centred: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """The axis to unroll about: along which the normals do not turn, the points' largest spread among those.

    The normals' scatter matrix has small eigenvalues along directions the
    normals have no part in (a cylinder's axis; both directions of a flat
    two-sided hand); among those, the points' principal spread decides.
    """
    vals, vecs = np.linalg.eigh(normals.T @ normals)
    free = vecs[:, vals <= 0.25 * vals.max() + 1e-12]  # columns
    if free.shape[1] == 0:
        free = vecs[:, :1]
    inside = centred @ free  # coordinates in the free subspace
    if free.shape[1] == 1:
        axis = free[:, 0]
    else:
        _, _, vt = np.linalg.svd(inside, full_matrices=False)
        axis = free @ vt[0]
    axis = axis / np.linalg.norm(axis)
    return axis if axis[np.argmax(np.abs(axis))] > 0 else -axis


def layout_2d(positions: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """A flat layout of sensing points for images and views [m], shape (n, 2).

    Points that face one way (the mean of their unit normals is at least 0.5
    long: a patch, a fingertip's electrodes) are projected onto the plane
    facing that way, seen from outside, its first axis along the points'
    largest spread.  Points all around a body part (an arm's rings, both
    sides of a hand) are unrolled about their largest spread: the first
    coordinate is the angle around that axis times the mean radius, the
    second the position along it, so no cell hides behind another.

    Parameters
    ----------
    positions, normals : numpy.ndarray, shape (n, 3)

    Returns
    -------
    numpy.ndarray, shape (n, 2)
        Deterministic for given points (no random orientation).
    """
    pos = np.asarray(positions, dtype=float).reshape(-1, 3)
    nrm = np.asarray(normals, dtype=float).reshape(-1, 3)
    if len(pos) < 2:
        return np.zeros((len(pos), 2))
    centred = pos - pos.mean(axis=0)
    mean_normal = nrm.mean(axis=0)
    if np.linalg.norm(mean_normal) >= 0.5:
        n = mean_normal / np.linalg.norm(mean_normal)
        flat = centred - np.outer(centred @ n, n)
        axes = _principal_axes(flat + pos.mean(axis=0)) if np.ptp(flat, axis=0).max() > 0 else np.eye(3)
        u = axes[0] - (axes[0] @ n) * n
        if np.linalg.norm(u) < 1e-9:
            u = np.cross(n, [1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.cross(n, [0.0, 1.0, 0.0])
        u /= np.linalg.norm(u)
        v = np.cross(n, u)  # seen from outside (looking along -n): u right, v up
        return np.stack([centred @ u, centred @ v], axis=1)
    axis = _unroll_axis(centred, nrm)
    along = centred @ axis
    radial = centred - np.outer(along, axis)
    ref = radial[np.argmax(np.linalg.norm(radial, axis=1))]
    ref = ref / np.linalg.norm(ref) if np.linalg.norm(ref) > 0 else _principal_axes(pos)[1]
    other = np.cross(axis, ref)
    angle = np.arctan2(radial @ other, radial @ ref)
    # cut the circle in its widest empty sector, so no side of the part is split in two
    order = np.sort(angle)
    gaps = np.diff(np.concatenate([order, order[:1] + 2 * math.pi]))
    k = int(np.argmax(gaps))
    seam = order[k] + gaps[k] / 2.0
    angle = np.mod(angle - seam, 2 * math.pi)
    radius = float(np.mean(np.linalg.norm(radial, axis=1)))
    return np.stack([angle * radius, along], axis=1)
