"""Robot descriptions: body parts, cells, channels, rates and thresholds as data.

One YAML file per robot in ``config/`` (``shadow_hand.yaml``, ``nao.yaml``)
is read by the nodes, the launch files and the in-repo launcher alike.  The
descriptor layout follows from it (paper eq. 11): each *cell type*
(:mod:`.cell_types`) declares a vibration modality S and a deformation
modality V, each as a list of axes and each axis as a list of channels, and
may declare *extra channels* (``extra_channels``): slow signals sampled with
V (one value per V sample) that enter only the feature groups that use them
-- the BioTac's PDC, TDC and TAC, the skin cell's proximity and temperature.
Which feature groups make up the descriptor is chosen in the ``descriptor``
section (``groups``; :mod:`.groups`), and checked at load time against what
every cell type can feed; block averaging (``block_s``, :mod:`.blocks`) is
checked here too (:func:`check_blocks`).

Validation is strict and names the offending key: an unknown body part or
cell type, a cell id listed twice, an impossible rate or threshold fails at
load time with :class:`~tactile_descriptors_ros.errors.ConfigError`.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..errors import ConfigError
from .cell_types import CellType, parse_cell_type
from .geometry import POSE_KEYS, RobotGeometry, parse_geometry
from .groups import check_groups, groups_of_channels
from .yamlreader import YamlReader, config_dir, resolve_yaml

__all__ = [
    "VIBRATION_GROUPS",
    "Cell",
    "BodyPart",
    "ContactSpec",
    "WindowSpec",
    "DescriptorSpec",
    "select_body_parts",
    "ViewSpec",
    "RobotDescription",
    "load_robot",
    "parse_robot",
    "config_dir",
    "robot_config_path",
    "WINDOW_MODES",
    "LAYOUT_MODES",
    "CHANNEL_MODES",
    "check_blocks",
]

WINDOW_MODES = ("fixed", "exploration")
LAYOUT_MODES = ("concat", "pooled")
CHANNEL_MODES = ("averaged", "per_channel")
#: Feature groups that need vibration channels of their own (a pressure-only cell type cannot feed them;
#: ``paper`` and ``statistics`` describe its deformation channels alone).
VIBRATION_GROUPS = ("per_channel", "bands")


@dataclass(frozen=True)
class Cell:
    """One physical cell: a BioTac or one skin cell."""

    id: int
    name: str
    extra: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class BodyPart:
    """A body part b (finger, hand, forearm, chest ...) and its cells."""

    name: str
    cell_type: str
    cells: tuple[Cell, ...]


@dataclass(frozen=True)
class ContactSpec:
    """Contact gate parameters (eq. 13): ``force_threshold_n`` is F_t.

    The field defaults are what a robot description that leaves a key out
    gets, and so the default of the nodes' parameters of the same names
    (``contact.force_threshold_n`` of the window node and the drivers).
    """

    force_threshold_n: float = 0.2
    release_threshold_n: float = 0.1  # hysteresis for exploration windows


@dataclass(frozen=True)
class WindowSpec:
    """Window parameters: fixed (length, hop) or exploration (onset to release)."""

    mode: str = "exploration"
    length_s: float = 2.0
    hop_s: float = 0.5
    min_duration_s: float = 1.0
    max_duration_s: float = 10.0
    release_s: float = 0.1


@dataclass(frozen=True)
class DescriptorSpec:
    """Descriptor layout (``concat`` or ``pooled``) and feature groups.

    Attributes
    ----------
    layout : str
    channels : str
        The legacy channel mode: ``averaged`` (= groups ``[paper]``),
        ``per_channel`` (= ``[per_channel]``), or ``""`` when the file gives
        ``groups``.
    groups : tuple of str
        Feature groups in descriptor order (:data:`.groups.GROUPS`).
    block_s : float
        Block averaging (:mod:`.blocks`): a window is described by the mean of
        the descriptors of its blocks of this many seconds; 0 (the default,
        the paper's) describes the whole window at once.
    block_hop_s : float
        Largest step between consecutive blocks (seconds).
    """

    layout: str = "concat"
    channels: str = "averaged"
    groups: tuple[str, ...] = ("paper",)
    block_s: float = 0.0
    block_hop_s: float = 0.5


@dataclass(frozen=True)
class ViewSpec:
    """How the views show the robot (``view`` section): colour scale, display rate, staleness.

    Attributes
    ----------
    force_max_n : float
        Force at the top of the colour scale [N] (a cell at or above it is the
        colour map's last colour); fixed, so one colour is one force.
    rate_hz : float
        Display rate of markers, images and the browser view [Hz].
    stale_s : float
        A cell with no valid sample for this long is shown grey [s].
    """

    force_max_n: float = 3.0
    rate_hz: float = 10.0
    stale_s: float = 0.5


@dataclass(frozen=True)
class RobotDescription:
    """A robot: its cell types, its body parts in descriptor order, and parameters.

    Attributes
    ----------
    name : str
        Robot name (``"shadow_hand"``, ``"nao"``).
    cell_types : dict of str to CellType
    body_parts : tuple of BodyPart
        In the order of the whole-robot descriptor (eq. 12, 18, 29).
    contact, window, descriptor : ContactSpec, WindowSpec, DescriptorSpec
    nodes : dict
        The node graph section, read by the launcher and launch files.
    source : str
        File the description was read from.
    geometry : RobotGeometry or None
        Where the cells are (:mod:`.geometry`); None when the file gives none.
    view : ViewSpec
    """

    name: str
    description: str
    cell_types: Mapping[str, CellType]
    body_parts: tuple[BodyPart, ...]
    contact: ContactSpec
    window: WindowSpec
    descriptor: DescriptorSpec
    nodes: Mapping[str, Any]
    source: str = ""
    geometry: RobotGeometry | None = None
    view: ViewSpec = ViewSpec()

    def body_part(self, name: str) -> BodyPart:
        """Return the body part called ``name``; raise ConfigError naming the known ones."""
        for part in self.body_parts:
            if part.name == name:
                return part
        known = ", ".join(p.name for p in self.body_parts)
        raise ConfigError(f"unknown body part {name!r} (known: {known})", key="body_parts", source=self.source)

    def cell_index(self) -> dict[int, tuple[BodyPart, Cell]]:
        """Map every cell id to its body part and cell."""
        return {cell.id: (part, cell) for part in self.body_parts for cell in part.cells}

    @property
    def n_cells(self) -> int:
        return sum(len(p.cells) for p in self.body_parts)


# --------------------------------------------------------------------------- paths


def robot_config_path(name_or_path: str | os.PathLike[str]) -> Path:
    """Resolve ``"nao"`` to ``config/nao.yaml``; paths are returned as they are."""
    return resolve_yaml(name_or_path, config_dir(), noun="robot", file_noun="robot description file")


def load_robot(name_or_path: str | os.PathLike[str]) -> RobotDescription:
    """Load and validate a robot description.

    Parameters
    ----------
    name_or_path : str or path
        A shipped robot's name (``"shadow_hand"``, ``"nao"``) or a YAML path.

    Returns
    -------
    RobotDescription

    Raises
    ------
    ConfigError
        With the offending key, for any inconsistency.
    """
    path = robot_config_path(name_or_path)
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise ConfigError(f"not valid YAML: {exc}", source=str(path)) from None
    return parse_robot(data, source=str(path))


# --------------------------------------------------------------------------- parsing


def _reader(data: Any, key: str, source: str) -> YamlReader:
    """Typed access to a YAML mapping that reports the dotted key on error (:class:`ConfigError`)."""
    return YamlReader(data, key, source, error=ConfigError)


def parse_robot(data: Any, source: str = "<dict>") -> RobotDescription:
    """Validate a robot description given as parsed YAML; see :func:`load_robot`."""
    root = _reader(data, "", source)
    rr = root.child("robot")
    name = rr.get("name", kind=str)
    description = rr.get("description", "", str)
    rr.check_unknown()

    ctr = root.child("cell_types")
    cell_types = {}
    for ct_name in ctr.data:
        ctr.used.add(ct_name)
        cell_types[ct_name] = parse_cell_type(ct_name, ctr.child(ct_name))
    if not cell_types:
        raise root.error("cell_types", "needs at least one cell type")

    raw_parts = root.get("body_parts", kind=list)
    if not raw_parts:
        raise root.error("body_parts", "needs at least one body part")
    parts: list[BodyPart] = []
    seen_parts: set[str] = set()
    seen_cells: dict[int, str] = {}
    for i, raw in enumerate(raw_parts):
        pr = _reader(raw, f"body_parts[{i}]", source)
        pname = pr.get("name", kind=str)
        if pname in seen_parts:
            raise pr.error("name", f"body part {pname!r} is listed twice")
        seen_parts.add(pname)
        ctype = pr.get("cell_type", kind=str)
        pr.get("link", "", str)  # the link the body part is on: read with the geometry
        if ctype not in cell_types:
            raise pr.error("cell_type", f"unknown cell type {ctype!r} (known: {', '.join(cell_types)})")
        cells = []
        raw_cells = pr.get("cells", kind=list)
        if not raw_cells:
            raise pr.error("cells", f"body part {pname!r} has no cells")
        for j, rc in enumerate(raw_cells):
            cr = _reader(rc, pr.path(f"cells[{j}]"), source)
            cid = cr.get("id", kind=int)
            if cid < 0:
                raise cr.error("id", f"cell ids are non-negative, got {cid}")
            if cid in seen_cells:
                raise cr.error("id", f"cell id {cid} is already listed in body part {seen_cells[cid]!r}")
            seen_cells[cid] = pname
            cname = cr.get("name", f"{pname}_{cid}", str)
            extra = {k: v for k, v in cr.data.items() if k not in ("id", "name", *POSE_KEYS)}
            cells.append(Cell(cid, cname, extra))
        pr.check_unknown()
        parts.append(BodyPart(pname, ctype, tuple(cells)))

    cr_ = root.child("contact", {})
    # the defaults of a file that leaves a key out are the spec classes' (one home: node parameters too)
    contact = ContactSpec(
        force_threshold_n=cr_.number("force_threshold_n", ContactSpec.force_threshold_n, minimum=0.0),
        release_threshold_n=cr_.number("release_threshold_n", ContactSpec.release_threshold_n, minimum=0.0),
    )
    cr_.check_unknown()
    if contact.release_threshold_n > contact.force_threshold_n:
        raise cr_.error("release_threshold_n", "must not exceed force_threshold_n (hysteresis)")

    wr = root.child("window", {})
    window = WindowSpec(
        mode=wr.get("mode", WindowSpec.mode, str),
        length_s=wr.number("length_s", WindowSpec.length_s, positive=True),
        hop_s=wr.number("hop_s", WindowSpec.hop_s, positive=True),
        min_duration_s=wr.number("min_duration_s", WindowSpec.min_duration_s, minimum=0.0),
        max_duration_s=wr.number("max_duration_s", WindowSpec.max_duration_s, positive=True),
        release_s=wr.number("release_s", WindowSpec.release_s, minimum=0.0),
    )
    wr.check_unknown()
    if window.mode not in WINDOW_MODES:
        raise wr.error("mode", f"must be one of {WINDOW_MODES}, got {window.mode!r}")
    if window.min_duration_s > window.max_duration_s:
        raise wr.error("min_duration_s", "must not exceed max_duration_s")

    dr = root.child("descriptor", {})
    desc = _parse_descriptor(dr, cell_types, parts)

    nodes = root.get("nodes", {}, dict)
    vr = root.child("view", {})
    view = ViewSpec(force_max_n=vr.number("force_max_n", 3.0, positive=True),
                    rate_hz=vr.number("rate_hz", 10.0, positive=True),
                    stale_s=vr.number("stale_s", 0.5, positive=True))
    vr.check_unknown()
    root.get("geometry", None)  # parsed below, with the parts and cell types
    root.check_unknown()
    geometry = parse_geometry(data, parts, cell_types, source)
    robot = RobotDescription(name, description, cell_types, tuple(parts), contact, window, desc, nodes, source,
                             geometry, view)
    _validate_nodes(robot, source)
    return robot


def _parse_descriptor(dr: YamlReader, cell_types: Mapping[str, CellType], parts: list[BodyPart]) -> DescriptorSpec:
    """``descriptor``: layout and feature groups (``groups``, or the legacy ``channels`` alias)."""
    layout = dr.get("layout", DescriptorSpec.layout, str)
    if layout not in LAYOUT_MODES:
        raise dr.error("layout", f"must be one of {LAYOUT_MODES}, got {layout!r}")
    has_groups, has_channels = "groups" in dr.data, "channels" in dr.data
    if has_groups and has_channels:
        raise dr.error("groups", "give either groups or the legacy channels mode, not both")
    if has_groups:
        raw = dr.get("groups", kind=list)
        if not raw or not all(isinstance(g, str) and g for g in raw):
            raise dr.error("groups", "needs a non-empty list of feature group names")
        channels, groups = "", tuple(raw)
    else:
        channels = dr.get("channels", DescriptorSpec.channels, str)
        if channels not in CHANNEL_MODES:
            raise dr.error("channels", f"must be one of {CHANNEL_MODES}, got {channels!r}")
        groups = groups_of_channels(channels)
    block_s = dr.number("block_s", DescriptorSpec.block_s)
    block_hop_s = dr.number("block_hop_s", min(DescriptorSpec.block_hop_s, block_s) if block_s else
                            DescriptorSpec.block_hop_s)
    dr.check_unknown()
    used = [cell_types[n] for n in dict.fromkeys(p.cell_type for p in parts)]
    check_blocks(block_s, block_hop_s, key=dr.path("block_s").rsplit(".", 1)[0], source=dr.source,
                 rates_hz=[ct.deformation.rate_hz for ct in used])
    for ct in used:  # every group must be computable from every cell type in use, at load time
        if not ct.has_vibration:
            vib = [g for g in groups if g.partition(":")[0] in VIBRATION_GROUPS]
            if vib:
                raise dr.error("groups", f"feature group {vib[0]!r} reads the vibration channels, which cell type "
                                         f"{ct.name!r} does not have (pressure only); the groups it can feed: "
                                         "paper, levels, statistics")
        check_groups(ct, groups, key=dr.path("groups"), source=dr.source)
    return DescriptorSpec(layout=layout, channels=channels, groups=groups, block_s=block_s, block_hop_s=block_hop_s)


def check_blocks(block_s: float, block_hop_s: float, *, key: str = "descriptor", source: str | None = None,
                 rates_hz: Sequence[float] = ()) -> tuple[float, float]:
    """Check a block setting: ``block_s`` >= 0 (0 = off) and ``0 < block_hop_s <= block_s``.

    ``rates_hz`` are the deformation rates of the cell types in use: a block
    must hold at least 3 frames of each.

    Returns
    -------
    (float, float)
        The setting as floats.

    Raises
    ------
    ConfigError
        Naming ``<key>.block_s`` or ``<key>.block_hop_s``.
    """
    try:
        block, hop = float(block_s), float(block_hop_s)
    except (TypeError, ValueError):
        raise ConfigError(f"block_s and block_hop_s must be numbers, got {block_s!r} and {block_hop_s!r}",
                          key=f"{key}.block_s", source=source) from None
    if not np.isfinite(block) or block < 0.0:
        raise ConfigError(f"must be >= 0 seconds (0 = one descriptor of the whole window), got {block_s!r}",
                          key=f"{key}.block_s", source=source)
    if block and not (np.isfinite(hop) and 0.0 < hop <= block):
        raise ConfigError(f"must be > 0 and at most block_s ({block:g} s), got {block_hop_s!r}",
                          key=f"{key}.block_hop_s", source=source)
    for rate in rates_hz:
        if block and round(block * float(rate)) < 3:
            raise ConfigError(f"a block of {block:g} s holds fewer than 3 frames at {float(rate):g} Hz",
                              key=f"{key}.block_s", source=source)
    return block, hop


def _validate_nodes(robot: RobotDescription, source: str) -> None:
    """Check that every body part a node section names exists."""
    known = {p.name for p in robot.body_parts}
    for node_name, spec in robot.nodes.items():
        if not isinstance(spec, Mapping):
            raise ConfigError("expected a mapping", key=f"nodes.{node_name}", source=source)
        for bp in spec.get("body_parts", []) or []:
            if bp not in known:
                raise ConfigError(
                    f"unknown body part {bp!r} (known: {', '.join(p.name for p in robot.body_parts)})",
                    key=f"nodes.{node_name}.body_parts",
                    source=source,
                )


def select_body_parts(robot: RobotDescription, names: Sequence[str]) -> RobotDescription:
    """The robot restricted to ``names`` (in the robot's order); all of it for an empty list.

    Raises
    ------
    ConfigError
        For an unknown body part (naming the known ones) or a name given twice.
    """
    names = [n for n in names if n]
    if not names:
        return robot
    if len(set(names)) != len(names):
        raise ConfigError(f"body part listed twice in {names}", key="body_parts")
    for n in names:
        robot.body_part(n)  # raises with the known names
    parts = tuple(p for p in robot.body_parts if p.name in set(names))
    return dataclasses.replace(robot, body_parts=parts)
