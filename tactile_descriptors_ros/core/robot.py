"""Robot descriptions: body parts, cells, channels, rates and thresholds as data.

One YAML file per robot in ``config/`` (``shadow_hand.yaml``, ``nao.yaml``)
is read by the nodes, the launch files and the in-repo launcher alike.  The
descriptor layout follows from it (paper eq. 11): each *cell type* declares
a vibration modality S and a deformation modality V, each as a list of axes
and each axis as a list of channels; the general 24-value form is three axes
of each, the BioTac's eq. 17 one PAC axis and one axis of 19 electrodes, the
skin cell's eq. 28 three accelerometer axes and one axis of three force
sensors.

Besides S and V a cell type may declare *extra channels* (``extra_channels``):
slow signals sampled with V (one value per V sample) that enter only the
feature groups that use them -- the BioTac's PDC, TDC and TAC, the skin
cell's proximity and temperature.  Which feature groups make up the
descriptor is chosen in the ``descriptor`` section (``groups``;
:mod:`.features`), and checked at load time against what every cell type
can feed.

Validation is strict and names the offending key: an unknown body part or
cell type, a cell id listed twice, an impossible rate or threshold fails at
load time with :class:`~tactile_descriptors_ros.errors.ConfigError`.
"""

from __future__ import annotations

import dataclasses
import os
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from ..errors import ConfigError
from .yamlreader import YamlReader, resolve_yaml

__all__ = [
    "Modality",
    "ForceSpec",
    "CellType",
    "Cell",
    "BodyPart",
    "ContactSpec",
    "WindowSpec",
    "DescriptorSpec",
    "select_body_parts",
    "RobotDescription",
    "load_robot",
    "parse_robot",
    "config_dir",
    "robot_config_path",
    "WINDOW_MODES",
    "LAYOUT_MODES",
    "CHANNEL_MODES",
]

WINDOW_MODES = ("fixed", "exploration")
LAYOUT_MODES = ("concat", "pooled")
CHANNEL_MODES = ("averaged", "per_channel")


@dataclass(frozen=True)
class Modality:
    """One sensing modality of a cell type (vibration S or deformation V).

    Attributes
    ----------
    symbol : str
        Short name used in descriptor labels (``"pac"``, ``"E"``, ``"a"``, ``"F"``).
    rate_hz : float
        Nominal sampling rate.
    adc_bits : int
        ADC resolution; values are integer counts in ``[0, 2**bits)``, or
        ``[-2**(bits-1), 2**(bits-1))`` when ``signed``.
    signed : bool
        Whether counts are signed.
    unit : str
        SI unit after scaling (``"Pa"``, ``"m/s^2"``, ``"N"``, or ``"count"``).
    si_per_count : float
        Scale from counts to ``unit``.
    axes : tuple of tuple of str
        Channels grouped by axis; values are averaged over the channels of an
        axis (paper eq. 6-10) and kept per axis.
    axis_names : tuple of str
        One name per axis (``""`` for a single axis, ``"x"``, ``"y"``, ``"z"``).
    """

    symbol: str
    rate_hz: float
    adc_bits: int
    signed: bool
    unit: str
    si_per_count: float
    axes: tuple[tuple[str, ...], ...]
    axis_names: tuple[str, ...]

    @property
    def channels(self) -> tuple[str, ...]:
        """All channels, axis by axis."""
        return tuple(ch for axis in self.axes for ch in axis)

    @property
    def adc_range(self) -> tuple[int, int]:
        """Smallest and largest count the ADC can report."""
        if self.signed:
            half = 1 << (self.adc_bits - 1)
            return (-half, half - 1)
        return (0, (1 << self.adc_bits) - 1)


@dataclass(frozen=True)
class ForceSpec:
    """How a cell's normal force is measured, for the contact gate (eq. 13, 16, 27).

    Attributes
    ----------
    channels : tuple of str
        Channels averaged to give the force (BioTac ``pdc``; skin ``f1 f2 f3``).
    n_per_count : float
        Newtons per count after taring.
    rate_hz : float
        Sampling rate of the force channels.
    """

    channels: tuple[str, ...]
    n_per_count: float
    rate_hz: float


@dataclass(frozen=True)
class CellType:
    """A kind of sensing cell: BioTac, skin cell, or anything declared in YAML."""

    name: str
    vibration: Modality
    deformation: Modality
    force: ForceSpec
    correlate: str  # "each_with_all" (S axis with every V axis) or "pairwise" (axis i with i)
    extra_channels: tuple[str, ...] = ()  # slow channels sampled with V (levels only)

    @property
    def channels(self) -> tuple[str, ...]:
        """Every channel the cell type declares: S, V, then the extra channels."""
        return self.vibration.channels + self.deformation.channels + self.extra_channels

    def correlation_pairs(self) -> tuple[tuple[int, int], ...]:
        """(vibration axis, deformation axis) pairs whose correlations are averaged (eq. 9-10)."""
        n_s, n_v = len(self.vibration.axes), len(self.deformation.axes)
        if self.correlate == "pairwise":
            return tuple((i, i) for i in range(n_s))
        return tuple((i, j) for i in range(n_s) for j in range(n_v))


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
    """Contact gate parameters (eq. 13): ``force_threshold_n`` is F_t."""

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
        Feature groups in descriptor order (:data:`.features.GROUPS`).
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


def config_dir() -> Path:
    """Directory holding the shipped robot descriptions and scenes.

    Looked up in order: ``$TACTILE_CONFIG_DIR``; the source checkout
    (``<repo>/config``); the installed share directory
    (``<prefix>/share/tactile_descriptors_ros/config``); the ament index.
    """
    env = os.environ.get("TACTILE_CONFIG_DIR")
    candidates = [Path(env)] if env else []
    candidates.append(Path(__file__).resolve().parents[2] / "config")
    candidates.append(Path(sys.prefix) / "share" / "tactile_descriptors_ros" / "config")
    for path in candidates:
        if (path / "shadow_hand.yaml").is_file():
            return path
    try:  # a colcon install on a real ROS 2 system
        from ament_index_python.packages import get_package_share_directory

        return Path(get_package_share_directory("tactile_descriptors_ros")) / "config"
    except Exception:  # noqa: BLE001 - ament_index may be absent or not know the package
        pass
    raise ConfigError("cannot find the config directory; set TACTILE_CONFIG_DIR")


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


def _parse_modality(r: YamlReader) -> Modality:
    bits = int(r.number("adc_bits", 12, positive=True))
    if not 1 <= bits <= 24:
        raise r.error("adc_bits", f"must be between 1 and 24, got {bits}")
    raw_axes = r.get("axes", kind=list)
    if not raw_axes:
        raise r.error("axes", "needs at least one axis")
    axes, names = [], []
    seen: set[str] = set()
    for i, raw in enumerate(raw_axes):
        ar = _reader(raw, r.path(f"axes[{i}]"), r.source)
        channels = ar.get("channels", kind=list)
        if not channels or not all(isinstance(c, str) and c for c in channels):
            raise ar.error("channels", "needs a non-empty list of channel names")
        for ch in channels:
            if ch in seen:
                raise ar.error("channels", f"channel {ch!r} is listed twice")
            seen.add(ch)
        axes.append(tuple(channels))
        names.append(str(ar.get("name", "", str)))
        ar.check_unknown()
    modality = Modality(
        symbol=str(r.get("symbol", kind=str)),
        rate_hz=r.number("rate_hz", positive=True),
        adc_bits=bits,
        signed=bool(r.get("signed", False, bool)),
        unit=str(r.get("unit", "count", str)),
        si_per_count=r.number("si_per_count", 1.0, positive=True),
        axes=tuple(axes),
        axis_names=tuple(names),
    )
    r.check_unknown()
    if modality.rate_hz > 1e6:
        raise r.error("rate_hz", f"{modality.rate_hz} Hz is not a plausible tactile sampling rate")
    return modality


def _parse_cell_type(name: str, r: YamlReader) -> CellType:
    vib = _parse_modality(r.child("vibration"))
    dfm = _parse_modality(r.child("deformation"))
    fr = r.child("force")
    force_channels = fr.get("channels", kind=list)
    if not force_channels:
        raise fr.error("channels", "needs at least one force channel")
    force = ForceSpec(tuple(force_channels), fr.number("n_per_count", positive=True), fr.number("rate_hz", positive=True))
    fr.check_unknown()
    correlate = r.get("correlate", "each_with_all", str)
    if correlate not in ("each_with_all", "pairwise"):
        raise r.error("correlate", f"must be 'each_with_all' or 'pairwise', got {correlate!r}")
    if correlate == "pairwise" and len(vib.axes) != len(dfm.axes):
        raise r.error("correlate", "'pairwise' needs as many vibration axes as deformation axes")
    if vib.rate_hz < dfm.rate_hz:
        raise r.error("vibration", "the vibration modality must be the faster one (it is the time base for correlations)")
    extra = r.get("extra_channels", [], list)
    if not all(isinstance(c, str) and c for c in extra):
        raise r.error("extra_channels", "needs a list of channel names")
    known = set(vib.channels) | set(dfm.channels)
    for i, ch in enumerate(extra):
        if ch in known or ch in extra[:i]:
            raise r.error("extra_channels", f"channel {ch!r} is already declared")
    r.check_unknown()
    return CellType(name, vib, dfm, force, correlate, tuple(extra))


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
        cell_types[ct_name] = _parse_cell_type(ct_name, ctr.child(ct_name))
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
            extra = {k: v for k, v in cr.data.items() if k not in ("id", "name")}
            cells.append(Cell(cid, cname, extra))
        pr.check_unknown()
        parts.append(BodyPart(pname, ctype, tuple(cells)))

    cr_ = root.child("contact", {})
    contact = ContactSpec(
        force_threshold_n=cr_.number("force_threshold_n", 0.2, minimum=0.0),
        release_threshold_n=cr_.number("release_threshold_n", 0.1, minimum=0.0),
    )
    cr_.check_unknown()
    if contact.release_threshold_n > contact.force_threshold_n:
        raise cr_.error("release_threshold_n", "must not exceed force_threshold_n (hysteresis)")

    wr = root.child("window", {})
    window = WindowSpec(
        mode=wr.get("mode", "exploration", str),
        length_s=wr.number("length_s", 2.0, positive=True),
        hop_s=wr.number("hop_s", 0.5, positive=True),
        min_duration_s=wr.number("min_duration_s", 1.0, minimum=0.0),
        max_duration_s=wr.number("max_duration_s", 10.0, positive=True),
        release_s=wr.number("release_s", 0.1, minimum=0.0),
    )
    wr.check_unknown()
    if window.mode not in WINDOW_MODES:
        raise wr.error("mode", f"must be one of {WINDOW_MODES}, got {window.mode!r}")
    if window.min_duration_s > window.max_duration_s:
        raise wr.error("min_duration_s", "must not exceed max_duration_s")

    dr = root.child("descriptor", {})
    desc = _parse_descriptor(dr, cell_types, parts)

    nodes = root.get("nodes", {}, dict)
    root.check_unknown()
    robot = RobotDescription(name, description, cell_types, tuple(parts), contact, window, desc, nodes, source)
    _validate_nodes(robot, source)
    return robot


def _parse_descriptor(dr: YamlReader, cell_types: Mapping[str, CellType], parts: list[BodyPart]) -> DescriptorSpec:
    """``descriptor``: layout and feature groups (``groups``, or the legacy ``channels`` alias)."""
    from .features import check_groups, groups_of_channels

    layout = dr.get("layout", "concat", str)
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
        channels = dr.get("channels", "averaged", str)
        if channels not in CHANNEL_MODES:
            raise dr.error("channels", f"must be one of {CHANNEL_MODES}, got {channels!r}")
        groups = groups_of_channels(channels)
    block_s = dr.number("block_s", 0.0)
    block_hop_s = dr.number("block_hop_s", min(0.5, block_s) if block_s else 0.5)
    from .blocks import check_blocks
    dr.check_unknown()
    used = [cell_types[n] for n in dict.fromkeys(p.cell_type for p in parts)]
    check_blocks(block_s, block_hop_s, key=dr.path("block_s").rsplit(".", 1)[0], source=dr.source,
                 rates_hz=[ct.deformation.rate_hz for ct in used])
    used = [cell_types[n] for n in dict.fromkeys(p.cell_type for p in parts)]
    for ct in used:  # every group must be computable from every cell type in use, at load time
        check_groups(ct, groups, key=dr.path("groups"), source=dr.source)
    return DescriptorSpec(layout=layout, channels=channels, groups=groups, block_s=block_s, block_hop_s=block_hop_s)


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
