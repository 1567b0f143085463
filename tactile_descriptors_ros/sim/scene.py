"""Scenes: one experiment as YAML, validated strictly, resolved into explorations.

A scene names a robot (``config/<robot>.yaml``), the effects to simulate
(nothing else is computed), default exploration parameters and a list of
explorations (touches with labels).  Parameters may be fixed values or
random draws, resolved once with the scene's seed, so a scene always expands
to the same explorations:

* a number or string: fixed;
* ``{grid: [min, max, step]}``: uniform over ``min, min+step, ..., max``
  (the paper's F in {0.2, 0.6, ..., 3} N, V in {0.5, ..., 4} cm/s,
  T in {2, ..., 10} s);
* ``{choice: [a, b, ...]}``: uniform over the list;
* ``{uniform: [lo, hi]}``: continuous uniform.

``body_parts`` is ``all``, a list, or ``{random_subset: [...], min: 1}``
(the paper's "any combination of fingers").  Motions are ``lateral``,
``medial``, ``circular``, sequences joined by ``+``
(``lateral+medial+circular``), ``rotating_stage``, ``in_hand`` (sliding
fingers on an object held by ``holding_parts``) and ``large_object`` (NAO:
an object of ``weight_g`` sliding between arms and chest; force, speed and
duration follow from the weight unless given).

See ``docs/simulator.md`` for the full schema and the shipped scenes.
"""

from __future__ import annotations

import math
import os
import random
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..core.robot import RobotDescription, config_dir, load_robot, robot_config_path
from ..core.yamlreader import YamlReader, resolve_yaml
from ..errors import ConfigError, SceneError

__all__ = [
    "EFFECTS",
    "MOTIONS",
    "Exploration",
    "Scene",
    "load_scene",
    "parse_scene",
    "scenes_dir",
    "scene_path",
    "large_object_parameters",
    "sensor_defaults",
    "sensor_kind",
    "restrict_robot",
]

#: Every effect a scene may declare, with its parameters and their defaults.
EFFECTS: dict[str, dict[str, Any]] = {
    "texture_vibration": {"gain": 1.0},
    "normal_force": {"ramp_s": 0.15, "load_spread": 0.3},
    "electrode_deformation": {"gain": 1.0},
    "stick_slip": {"gain": 1.0, "decay_s": 0.03, "frequency_hz": 40.0},
    "sensor_noise": {"std_counts": 1.0, "per_stream": {}},
    "bias_drift": {"counts_per_s": 0.5},
    "adc": {},
    "dropped_frames": {"probability": 0.001},
    "bad_parity": {"probability": 0.0005},
    "corrupt_frames": {"probability": 0.0005},
    "unplug": {"events": []},
    "proximity": {"lead_s": 0.3},
    "contact_patch": {"radius_m": 0.01, "biotac_radius_m": 0.004, "electrode_counts_per_n": 150.0},
}

#: Single motions; sequences are joined with '+'.
MOTIONS = ("lateral", "medial", "circular", "rotating_stage", "in_hand", "large_object")
_SLIDING = ("lateral", "medial", "circular")

_EXPLORATION_KEYS = {
    "material", "materials", "label", "repeat", "order", "motion", "body_parts", "holding_parts",
    "force_n", "holding_force_n", "speed_m_s", "duration_s", "pause_s", "stroke_m", "circle_period_s",
    "stage_radius_m", "stage_frequency_hz", "weight_g", "slide_m", "group",
}
_DEFAULT_KEYS = _EXPLORATION_KEYS - {"material", "materials", "label", "repeat", "order"}


@dataclass(frozen=True)
class Exploration:
    """One touch: ground truth of what the simulator renders.

    Times are relative to the scene start and set by the engine's timeline
    (``onset_s`` = force ramp starts, ``release_s`` = force back to zero).
    """

    index: int
    label: str
    material: str
    motion: tuple[str, ...]
    body_parts: tuple[str, ...]
    holding_parts: tuple[str, ...]
    force_n: float
    holding_force_n: float
    speed_m_s: float
    duration_s: float
    pause_s: float
    stroke_m: float
    circle_period_s: float
    weight_g: float | None
    group: str
    part_force_n: Mapping[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {
            "index": self.index, "label": self.label, "material": self.material, "motion": "+".join(self.motion),
            "body_parts": list(self.body_parts), "holding_parts": list(self.holding_parts),
            "force_n": self.force_n, "holding_force_n": self.holding_force_n, "speed_m_s": self.speed_m_s,
            "duration_s": self.duration_s, "pause_s": self.pause_s, "weight_g": self.weight_g, "group": self.group,
            "part_force_n": dict(self.part_force_n),
        }


@dataclass(frozen=True)
class Scene:
    """A validated scene.

    Attributes
    ----------
    name, description : str
    robot : RobotDescription
    seed : int
    start_ns : int
        Time stamp of the first sample.
    lead_in_s : float
        Time without contact before the first exploration (for taring).
    effects : dict of str to dict
        Declared effects with their parameters (defaults filled in); only
        these are computed.
    sensors : dict
        Per-cell-type sensor overrides (baselines, gains, rates).
    explorations : tuple of Exploration
        Resolved explorations, in order.
    source : str
    """

    name: str
    description: str
    robot: RobotDescription
    seed: int
    start_ns: int
    lead_in_s: float
    effects: Mapping[str, Mapping[str, Any]]
    sensors: Mapping[str, Mapping[str, Any]]
    explorations: tuple[Exploration, ...]
    source: str = ""

    def has(self, effect: str) -> bool:
        """Whether the scene declared ``effect``."""
        return effect in self.effects

    @property
    def duration_s(self) -> float:
        """Total simulated time (lead-in, ramps, explorations, pauses)."""
        ramp = float(self.effects.get("normal_force", {}).get("ramp_s", EFFECTS["normal_force"]["ramp_s"]))
        return self.lead_in_s + sum(2 * ramp + e.duration_s + e.pause_s for e in self.explorations)


# --------------------------------------------------------------------------- paths


def scenes_dir() -> Path:
    """``config/scenes`` (next to the robot descriptions)."""
    return config_dir() / "scenes"


def scene_path(name_or_path: str | os.PathLike[str]) -> Path:
    """Resolve a shipped scene name (``demo_nao``) or a path."""
    return resolve_yaml(name_or_path, scenes_dir(), noun="scene", file_noun="scene file", error=SceneError)


def load_scene(name_or_path: str | os.PathLike[str], *, seed: int | None = None) -> Scene:
    """Load and validate a scene; ``seed`` overrides the scene's seed.

    Raises
    ------
    SceneError
        Naming the offending key.
    """
    path = scene_path(name_or_path)
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise SceneError(f"not valid YAML: {exc}", source=str(path)) from None
    return parse_scene(data, source=str(path), seed=seed)


# --------------------------------------------------------------------------- parsing


def _reader(data: Any, key: str, source: str) -> YamlReader:
    """Typed access to a mapping that names the dotted key in every error (:class:`SceneError`)."""
    return YamlReader(data, key, source, error=SceneError)


def _draw(spec: Any, key: str, source: str, rng: random.Random, *, numeric: bool,
          positive: bool = True) -> Any:
    """Resolve a value spec (fixed, grid, choice, uniform) to one value."""
    if isinstance(spec, Mapping):
        if len(spec) != 1:
            raise SceneError("a random value is one of {grid: [...]}, {choice: [...]}, {uniform: [...]}",
                             key=key, source=source)
        (kind, args), = spec.items()
        if kind == "choice":
            if not isinstance(args, list) or not args:
                raise SceneError("choice needs a non-empty list", key=f"{key}.choice", source=source)
            value = args[rng.randrange(len(args))]
        elif kind in ("grid", "uniform") and numeric:
            if (not isinstance(args, list) or len(args) != (3 if kind == "grid" else 2)
                    or not all(isinstance(a, (int, float)) and not isinstance(a, bool) for a in args)):
                n = "[min, max, step]" if kind == "grid" else "[low, high]"
                raise SceneError(f"{kind} needs {n}", key=f"{key}.{kind}", source=source)
            lo, hi = float(args[0]), float(args[1])
            if hi < lo:
                raise SceneError(f"{kind}: max {hi} is below min {lo}", key=f"{key}.{kind}", source=source)
            if kind == "grid":
                step = float(args[2])
                if step <= 0:
                    raise SceneError("grid step must be positive", key=f"{key}.grid", source=source)
                n = int(math.floor((hi - lo) / step + 1e-9)) + 1
                value = round(lo + step * rng.randrange(n), 9)
            else:
                value = rng.uniform(lo, hi)
        else:
            raise SceneError(f"unknown random value kind {kind!r} (use grid, choice or uniform)", key=key, source=source)
    else:
        value = spec
    if numeric:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SceneError(f"expected a number, got {value!r}", key=key, source=source)
        value = float(value)
        if not math.isfinite(value) or (positive and value <= 0) or value < 0:
            raise SceneError(f"must be {'positive' if positive else 'non-negative'} and finite, got {value!r}",
                             key=key, source=source)
    return value


#: Large objects (paper section V-B): grasp force per weight (f_500 = 2 N,
#: f_1000 = 2.7 N, f_1500 = 3.5 N); the sliding speed grows with the weight.
_GRASP_N = ((500.0, 2.0), (1000.0, 2.7), (1500.0, 3.5))


def large_object_parameters(weight_g: float, slide_m: float = 0.1) -> tuple[float, float, float]:
    """Grasp force (N), sliding speed (m/s) and sliding time (s) of a large object of ``weight_g``.

    The grasp force interpolates the paper's values (2, 2.7, 3.5 N for 500,
    1000, 1500 g); the paper gives no speed, so we take the speed
    proportional to the weight (1, 2, 3 cm/s) and the time to slide
    ``slide_m``: heavier objects slide faster and for a shorter time, as the
    paper reports.
    """
    w, f = zip(*_GRASP_N)
    force = float(np.interp(weight_g, w, f, left=None, right=None))
    if weight_g < w[0]:
        force = f[0] * weight_g / w[0]
    elif weight_g > w[-1]:
        force = f[-1] + (weight_g - w[-1]) * (f[-1] - f[-2]) / (w[-1] - w[-2])
    speed = 0.01 * weight_g / 500.0
    return force, speed, slide_m / speed


def _parse_motion(value: Any, key: str, source: str) -> tuple[str, ...]:
    if not isinstance(value, str) or not value:
        raise SceneError(f"expected a motion name, got {value!r}", key=key, source=source)
    parts = tuple(p.strip() for p in value.split("+"))
    for p in parts:
        if p not in MOTIONS:
            raise SceneError(f"unknown motion {p!r} (known: {', '.join(MOTIONS)}, or sequences like "
                             "lateral+medial+circular)", key=key, source=source)
    if len(parts) > 1 and not all(p in _SLIDING for p in parts):
        raise SceneError(f"only {', '.join(_SLIDING)} can be combined in a sequence, got {value!r}", key=key, source=source)
    return parts


def _parse_parts(spec: Any, key: str, source: str, robot: RobotDescription, rng: random.Random) -> tuple[str, ...]:
    known = [p.name for p in robot.body_parts]
    if spec == "all":
        return tuple(known)
    if isinstance(spec, Mapping):
        r = _reader(spec, key, source)
        pool = r.get("random_subset", kind=list)
        minimum = int(r.number("min", 1, positive=True))
        maximum = int(r.number("max", len(pool), positive=True))
        r.check_unknown()
        for i, name in enumerate(pool):
            if name not in known:
                raise SceneError(f"unknown body part {name!r} (known: {', '.join(known)})",
                                 key=f"{key}.random_subset[{i}]", source=source)
        if not 1 <= minimum <= maximum <= len(pool):
            raise SceneError(f"need 1 <= min <= max <= {len(pool)}", key=f"{key}.min", source=source)
        k = rng.randint(minimum, maximum)
        chosen = set(rng.sample(range(len(pool)), k))
        return tuple(p for i, p in enumerate(pool) if i in chosen)
    if isinstance(spec, str):
        spec = [spec]
    if not isinstance(spec, list) or not spec:
        raise SceneError("expected 'all', a list of body parts or {random_subset: [...]}", key=key, source=source)
    for i, name in enumerate(spec):
        if name not in known:
            raise SceneError(f"unknown body part {name!r} (known: {', '.join(known)})", key=f"{key}[{i}]", source=source)
    if len(set(spec)) != len(spec):
        raise SceneError("a body part is listed twice", key=key, source=source)
    return tuple(spec)


def _parse_effects(r: YamlReader, robot: RobotDescription) -> dict[str, dict[str, Any]]:
    raw = r.get("effects", {}, dict)
    out: dict[str, dict[str, Any]] = {}
    cell_ids = {c.id for p in robot.body_parts for c in p.cells}
    for name, params in raw.items():
        key = f"effects.{name}"
        if name not in EFFECTS:
            raise SceneError(f"unknown effect (known: {', '.join(EFFECTS)})", key=key, source=r.source)
        params = {} if params is None else params
        er = _reader(params, key, r.source)
        merged = dict(EFFECTS[name])
        for pname, default in EFFECTS[name].items():
            if isinstance(default, float):
                v = er.number(pname, default, minimum=0.0)
                if pname == "probability" and v > 1:
                    raise er.error(pname, f"a probability is at most 1, got {v}")
                merged[pname] = v
            elif isinstance(default, dict):
                sub = er.get(pname, default, dict)
                for sk, sv in sub.items():
                    if isinstance(sv, bool) or not isinstance(sv, (int, float)) or sv < 0:
                        raise SceneError(f"expected a non-negative number, got {sv!r}", key=f"{key}.{pname}.{sk}",
                                         source=r.source)
                merged[pname] = {k: float(v) for k, v in sub.items()}
            elif isinstance(default, list):
                merged[pname] = er.get(pname, default, list)
        er.check_unknown()
        if name == "unplug":
            events = []
            for i, ev in enumerate(merged["events"]):
                vr = _reader(ev, f"{key}.events[{i}]", r.source)
                cell = vr.get("cell", kind=int)
                if cell not in cell_ids:
                    raise vr.error("cell", f"no cell with id {cell} on robot {robot.name!r}")
                events.append({"cell": cell, "at_s": vr.number("at_s", minimum=0.0), "for_s": vr.number("for_s", positive=True),
                               "rebias_counts": vr.number("rebias_counts", 0.0, minimum=0.0)})
                vr.check_unknown()
            if not events:
                raise er.error("events", "unplug needs at least one event {cell, at_s, for_s}")
            merged["events"] = events
        out[name] = merged
    return out


def parse_scene(data: Any, source: str = "<dict>", *, seed: int | None = None) -> Scene:
    """Validate a scene given as parsed YAML and resolve its explorations; see :func:`load_scene`."""
    root = _reader(data, "", source)
    sr = _reader(root.get("scene"), "scene", source)
    name = sr.get("name", kind=str)
    description = sr.get("description", "", str)
    robot_name = sr.get("robot", kind=str)
    try:
        robot = _robot(robot_name)
    except ConfigError as exc:
        raise SceneError(str(exc), key="scene.robot", source=source) from None
    scene_seed = int(sr.get("seed", 0, int))
    if seed is not None:
        scene_seed = int(seed)
    start_ns = int(round(sr.number("start_s", 0.0, minimum=0.0) * 1e9))
    lead_in_s = sr.number("lead_in_s", 1.0, minimum=0.0)
    sr.check_unknown()

    effects = _parse_effects(root, robot)
    if "contact_patch" in effects and robot.geometry is None:
        raise SceneError(f"contact_patch presses at places on the cells: robot {robot.name!r} has no geometry "
                         "section", key="effects.contact_patch", source=source)
    if "bad_parity" in effects and not any(sensor_kind(robot, p.cell_type) == "biotac" for p in robot.body_parts):
        raise SceneError("bad_parity applies to BioTac SPI words; this robot has none (use corrupt_frames)",
                         key="effects.bad_parity", source=source)

    sensors = root.get("sensors", {}, dict)
    for ct, params in sensors.items():
        if ct not in robot.cell_types:
            raise SceneError(f"unknown cell type (known: {', '.join(robot.cell_types)})", key=f"sensors.{ct}", source=source)
        _validate_sensor(params, f"sensors.{ct}", source, sensor_kind(robot, ct))

    defaults = root.get("defaults", {}, dict)
    dr = _reader(defaults, "defaults", source)
    for k in defaults:
        if k not in _DEFAULT_KEYS:
            raise dr.error(k, f"unknown key (known here: {', '.join(sorted(_DEFAULT_KEYS))})")

    raw = root.get("explorations", kind=list)
    if not raw:
        raise root.error("explorations", "a scene needs at least one exploration")
    root.check_unknown()

    rng = random.Random(f"tactile-scene/{scene_seed}")  # fast scalar draws, stable across versions
    explorations: list[Exploration] = []
    for i, entry in enumerate(raw):
        key = f"explorations[{i}]"
        er = _reader(entry, key, source)
        for k in entry:
            if k not in _EXPLORATION_KEYS:
                raise er.error(k, f"unknown key (known here: {', '.join(sorted(_EXPLORATION_KEYS))})")
        materials = _materials_of(entry, key, source)
        repeat = entry.get("repeat", 1)
        if isinstance(repeat, bool) or not isinstance(repeat, int) or repeat < 1:
            raise SceneError(f"expected a positive integer, got {repeat!r}", key=f"{key}.repeat", source=source)
        order = entry.get("order", "round_robin")
        if order not in ("round_robin", "shuffled", "blocked"):
            raise SceneError("order is round_robin, shuffled or blocked", key=f"{key}.order", source=source)
        if "label" in entry and len(materials) > 1:
            raise SceneError("label is only allowed with a single material (labels default to material names)",
                             key=f"{key}.label", source=source)
        if order == "blocked":
            sequence = [m for m in materials for _ in range(repeat)]
        else:
            sequence = []
            for _ in range(repeat):
                batch = list(materials)
                if order == "shuffled":
                    rng.shuffle(batch)
                sequence += batch
        params = {**defaults, **{k: v for k, v in entry.items() if k in _DEFAULT_KEYS}}
        for mat in sequence:
            explorations.append(_resolve(len(explorations), mat, entry.get("label"), params, key, source, robot, rng))
    return Scene(name, description, robot, scene_seed, start_ns, lead_in_s, effects, sensors, tuple(explorations), source)


def _robot(name: str) -> RobotDescription:
    """Robot descriptions are read once per file version (PyYAML is slow on the 116-cell NAO)."""
    path = robot_config_path(name)
    return _robot_cached(str(path.resolve()), path.stat().st_mtime_ns)


@lru_cache(maxsize=16)
def _robot_cached(path: str, mtime_ns: int) -> RobotDescription:
    return load_robot(path)


def _materials_of(entry: Mapping[str, Any], key: str, source: str) -> list[str]:
    if ("material" in entry) == ("materials" in entry):
        raise SceneError("give exactly one of material or materials", key=f"{key}.material", source=source)
    if "material" in entry:
        m = entry["material"]
        if not isinstance(m, str) or not m:
            raise SceneError(f"expected a material name, got {m!r}", key=f"{key}.material", source=source)
        return [m]
    ms = entry["materials"]
    if isinstance(ms, Mapping):
        r = _reader(ms, f"{key}.materials", source)
        out: list[str] = []
        fitted = r.get("fitted", [], (str, list))
        if fitted == "all":
            from .textures import material_library

            out += sorted(material_library())
        elif isinstance(fitted, list):
            out += [str(m) for m in fitted]
        else:
            raise r.error("fitted", f"expected 'all' or a list of material names, got {fitted!r}")
        n = r.get("parametric", 0, int)
        prefix = r.get("prefix", "material", str)
        r.check_unknown()
        if n < 0:
            raise r.error("parametric", f"must be at least 0, got {n}")
        out += [f"param:{prefix}_{j:03d}" for j in range(1, n + 1)]
        if not out:
            raise r.error("parametric", "no materials: give fitted and/or parametric")
        return out
    if not isinstance(ms, list) or not ms or not all(isinstance(m, str) and m for m in ms):
        raise SceneError("expected a list of material names or {parametric: N, prefix: ...}", key=f"{key}.materials",
                         source=source)
    return list(ms)


def sensor_kind(robot: RobotDescription, cell_type: str) -> str:
    """Which simulated sensor a cell type is: ``"biotac"``, ``"skin"`` or ``"unsupported"``."""
    ct = robot.cell_types[cell_type]
    if ct.vibration.channels == ("pac",):
        return "biotac"
    if len(ct.vibration.axes) == 3 and len(ct.force.channels) == 3:
        return "skin"
    return "unsupported"


_SENSOR_KEYS = {
    "biotac": {"baseline_pac": 2048.0, "baseline_pdc": 2000.0, "baseline_electrode": 3000.0, "baseline_tac": 2000.0,
               "baseline_tdc": 2400.0, "baseline_spread_counts": 40.0},
    "skin": {"accel_gain": 0.25, "baseline_force": 20.0, "baseline_spread_counts": 4.0, "gravity_counts": 256.0,
             "temperature_rate_hz": 10.0, "temperature_c": 30.0},
}


def sensor_defaults(kind: str) -> dict[str, float]:
    """Default sensor parameters of a cell kind (``biotac`` or ``skin``)."""
    return dict(_SENSOR_KEYS[kind])


def _validate_sensor(params: Any, key: str, source: str, kind: str) -> None:
    r = _reader(params, key, source)
    if kind not in _SENSOR_KEYS:
        raise SceneError("the simulator renders BioTac and 3-axis skin cells only", key=key, source=source)
    for k, default in _SENSOR_KEYS[kind].items():
        r.number(k, default, minimum=0.0)
    r.check_unknown()


def _resolve(index: int, material: str, label: Any, params: Mapping[str, Any], key: str, source: str,
             robot: RobotDescription, rng: random.Random) -> Exploration:
    def num(name: str, default: Any, positive: bool = True) -> float:
        return _draw(params.get(name, default), f"{key}.{name}", source, rng, numeric=True, positive=positive)

    motion_spec = _draw(params.get("motion", "lateral"), f"{key}.motion", source, rng, numeric=False)
    motion = _parse_motion(motion_spec, f"{key}.motion", source)
    if len(motion) > 1 and motion[0] in ("rotating_stage", "in_hand", "large_object"):
        raise SceneError("this motion cannot be part of a sequence", key=f"{key}.motion", source=source)
    parts = _parse_parts(params.get("body_parts", "all"), f"{key}.body_parts", source, robot, rng)
    holding = ()
    if "holding_parts" in params:
        holding = _parse_parts(params["holding_parts"], f"{key}.holding_parts", source, robot, rng)
        if motion[0] != "in_hand":
            raise SceneError("holding_parts is only used with motion in_hand", key=f"{key}.holding_parts", source=source)
        overlap = set(holding) & set(parts)
        if overlap:
            raise SceneError(f"{sorted(overlap)[0]!r} cannot both hold and slide", key=f"{key}.holding_parts", source=source)
    weight = None
    force = num("force_n", 1.0)
    speed = num("speed_m_s", 0.02)
    duration = num("duration_s", 2.0)
    if motion[0] == "large_object":
        if "weight_g" not in params:
            raise SceneError("a large_object exploration needs weight_g", key=f"{key}.weight_g", source=source)
        weight = num("weight_g", None)
        slide = num("slide_m", 0.1)
        f_w, v_w, t_w = large_object_parameters(weight, slide)
        force = num("force_n", f_w) if "force_n" in params else f_w
        speed = num("speed_m_s", v_w) if "speed_m_s" in params else v_w
        duration = num("duration_s", t_w) if "duration_s" in params else slide / speed
    elif "weight_g" in params or "slide_m" in params:
        raise SceneError("weight_g and slide_m are only used with motion large_object", key=f"{key}.weight_g", source=source)
    if motion[0] == "rotating_stage":
        radius = num("stage_radius_m", 0.05)
        freq = num("stage_frequency_hz", 0.1011)
        speed = 2.0 * math.pi * radius * freq
    if label is not None and (not isinstance(label, str) or not label):
        raise SceneError(f"expected a label string, got {label!r}", key=f"{key}.label", source=source)
    lbl = label if label is not None else (material[6:] if material.startswith("param:") else material)
    part_force = {p: force for p in parts}
    if motion[0] == "large_object":
        # the chest only holds the object against the arms: the light contact of the paper
        part_force = {p: (max(0.2, 0.3 * force) if p == "chest" else force) for p in parts}
    hold_force = num("holding_force_n", 1.5) if holding else 0.0
    for p in holding:
        part_force[p] = hold_force
    group = params.get("group", "")
    if not isinstance(group, str):
        raise SceneError(f"expected a string, got {group!r}", key=f"{key}.group", source=source)
    return Exploration(
        index=index, label=lbl, material=material, motion=motion, body_parts=parts, holding_parts=holding,
        force_n=force, holding_force_n=hold_force, speed_m_s=speed, duration_s=duration,
        pause_s=num("pause_s", 1.0, positive=False), stroke_m=num("stroke_m", 0.04),
        circle_period_s=num("circle_period_s", 1.0), weight_g=weight, group=group, part_force_n=part_force,
    )


def restrict_robot(scene: Scene, body_parts: Sequence[str]) -> Scene:
    """The same scene on a robot reduced to ``body_parts`` (in the robot's order).

    The simulator keys every random draw by cell and exploration, so the kept
    cells' samples do not change (checked by the tests); the explorations
    must touch only kept body parts.
    """
    robot = scene.robot
    keep = tuple(p for p in robot.body_parts if p.name in set(body_parts))
    missing = sorted(set(body_parts) - {p.name for p in keep})
    if missing:
        raise ConfigError(f"unknown body parts {missing} of robot {robot.name!r}", key="body_parts")
    used = {b for e in scene.explorations for b in (*e.body_parts, *e.holding_parts)}
    lost = sorted(used - {p.name for p in keep})
    if lost:
        raise ConfigError(f"explorations touch body parts {lost} that would be removed", key="body_parts")
    small = replace(robot, body_parts=keep)
    return replace(scene, robot=small)
