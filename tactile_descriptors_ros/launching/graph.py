"""The node graph of a robot, as data: robot description + options -> NodeSpecs.

The robot YAML's ``nodes:`` section is the declarative graph.  Each entry
names a node and says what to run::

    nodes:
      biotac_driver:                  # node name
        executable: biotac_driver     # one of EXECUTABLES
        body_parts: [thumb, index]    # optional: the body parts this node serves (default: all)
        namespace: ""                 # optional
        parameters: {transport: cheetah, serial: {port: /dev/ttyACM0}}   # nested = dotted names
        sim_parameters: {transport: simulated}   # merged over parameters with --sim SCENE (any node)
        remappings: {tactile/descriptor: /hand/descriptor}

:func:`build_graph` turns it into :class:`NodeSpec` objects that both the
ROS 2 launch files (``launch/*.launch.py``, one ``launch_ros.actions.Node``
per spec) and the in-repo launcher (:mod:`.processes`, ``tactile launch``)
start, so the two cannot drift apart.  It adds what every node needs
(``robot`` as an absolute path, ``body_parts``), the simulation switch
(``--sim SCENE``: every node gets its ``sim_parameters``, drivers ``sim.scene``), and the
scale-out option (one window node per body part).

No rclpy and no launch import here: this module is plain data and is tested
without ROS.
"""

from __future__ import annotations

import copy
import dataclasses
import importlib.util
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from ..core.robot import RobotDescription, load_robot
from ..errors import ConfigError
from .parameters import check_parameters

__all__ = [
    "PACKAGE",
    "EXECUTABLES",
    "DRIVERS",
    "LOG_LEVELS",
    "NodeSpec",
    "read_params_file",
    "build_graph",
    "NOT_ON_PYPI",
    "unrunnable",
    "flatten_parameters",
    "parameters_document",
    "write_parameters_file",
]

PACKAGE = "tactile_descriptors_ros"
#: ``--log-level`` values of rcl.
LOG_LEVELS = ("debug", "info", "warn", "error", "fatal")
#: Executables of the package (console scripts in setup.py).
EXECUTABLES = ("biotac_driver", "skin_driver", "window_node", "classifier_node", "contact_node", "tf_publisher")
#: Interface packages an executable imports that the ROS 2 wheels on PyPI do not carry: a ROS 2 install has
#: them, and ``make setup`` builds them with the ros2 CLI from its sources; a venv of wheels alone lacks them.
NOT_ON_PYPI = {"tf_publisher": "tf2_msgs"}
#: Executables that talk to hardware (and switch to a simulated transport with ``--sim``).
DRIVERS = ("biotac_driver", "skin_driver")
_ENTRY_KEYS = {"executable", "body_parts", "namespace", "parameters", "sim_parameters", "remappings"}


@dataclass(frozen=True)
class NodeSpec:
    """One node to start.

    Attributes
    ----------
    name : str
        Node name (``__node``).
    executable : str
        Console script of :data:`PACKAGE`.
    parameters : dict
        Flat parameter names (``qos.frames.depth``) to values.
    remappings : tuple of (str, str)
    namespace : str
    package : str
    log_level : str
        ``--log-level`` of the node (``""``: rcl's default, info).
    """

    name: str
    executable: str
    parameters: dict[str, Any] = field(default_factory=dict)
    remappings: tuple[tuple[str, str], ...] = ()
    namespace: str = ""
    package: str = PACKAGE
    log_level: str = ""

    @property
    def fully_qualified_name(self) -> str:
        """``/namespace/name`` (``/name`` without a namespace)."""
        ns = "/" + self.namespace.strip("/") if self.namespace.strip("/") else ""
        return f"{ns}/{self.name}"


def flatten_parameters(params: Mapping[str, Any], prefix: str = "", key: str = "parameters",
                       source: str | None = None) -> dict[str, Any]:
    """Nested mappings to dotted names: ``{"qos": {"frames": {"depth": 5}}}`` -> ``{"qos.frames.depth": 5}``.

    Raises
    ------
    ConfigError
        For a value ROS 2 parameters cannot hold (None, an empty or mixed list).
    """
    out: dict[str, Any] = {}
    for name, value in params.items():
        full = f"{prefix}.{name}" if prefix else str(name)
        if isinstance(value, Mapping):
            out.update(flatten_parameters(value, full, key, source))
            continue
        if value is None:
            raise ConfigError("a ROS parameter cannot be null", key=f"{key}.{full}", source=source)
        if isinstance(value, (list, tuple)):
            if not value:
                raise ConfigError("a ROS parameter cannot be an empty list (its type is unknown)",
                                  key=f"{key}.{full}", source=source)
            value = _homogeneous_list(list(value), f"{key}.{full}")
        elif not isinstance(value, (bool, int, float, str)):
            raise ConfigError(f"unsupported parameter value {value!r}", key=f"{key}.{full}", source=source)
        out[full] = value
    return out


def _homogeneous_list(value: list, key: str) -> list:
    """A list ROS 2 can hold: all bool, all str, all int, or numbers with a float (cast to float)."""
    if all(isinstance(v, bool) for v in value) or all(isinstance(v, str) for v in value):
        return value
    numbers = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
    if numbers and all(isinstance(v, int) for v in value):
        return value
    if numbers:
        return [float(v) for v in value]
    raise ConfigError(f"a list parameter needs items of one type (bool, int, float or str), got {value!r}", key=key)


def _entry(robot: RobotDescription, name: str, raw: Any) -> dict[str, Any]:
    key = f"nodes.{name}"
    if not isinstance(raw, Mapping):
        raise ConfigError("expected a mapping", key=key, source=robot.source)
    unknown = set(raw) - _ENTRY_KEYS
    if unknown:
        raise ConfigError(f"unknown key {sorted(unknown)[0]!r} (known: {', '.join(sorted(_ENTRY_KEYS))})",
                          key=key, source=robot.source)
    exe = raw.get("executable")
    if exe not in EXECUTABLES:
        raise ConfigError(f"executable must be one of {EXECUTABLES}, got {exe!r}", key=f"{key}.executable",
                          source=robot.source)
    parts = raw.get("body_parts")
    if parts is not None:
        if not isinstance(parts, list) or not parts or not all(isinstance(p, str) for p in parts):
            raise ConfigError("body_parts must be a non-empty list of body part names", key=f"{key}.body_parts",
                              source=robot.source)
        for p in parts:
            robot.body_part(p)
    for sub in ("parameters", "sim_parameters", "remappings"):
        if not isinstance(raw.get(sub, {}) or {}, Mapping):
            raise ConfigError("expected a mapping", key=f"{key}.{sub}", source=robot.source)
    ns = raw.get("namespace", "") or ""
    if not isinstance(ns, str):
        raise ConfigError("expected a string", key=f"{key}.namespace", source=robot.source)
    return {
        "executable": exe,
        "body_parts": list(parts) if parts else None,
        "namespace": ns,
        "parameters": flatten_parameters(raw.get("parameters") or {}, key=f"{key}.parameters",
                                         source=robot.source),
        "sim_parameters": flatten_parameters(raw.get("sim_parameters") or {}, key=f"{key}.sim_parameters",
                                             source=robot.source),
        "remappings": tuple((str(a), str(b)) for a, b in (raw.get("remappings") or {}).items()),
    }


def unrunnable(specs: Sequence[NodeSpec]) -> dict[str, str]:
    """The nodes of ``specs`` that cannot start on this machine, and why.

    A node whose executable imports an interface package that is not
    installed (:data:`NOT_ON_PYPI`) would end at once with an ``ImportError``,
    and a launcher that stops the graph when one node ends would stop the
    whole graph with it; the launchers leave such a node out and say so.

    Returns
    -------
    dict of str to str
        Node name -> the reason, one line naming the missing package.
    """
    out: dict[str, str] = {}
    for s in specs:
        package = NOT_ON_PYPI.get(s.executable)
        if package is not None and importlib.util.find_spec(package) is None:
            out[s.name] = (f"{s.name} ({s.executable}) left out: it needs the {package} message package, which "
                           f"is not installed (not on PyPI; a ROS 2 install has it, and make setup builds it "
                           f"with the ros2 CLI)")
    return out


def build_graph(robot: RobotDescription | str | os.PathLike[str], *, sim_scene: str | os.PathLike[str] | None = None,
                sim_speed: float | None = None, split_window_nodes: bool = False, model_path: str | None = None,
                use_sim_time: bool = False, overrides: Mapping[str, Mapping[str, Any]] | None = None,
                namespace: str = "", drivers: bool = True,
                params_file: str | os.PathLike[str] | None = None, log_level: str = "") -> list[NodeSpec]:
    """The nodes to start for a robot.

    Parameters
    ----------
    robot : RobotDescription or str or path
        A loaded description, a shipped robot name or a YAML path.
    sim_scene : str or path, optional
        A scene name (``demo_shadow_hand``) or path: every node gets its
        ``sim_parameters``; drivers run on the simulated transport (plus
        ``sim.scene`` as an absolute path).
    sim_speed : float, optional
        ``sim.speed`` of the drivers with ``sim_scene``: simulated seconds per
        wall second (a busy machine needs less than 1; default: the
        ``sim_parameters``', else the driver's 1.0).
    split_window_nodes : bool
        Scale-out: every window node serving several body parts becomes one
        node per body part (``<name>_<body part>``), all publishing on the
        same descriptor topic with interleaved exploration ids
        (``exploration_id_stride``/``offset``), and a ``pooled`` layout so
        one classifier can take them all.
    model_path : str, optional
        ``model_path`` of every classifier node.
    use_sim_time : bool
        Set ``use_sim_time`` on every node (bag replay with ``--clock``).
    overrides : mapping, optional
        Node name -> parameters merged last (nested or dotted names).
    namespace : str
        Namespace of nodes that do not set their own.
    drivers : bool
        Start the device drivers; without them every other node runs
        (window, classifier, contact, tf_publisher), for a bag replayed into
        them (``tactile replay``).
    params_file : str or path, optional
        A ROS 2 parameters file (``{node: {ros__parameters: {...}}}``; a node
        by name, fully qualified name or ``/**`` for every node declaring the
        parameter), merged over the graph's parameters and under ``overrides``.
    log_level : str
        ``--log-level`` of every node (:data:`LOG_LEVELS`; ``""``: info).

    Returns
    -------
    list of NodeSpec
        In the order of the ``nodes:`` section (drivers first by convention).

    Raises
    ------
    ConfigError
        For an empty or malformed ``nodes:`` section, an unknown body part,
        executable or override target, a parameter the node does not declare,
        of the wrong type or refused by its schema
        (:func:`~.parameters.check_parameters`), an unreadable parameters
        file, or contradictory options (a scene without drivers).
    """
    if not isinstance(robot, RobotDescription):
        robot = load_robot(robot)
    if not robot.nodes:
        raise ConfigError("the robot description has no 'nodes:' section to launch", key="nodes",
                          source=robot.source)
    robot_param = str(Path(robot.source).resolve()) if robot.source and Path(robot.source).is_file() else robot.name
    if sim_speed is not None and not (float(sim_speed) > 0 and float(sim_speed) != float("inf")):
        raise ConfigError(f"must be a finite number above 0, got {sim_speed!r}", key="sim_speed")
    if log_level and log_level not in LOG_LEVELS:
        raise ConfigError(f"must be one of {', '.join(LOG_LEVELS)}, got {log_level!r}", key="log_level")
    if not drivers and sim_scene is not None and str(sim_scene):
        raise ConfigError("a simulated scene plays through the drivers: drop sim, or start the drivers",
                          key="sim")
    scene_param = None
    if sim_scene is not None and str(sim_scene):
        from ..sim.scene import scene_path

        scene_param = str(scene_path(sim_scene).resolve())
    entries = {name: _entry(robot, name, raw) for name, raw in robot.nodes.items()}
    overrides = {k: flatten_parameters(v, key=f"overrides.{k}") for k, v in (overrides or {}).items()}

    specs: list[NodeSpec] = []
    for name, e in entries.items():
        params: dict[str, Any] = {}
        exe = e["executable"]
        # the classifier only names its default model file after the robot
        params["robot"] = robot_param
        if exe != "classifier_node":
            if e["body_parts"]:
                params["body_parts"] = list(e["body_parts"])
        params.update(e["parameters"])
        if scene_param is not None:
            params.update(e["sim_parameters"])
        if exe in DRIVERS and scene_param is not None:
            params.setdefault("transport", "simulated")
            params["sim.scene"] = scene_param
            if sim_speed is not None:
                params["sim.speed"] = float(sim_speed)
        if exe == "classifier_node" and model_path is not None:
            params["model_path"] = str(model_path)
        if use_sim_time:
            params["use_sim_time"] = True
        specs.append(NodeSpec(name, exe, params, e["remappings"], e["namespace"] or namespace))

    if split_window_nodes:
        specs = _split_window_nodes(robot, specs)
    if not drivers:
        specs = [s for s in specs if s.executable not in DRIVERS]
        if not specs:
            raise ConfigError("the graph has only drivers", key="drivers", source=robot.source)
    if params_file is not None and str(params_file):
        specs = _apply_params_file(specs, params_file)

    names = {s.name for s in specs}
    for target, values in overrides.items():
        if target not in names:
            raise ConfigError(f"no node named {target!r} to override (nodes: {', '.join(sorted(names))})",
                              key=f"overrides.{target}")
        specs = [dataclasses.replace(s, parameters={**s.parameters, **values}) if s.name == target else s
                 for s in specs]
    # every parameter declared by its executable, with its type (an integer for a double widens) and a value
    # its schema accepts
    specs = [dataclasses.replace(s, parameters=check_parameters(s.name, s.executable, s.parameters),
                                 log_level=log_level) for s in specs]
    fq = [s.fully_qualified_name for s in specs]
    dup = sorted({n for n in fq if fq.count(n) > 1})
    if dup:
        raise ConfigError(f"two nodes would have the same name {dup[0]!r}", key="nodes", source=robot.source)
    return specs


def _split_window_nodes(robot: RobotDescription, specs: list[NodeSpec]) -> list[NodeSpec]:
    out: list[NodeSpec] = []
    windows = [s for s in specs if s.executable == "window_node"]
    parts_of = {s.name: list(s.parameters.get("body_parts") or [p.name for p in robot.body_parts]) for s in windows}
    total = sum(len(v) for v in parts_of.values())
    index = 0
    for s in specs:
        if s.executable != "window_node":
            out.append(s)
            continue
        layout = s.parameters.get("descriptor.layout", "pooled")
        if layout != "pooled":
            raise ConfigError(
                f"window node {s.name!r} sets descriptor.layout {layout!r}, but split window nodes publish one "
                "body part each on one topic: only the 'pooled' layout gives the classifier one feature layout",
                key=f"nodes.{s.name}.parameters.descriptor.layout", source=robot.source)
        for part in parts_of[s.name]:
            params = copy.deepcopy(s.parameters)
            params.update({"body_parts": [part], "descriptor.layout": "pooled",
                           "exploration_id_stride": total, "exploration_id_offset": index})
            out.append(dataclasses.replace(s, name=f"{s.name}_{part}", parameters=params))
            index += 1
    return out


def read_params_file(path: str | os.PathLike[str]) -> dict[str, dict[str, Any]]:
    """A ROS 2 parameters file: node key (name, ``/ns/name`` or ``/**``) -> flat parameters.

    Raises
    ------
    ConfigError
        Naming the file: unreadable, not YAML, or not the ``{node: {ros__parameters: {...}}}`` layout.
    """
    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise ConfigError(f"cannot read the parameters file: {exc.strerror or exc}", key="params_file",
                          source=str(path)) from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"not YAML: {exc}", key="params_file", source=str(path)) from None
    if not isinstance(doc, Mapping) or not doc:
        raise ConfigError("expected a mapping of node names to {ros__parameters: {...}}", key="params_file",
                          source=str(path))
    out: dict[str, dict[str, Any]] = {}
    for node, entry in doc.items():
        if not isinstance(entry, Mapping) or set(entry) != {"ros__parameters"} or \
                not isinstance(entry["ros__parameters"], Mapping):
            raise ConfigError("expected {ros__parameters: {...}}", key=str(node), source=str(path))
        out[str(node)] = flatten_parameters(entry["ros__parameters"], key=str(node), source=str(path))
    return out


def _apply_params_file(specs: list[NodeSpec], path: str | os.PathLike[str]) -> list[NodeSpec]:
    """``specs`` with a parameters file's values merged in (a ``/**`` value: into every node declaring it)."""
    from .parameters import PARAMETER_TYPES

    entries = read_params_file(path)
    out = list(specs)
    for key, values in entries.items():
        if key == "/**":
            for name, value in values.items():
                takers = [i for i, s in enumerate(out) if name in PARAMETER_TYPES[s.executable]]
                if not takers:
                    raise ConfigError(f"no node of the graph declares {name!r}", key=f"/**.{name}",
                                      source=str(path))
                for i in takers:
                    out[i] = dataclasses.replace(out[i], parameters={**out[i].parameters, name: value})
            continue
        hits = [i for i, s in enumerate(out) if key in (s.name, s.fully_qualified_name)]
        if not hits:
            known = ", ".join(s.fully_qualified_name for s in out)
            raise ConfigError(f"no node {key!r} in the graph (nodes: {known}; /** for all)", key=key,
                              source=str(path))
        for i in hits:
            out[i] = dataclasses.replace(out[i], parameters={**out[i].parameters, **values})
    return out


def parameters_document(specs: Sequence[NodeSpec]) -> dict[str, Any]:
    """A ROS 2 parameters file (``--params-file``) for the specs: ``{fq name: {ros__parameters: ...}}``."""
    return {s.fully_qualified_name: {"ros__parameters": dict(s.parameters)} for s in specs}


def write_parameters_file(specs: Sequence[NodeSpec], path: str | os.PathLike[str]) -> Path:
    """Write :func:`parameters_document` as YAML; return the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(parameters_document(specs), sort_keys=False, default_flow_style=False))
    return path
