"""Synthetic robots and windows: large skins, whole windows of signals, looped scenes.

What benchmarks and tests feed the descriptor path and the node graph when
no recording fits: a skin of any number of NAO skin cells
(:func:`skin_robot`), one window of every cell's signals, all in contact
(:func:`skin_window`, :func:`biotac_window`), and a robot description with
its node graph and one looped scene per bus (:func:`scale_robot_files`):
each skin driver plays a 2 s sliding touch over and over as real CAN frames
(``sim.loop``), so the drivers decode real wire frames at full rate without
simulating them live.
"""

from __future__ import annotations

import copy
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from scipy import signal

from ..core.aggregation import CellSignals
from ..core.robot import RobotDescription, load_robot, parse_robot, robot_config_path
from ..errors import ConfigError

__all__ = [
    "skin_robot",
    "skin_window",
    "biotac_window",
    "scale_robot_files",
    "split_cells",
    "part_name",
    "cell_samples_per_s",
    "LAP_S",
    "WINDOW_LENGTH_S",
    "WINDOW_HOP_S",
]

#: Seconds of the scene each driver plays over and over.
LAP_S = 2.0
#: Fixed windows of the measurement.
WINDOW_LENGTH_S = 2.0
WINDOW_HOP_S = 0.5


def skin_robot(n_cells: int, cells_per_part: int = 116) -> RobotDescription:
    """A robot of ``n_cells`` NAO skin cells (the ``skin_cell`` type of ``nao.yaml``).

    Cells are split into body parts of at most ``cells_per_part`` cells, with
    no geometry (a synthetic skin has no place on a robot); for ``n_cells ==
    116`` the shipped NAO description is returned unchanged.
    """
    if n_cells == 116:
        return load_robot("nao")
    with open(robot_config_path("nao"), encoding="utf-8") as fh:
        data = yaml.safe_load(fh)
    data["robot"]["name"] = f"skin_{n_cells}"
    data.pop("nodes", None)
    data.pop("geometry", None)
    parts = []
    for k, start in enumerate(range(0, n_cells, cells_per_part)):
        ids = range(start + 1, min(n_cells, start + cells_per_part) + 1)
        parts.append({"name": f"part_{k}", "cell_type": "skin_cell", "cells": [{"id": i} for i in ids]})
    data["body_parts"] = parts
    return parse_robot(data, source=f"<bench skin robot, {n_cells} cells>")


def skin_window(robot: RobotDescription, length_s: float = 2.0, *, seed: int = 0,
                dtype: type = np.int32) -> dict[int, CellSignals]:
    """One window of every cell of a skin robot, all in contact (synthetic).

    Accelerometer (1 kHz, 10-bit signed counts): gravity on z plus a texture
    vibration (AR(2) noise, std about 13 counts); force sensors (250 Hz,
    12-bit counts): a pressing profile around 0.5-2 N plus noise.  Like the
    windows the window node cuts (:class:`~..core.windowing.Windower`), only
    samples inside the window: 2,000 accelerometer and 500 force samples per
    cell at 2 s, the first force sample at the first accelerometer sample's
    stamp.  Counts are ``dtype`` (int32, as the window node delivers them).
    """
    rng = np.random.default_rng(seed)
    cell_type = next(iter(robot.cell_types.values()))
    fs_a = cell_type.vibration.rate_hz
    fs_f = cell_type.deformation.rate_hz
    n_a = int(round(length_s * fs_a))
    n_f = int(round(length_s * fs_f))
    t_a = np.arange(n_a, dtype=np.int64) * int(round(1e9 / fs_a))
    t_f = (np.arange(n_f + 1, dtype=np.int64) - 1) * int(round(1e9 / fs_f))
    n_per_count = float(cell_type.force.n_per_count) if cell_type.force else 0.002442
    ids = sorted(robot.cell_index())
    n_cells = len(ids)
    accel = np.empty((n_cells, 3, n_a), dtype=dtype)
    for c0 in range(0, n_cells, 256):  # blocks of cells keep the float scratch small
        c1 = min(n_cells, c0 + 256)
        vib = signal.lfilter([1.0], [1.0, -1.2, 0.5], rng.normal(0.0, 7.0, (c1 - c0, 3, n_a)), axis=-1)
        vib[:, 2] += 256.0  # gravity on z
        accel[c0:c1] = np.clip(np.rint(vib), -512, 511)
    press = rng.uniform(200, 800, (n_cells, 3, 1)) * (1 + 0.2 * np.sin(np.linspace(0, np.pi, n_f + 1)))
    force = np.clip(np.rint(press + rng.normal(0, 4.0, (n_cells, 3, n_f + 1))), 0, 4095).astype(dtype)
    out = {}
    # extra channels (proximity counts, temperature), one value per force sample
    prox = np.rint(rng.normal(1500, 20, (n_cells, n_f + 1)))
    temp = rng.uniform(28.0, 33.0, (n_cells, 1)) + np.zeros(n_f + 1)
    # the profile's first sample falls before the window: the window holds the n_f after it
    force, prox, temp, t_f = (np.ascontiguousarray(a[..., 1:]) for a in (force, prox, temp, t_f))
    for c, cid in enumerate(ids):
        force_n = force[c].mean(axis=0) * n_per_count
        extra = np.stack([prox[c], temp[c]])[:len(cell_type.extra_channels)]
        out[cid] = CellSignals(accel[c], t_a, force[c], t_f, force_n, extra=extra)
    return out


def biotac_window(robot: RobotDescription | None = None, length_s: float = 2.0, *, seed: int = 0,
                  dtype: type = np.int32) -> dict[int, CellSignals]:
    """One window of every BioTac of the Shadow Hand, all in contact (synthetic).

    Frames at 100 Hz carry 22 PAC samples (2.2 kHz, spread over the frame)
    and 19 electrodes; 12-bit counts.  PAC is a texture vibration around
    2000 counts, electrodes a slow deformation around 2500 counts.
    """
    robot = robot or load_robot("shadow_hand")
    rng = np.random.default_rng(seed)
    cell_type = next(iter(robot.cell_types.values()))
    frame_hz = cell_type.deformation.rate_hz
    per_frame = int(round(cell_type.vibration.rate_hz / frame_hz))
    n_frames = int(round(length_s * frame_hz))
    frame_t = np.arange(n_frames, dtype=np.int64) * int(round(1e9 / frame_hz))
    pac_t = (frame_t[:, None] + (np.arange(per_frame) * int(round(1e9 / frame_hz))) // per_frame).ravel()
    n_e = len(cell_type.deformation.channels)
    out = {}
    for cid in sorted(robot.cell_index()):
        white = rng.normal(0, 25.0, pac_t.size + 2)
        pac = np.convolve(white, [1.0, 0.8, 0.3], mode="valid")[: pac_t.size]
        electrodes = 2500 + rng.normal(0, 3, (n_e, n_frames)).cumsum(axis=1) + rng.normal(0, 2, (n_e, n_frames))
        extra = np.stack([rng.normal(20, 2, n_frames), rng.normal(2000, 3, n_frames),
                          rng.normal(1500, 3, n_frames)])[:len(cell_type.extra_channels)]  # PDC, TDC, TAC
        out[cid] = CellSignals(
            np.clip(np.rint(2000 + pac), 0, 4095).astype(dtype)[None, :], pac_t,
            np.clip(np.rint(electrodes), 0, 4095).astype(dtype), frame_t,
            np.full(n_frames, 1.0), extra=extra,
        )
    return out


# ----------------------------------------------------------------- scale robots


def split_cells(n_cells: int, parts: int) -> list[range]:
    """Cell ids ``1..n_cells`` in ``parts`` consecutive runs whose sizes differ by at most one.

    Raises
    ------
    ConfigError
        For fewer cells than body parts, or a count below 1.
    """
    if n_cells < 1 or parts < 1:
        raise ConfigError(f"need at least one cell and one body part, got {n_cells} cells, {parts} parts",
                          key="cells")
    if parts > n_cells:
        raise ConfigError(f"{parts} body parts need at least as many cells, got {n_cells}", key="parts")
    base, extra = divmod(n_cells, parts)
    out, start = [], 1
    for k in range(parts):
        size = base + (1 if k < extra else 0)
        out.append(range(start, start + size))
        start += size
    return out


def cell_samples_per_s() -> float:
    """Bus frames per second of one simulated skin cell: accelerometer, force, proximity, temperature."""
    from ..core.robot import load_robot
    from ..sim.scene import sensor_defaults

    ct = load_robot("nao").cell_types["skin_cell"]
    return ct.vibration.rate_hz + 2 * ct.deformation.rate_hz + sensor_defaults("skin")["temperature_rate_hz"]


def part_name(k: int, parts: int) -> str:
    """Name of body part ``k`` of ``parts`` (``part_07``: zero-padded so names sort in order)."""
    return f"part_{k:0{len(str(parts - 1))}d}"


def _scene(robot_path: Path, name: str, seed: int) -> dict[str, Any]:
    """A 2 s scene: one lateral slide over cork on every cell, loop-ready (whole periods, no bus faults)."""
    return {
        "scene": {"name": name, "description": "one sliding touch on every cell, played over and over",
                  "robot": str(robot_path), "seed": seed, "lead_in_s": 0.05,
                  "start_s": 1.0},  # bus time 0.0 means "no time stamp" on CAN
        "effects": {"normal_force": {"ramp_s": 0.1}, "texture_vibration": {}, "sensor_noise": {"std_counts": 1.0},
                    "adc": {}},
        "defaults": {"pause_s": 0.05},
        "explorations": [{"materials": ["cork"], "repeat": 1, "body_parts": "all", "motion": "lateral",
                          "force_n": 2.0, "speed_m_s": 0.02, "duration_s": LAP_S - 0.3}],
    }


def scale_robot_files(n_cells: int, parts: int, out_dir: str | os.PathLike[str], *,
                      groups: Sequence[str] = ("paper",), batch_s: float | None = None,
                      read_period_s: float | None = None, one_driver: bool = False,
                      window_parameters: dict[str, Any] | None = None, classifier: bool = False) -> Path:
    """Write the synthetic robot description (with its ``nodes:`` graph) and the drivers' scenes.

    Parameters
    ----------
    n_cells, parts : int
        Skin cells (ids 1..n_cells) and the body parts they are split into.
    out_dir : path
        Where ``scale_<n>.yaml``, each body part's scene and the scenes'
        one-part robot descriptions are written.
    groups : sequence of str
        Descriptor feature groups (default: the paper's 18 values per body part).
    batch_s : float, optional
        The drivers' ``batch_s`` (default: the NAO graph's).
    read_period_s : float, optional
        The drivers' ``read_period_s`` (default: the NAO graph's, else the driver's: 0, read as soon as frames
        are due).
    one_driver : bool
        One skin driver for all body parts (one bus) instead of one per body part.
    window_parameters : dict, optional
        Parameters of the window node merged over the NAO graph's (nested names).
    classifier : bool
        Add the NAO graph's classifier node (one for every body part's descriptors).

    Returns
    -------
    Path
        The robot description, ready for :func:`~..launching.graph.build_graph`
        with ``split_window_nodes=True`` (or ``tactile launch PATH
        --split-window-nodes``).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    with open(robot_config_path("nao"), encoding="utf-8") as fh:
        nao = yaml.safe_load(fh)
    name = f"scale_{n_cells}"
    runs = split_cells(n_cells, parts)
    body_parts = [{"name": part_name(k, parts), "cell_type": "skin_cell", "cells": [{"id": i} for i in ids]}
                  for k, ids in enumerate(runs)]
    base = {"robot": {"name": name, "description": f"{n_cells} skin cells in {parts} body parts (synthetic)"},
            "cell_types": nao["cell_types"], "contact": nao["contact"],
            "window": {"mode": "fixed", "length_s": WINDOW_LENGTH_S, "hop_s": WINDOW_HOP_S},
            "descriptor": {"layout": "pooled", "groups": list(groups)}}
    # Each scene names a robot of only the cells its driver's bus carries (same robot name, so the
    # driver accepts it): a driver simulates and decodes its own body parts, never the whole skin.
    buses = [[bp] for bp in body_parts] if not one_driver else [body_parts]
    # No tare at start: every lap is mostly touch, so the first samples are no baseline; the simulated
    # force baseline (20 counts, 0.05 N) is below the contact threshold untared.
    shipped = nao.get("nodes", {})
    shipped_driver = shipped.get("skin_driver", {}).get("parameters", {})
    if batch_s is None:
        batch_s = float(shipped_driver.get("batch_s", 0.05))
    if read_period_s is None:
        read_period_s = shipped_driver.get("read_period_s")
    driver_params = {"transport": "simulated", "batch_s": float(batch_s), "stamp_source": "device",
                     "tare_on_start_s": 0.0,
                     "sim": {"loop": True, "speed": 1.0}}
    nodes: dict[str, Any] = {}
    if read_period_s is not None:
        driver_params["read_period_s"] = float(read_period_s)
    for k, bus in enumerate(buses):
        bus_name = bus[0]["name"] if not one_driver else "all"
        sub = copy.deepcopy(base)
        sub["body_parts"] = bus
        sub_path = out / f"{name}_{bus_name}.robot.yaml"
        sub_path.write_text(yaml.safe_dump(sub, sort_keys=False))
        scene_path = out / f"{name}_{bus_name}.scene.yaml"
        scene_path.write_text(yaml.safe_dump(_scene(sub_path, f"{name}_{bus_name}", seed=k + 1), sort_keys=False))
        params = copy.deepcopy(driver_params)
        params["sim"]["scene"] = str(scene_path.resolve())
        node = "skin_driver" if one_driver else f"skin_driver_{bus_name}"
        nodes[node] = {"executable": "skin_driver", "body_parts": [bp["name"] for bp in bus], "parameters": params}
    # the window node as the NAO graph ships it (lateness, draining, queue depth), windows fixed by the robot
    window = copy.deepcopy(shipped.get("window_node", {}).get("parameters", {}) or {})
    for key, value in (window_parameters or {}).items():
        if isinstance(value, dict) and isinstance(window.get(key), dict):
            window[key] = {**window[key], **value}
        else:
            window[key] = value
    nodes["window_node"] = {"executable": "window_node", "parameters": window}
    if classifier:
        nodes["classifier_node"] = {"executable": "classifier_node",
                                    "parameters": copy.deepcopy(shipped.get("classifier_node", {}).get("parameters")
                                                                or {})}
    doc = {**base, "body_parts": body_parts, "nodes": nodes}
    path = out / f"{name}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path
