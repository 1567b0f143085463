"""``tactile view --snapshot out.png``: one frame of the view as a PNG (matplotlib, no browser).

The same data as the page (:meth:`~.model.ViewModel.config` and
:meth:`~.model.ViewModel.frame`): a panel per body part with its sensing
points on their flat layout, coloured by force on the robot's fixed scale
(grey when stale), the centre of pressure as a red ring, the body part's
force and vibration; the prediction and its confidence in the title and a
colour bar.  Needs matplotlib (the ``eval`` extra, ``pip install .[eval]``).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ..core.colormap import STALE_RGB, VIRIDIS_RGB
from ..errors import ConfigError

__all__ = ["write_snapshot"]


def write_snapshot(config: dict[str, Any], frame: dict[str, Any], path: str | Path, *, dpi: int = 100) -> Path:
    """Render ``frame`` (with ``config``'s layout) into the PNG ``path``; returns the path.

    Raises
    ------
    ConfigError
        When matplotlib is not installed, or the view has no body parts yet.
    """
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from matplotlib.colors import ListedColormap, Normalize
        from matplotlib.patches import Circle
    except ImportError:
        raise ConfigError("--snapshot draws with matplotlib: pip install .[eval]") from None
    parts = config.get("parts") or []
    if not parts:
        raise ConfigError("nothing to draw yet: no body parts (is the contact node running?)")
    n = len(parts)
    cols = min(n, 4)
    rows = math.ceil(n / cols)
    fig = plt.figure(figsize=(3.2 * cols + 1.2, 2.9 * rows + 1.0))
    scale = float(config["force_max_n"])
    lut = VIRIDIS_RGB / 255.0
    by_name = {p["name"]: p for p in frame.get("parts", [])}
    for k, part in enumerate(parts):
        ax = fig.add_subplot(rows, cols, k + 1)
        data = by_name.get(part["name"], {})
        forces = data.get("force") or [None] * len(part["taxels"])
        r = float(part["radius"])
        for t, f in zip(part["taxels"], forces):
            if f is None:
                rgb = np.asarray(STALE_RGB) / 255.0
            else:
                rgb = lut[int(np.clip(round(f / scale * 255), 0, 255))]
            ax.add_patch(Circle((t["x"], t["y"]), r, facecolor=rgb, edgecolor="none"))
        if data.get("cop") and config.get("geometry"):
            ax.add_patch(Circle(tuple(data["cop"]), 0.9 * r, facecolor="none", edgecolor="#d33", linewidth=2))
        xs = [t["x"] for t in part["taxels"]]
        ys = [t["y"] for t in part["taxels"]]
        ax.set_xlim(min(xs) - 1.5 * r, max(xs) + 1.5 * r)
        ax.set_ylim(min(ys) - 1.5 * r, max(ys) + 1.5 * r)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        touching = data.get("in_contact")
        for side in ax.spines.values():
            side.set_color("#d33" if touching else "#bbb")
            side.set_linewidth(2 if touching else 1)
        vib = data.get("vibration_rms")
        ax.set_title(f"{part['name']}  {data.get('force_n', 0.0):.2f} N"
                     + (f"\nvibration {vib:.3g} {part.get('vibration_unit', '')} rms" if vib is not None else ""),
                     fontsize=9)
    pred = frame.get("prediction")
    title = f"{config.get('robot') or 'tactile view'}  ({config.get('source')})"
    if frame.get("t") is not None:
        title += f"  t = {frame['t']:.2f} s"
    if pred and pred.get("has_model"):
        title += f"\nprediction: {pred['class_name']} ({100 * pred['confidence']:.0f} %)"
    if config.get("notice"):
        title += f"\n{config['notice']}"
    fig.suptitle(title, fontsize=10)
    cax = fig.add_axes([0.92, 0.15, 0.015, 0.6])
    fig.colorbar(matplotlib.cm.ScalarMappable(norm=Normalize(0.0, scale), cmap=ListedColormap(lut)), cax=cax,
                 label="force [N]")
    fig.subplots_adjust(left=0.03, right=0.9, top=0.82 if rows == 1 else 0.88, bottom=0.04, wspace=0.1, hspace=0.35)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path
