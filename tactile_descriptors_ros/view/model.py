"""What ``tactile view`` shows, as JSON-ready data: the layout once, then a frame per display period (no ROS).

:class:`ViewModel` holds a robot's body parts with their sensing points laid
out flat (:func:`~..core.geometry.layout_2d`, the same layout as the
contact node's tactile images), and turns each body part's display frame
into the page's data: the force on every sensing point (``None`` when
stale), the contact, the centre of pressure on the flat layout (the same
force-weighted mean as the 3-D one), the vibration trace, and the
predictions with their confidence and labels (:class:`~..core.display.PredictionHistory`).

A robot without geometry (or a bag whose robot is unknown, such as an
imported recording) is laid out as a grid of its cells; :attr:`ViewModel.notice`
says so, and no centre of pressure is drawn.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..core.colormap import STALE_RGB, VIRIDIS_RGB
from ..core.display import DisplayFrame, PartDisplay, PredictionHistory
from ..core.geometry import Taxels, layout_2d
from ..core.robot import RobotDescription

__all__ = ["ViewPart", "ViewModel", "grid_taxels", "TRACE_S"]

#: Seconds of vibration trace kept per body part.
TRACE_S = 10.0
#: Spacing of the grid layout of a robot without geometry [m].
GRID_M = 0.02


def grid_taxels(part: str, cell_ids: Sequence[int], names: Sequence[str] | None = None) -> Taxels:
    """Sensing points of a body part without geometry: its cells on a square grid, facing +z."""
    n = len(cell_ids)
    cols = max(1, math.ceil(math.sqrt(n)))
    pos = np.array([[GRID_M * (k % cols), -GRID_M * (k // cols), 0.0] for k in range(n)], dtype=float).reshape(-1, 3)
    normals = np.tile([0.0, 0.0, 1.0], (n, 1))
    return Taxels(part, part, "cells", tuple(names or (f"{part}_{c}" for c in cell_ids)),
                  np.asarray(cell_ids, dtype=np.int64), tuple(() for _ in range(n)), pos, normals)


@dataclass
class ViewPart:
    """One body part of the view."""

    name: str
    taxels: Taxels
    layout: np.ndarray  # (n, 2) [m]
    cell_ids: np.ndarray
    vibration_unit: str = ""
    trace: deque = field(default_factory=lambda: deque(maxlen=int(TRACE_S * 50)))
    last: dict = field(default_factory=dict)

    def layout_dict(self) -> dict[str, Any]:
        xy = self.layout
        if len(xy) > 1:
            d = np.linalg.norm(xy[:, None, :] - xy[None, :, :], axis=2)
            d[np.diag_indices_from(d)] = np.inf
            radius = 0.45 * float(d.min())
        else:
            radius = 0.005
        radius = max(radius, 1e-4)
        return {"name": self.name, "frame_id": self.taxels.frame_id, "kind": self.taxels.kind,
                "vibration_unit": self.vibration_unit, "radius": radius,
                "taxels": [{"name": n, "cell_id": int(c), "x": float(p[0]), "y": float(p[1])}
                           for n, c, p in zip(self.taxels.names, self.taxels.cell_ids, xy)]}


class ViewModel:
    """The view of one robot (or of the cells a bag shows, laid out in a grid).

    Parameters
    ----------
    robot : RobotDescription or None
        With geometry, its body parts are laid out by it; without, in a grid.
    source : str
        ``"live"`` or the bag's path, shown on the page.
    parts : mapping of str to list of int, optional
        Body parts and cell ids when ``robot`` is None (from a bag's messages).
    force_max_n, stale_s, rate_hz : float, optional
        Default: the robot's ``view`` section (3 N, 0.5 s, 10 Hz without a robot).
    """

    def __init__(self, robot: RobotDescription | None, *, source: str = "live",
                 parts: Mapping[str, Sequence[int]] | None = None, force_max_n: float | None = None,
                 stale_s: float | None = None, rate_hz: float | None = None) -> None:
        self.robot = robot
        self.source = source
        view = robot.view if robot is not None else None
        self.force_max_n = float(force_max_n or (view.force_max_n if view else 3.0))
        self.stale_s = float(stale_s or (view.stale_s if view else 0.5))
        self.rate_hz = float(rate_hz or (view.rate_hz if view else 10.0))
        self.geometry = robot is not None and robot.geometry is not None
        self.parts: dict[str, ViewPart] = {}
        if robot is not None:
            for part in robot.body_parts:
                ct = robot.cell_types[part.cell_type]
                ids = [c.id for c in part.cells]
                taxels = robot.geometry.taxels(robot, part.name) if self.geometry else \
                    grid_taxels(part.name, ids, [c.name for c in part.cells])
                self._add(part.name, taxels, ids, ct.vibration.unit)
        for name, ids in (parts or {}).items():
            if name not in self.parts:
                self._add(name, grid_taxels(name, list(ids)), list(ids), "")
        if not self.geometry:
            why = f"robot {robot.name!r} has no geometry section" if robot is not None else \
                "the robot is not known (no robot description matches the bag)"
            self.notice: str | None = f"no geometry: {why}; the cells are laid out in a grid, without contact location"
        else:
            self.notice = None
        self.history = PredictionHistory()
        self.t_ns = -1
        self.frames = 0
        self.progress: dict[str, Any] | None = None

    def _add(self, name: str, taxels: Taxels, ids: Sequence[int], unit: str) -> None:
        self.parts[name] = ViewPart(name, taxels, layout_2d(taxels.positions, taxels.normals),
                                    np.asarray(ids, dtype=np.int64), unit)

    # --------------------------------------------------------------- inputs
    def part_display(self, name: str, n_deformation: int, threshold_n: float, floor_n: float = 0.05) -> PartDisplay:
        """A :class:`~..core.display.PartDisplay` of body part ``name`` (bag mode computes contacts itself)."""
        p = self.parts[name]
        return PartDisplay(p.taxels, p.cell_ids, n_deformation, threshold_n=threshold_n, floor_n=floor_n,
                           stale_s=self.stale_s)

    def update_part(self, name: str, *, taxel_force_n: np.ndarray, taxel_stale: np.ndarray, in_contact: bool,
                    force_n: float, active_cells: Sequence[int], vibration_rms: float, t_ns: int) -> None:
        """One body part's display frame."""
        p = self.parts.get(name)
        if p is None:
            return
        f = np.asarray(taxel_force_n, dtype=float)
        stale = np.asarray(taxel_stale, dtype=bool) | ~np.isfinite(f)
        w = np.where(stale, 0.0, np.maximum(f, 0.0))
        cop = None
        if self.geometry and in_contact and w.sum() > 0:
            cop = [float(v) for v in (w[:, None] * p.layout).sum(axis=0) / w.sum()]
        t_s = t_ns / 1e9 if t_ns >= 0 else None
        if t_s is not None and math.isfinite(vibration_rms):
            if p.trace and t_s < p.trace[-1][0]:
                p.trace.clear()  # time went back (a seek, a restarted bag)
            p.trace.append((t_s, float(vibration_rms)))
            while p.trace and p.trace[-1][0] - p.trace[0][0] > TRACE_S:
                p.trace.popleft()
        p.last = {"name": name, "in_contact": bool(in_contact), "force_n": float(force_n),
                  "force": [None if s else round(float(v), 4) for v, s in zip(f, stale)],
                  "active_cells": [int(c) for c in active_cells], "cop": cop,
                  "vibration_rms": float(vibration_rms) if math.isfinite(vibration_rms) else None}
        self.t_ns = max(self.t_ns, int(t_ns))

    def update_frame(self, name: str, frame: DisplayFrame) -> None:
        """One body part's :class:`~..core.display.DisplayFrame` (bag mode)."""
        c = frame.contact
        self.update_part(name, taxel_force_n=c.taxel_force_n, taxel_stale=frame.taxel_stale,
                         in_contact=c.in_contact, force_n=c.force_n, active_cells=c.active_cells,
                         vibration_rms=c.vibration_rms, t_ns=frame.end_ns if frame.end_ns >= 0 else self.t_ns)

    def update_contact_msg(self, c: Mapping[str, Any]) -> None:
        """One body part's ``Contact`` of a ``ContactArray`` (:func:`~..nodes.contact_msgs.contact_from_msg`)."""
        p = self.parts.get(c["body_part"])
        if p is None:
            return
        cell_force = np.asarray(c["cell_force_n"], dtype=float)
        index = {int(cid): k for k, cid in enumerate(c["cell_ids"])}
        owner = np.array([index.get(int(cid), -1) for cid in p.taxels.cell_ids])
        owner_force = np.where(owner >= 0, cell_force[np.maximum(owner, 0)] if cell_force.size else np.nan, np.nan)
        stale = ~np.isfinite(owner_force)
        if p.taxels.kind == "sites" and len(c["site_force_n"]) == len(p.taxels):
            force = np.asarray(c["site_force_n"], dtype=float)
        else:
            force = owner_force
        self.update_part(p.name, taxel_force_n=force, taxel_stale=stale, in_contact=c["in_contact"],
                         force_n=c["force_n"], active_cells=c["active_cell_ids"], vibration_rms=c["vibration_rms"],
                         t_ns=c["stamp_ns"])

    # -------------------------------------------------------------- outputs
    def config(self) -> dict[str, Any]:
        """The page's layout, colour map and scale (sent once per page)."""
        return {"robot": self.robot.name if self.robot is not None else "", "source": self.source,
                "geometry": self.geometry, "notice": self.notice, "force_max_n": self.force_max_n,
                "stale_s": self.stale_s, "rate_hz": self.rate_hz,
                "colormap": VIRIDIS_RGB.tobytes().hex(), "stale_rgb": list(STALE_RGB),
                "parts": [p.layout_dict() for p in self.parts.values()]}

    def frame(self) -> dict[str, Any]:
        """The current state of every body part and the predictions (one display period)."""
        self.frames += 1
        latest = self.history.latest
        return {"t": self.t_ns / 1e9 if self.t_ns >= 0 else None, "frame": self.frames,
                "parts": [dict(p.last, trace=[[round(t, 3), round(v, 6)] for t, v in p.trace]) if p.last else
                          {"name": p.name, "force": [None] * len(p.taxels), "in_contact": False, "force_n": 0.0,
                           "active_cells": [], "cop": None, "vibration_rms": None, "trace": []}
                          for p in self.parts.values()],
                "prediction": latest.to_dict() if latest is not None else None,
                "history": [e.to_dict() for e in self.history.recent(20)],
                "progress": self.progress}
