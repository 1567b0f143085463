"""A "tactile image" of a body part: its sensing points as discs on their flat layout (pure numpy).

The layout (:func:`~.geometry.layout_2d`) is scaled into a square image with
one uniform scale (no distortion), each sensing point a disc of 45 % of the
smallest distance between two of them (so discs never touch).
:func:`image_layout` does the geometry once per body part: a label image
that says which point each pixel shows; :func:`render` then colours a frame
with one lookup, cheap enough for every display period.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["ImageLayout", "image_layout", "render", "BACKGROUND_RGB"]

#: Pixels outside every disc.
BACKGROUND_RGB: tuple[int, int, int] = (255, 255, 255)


@dataclass(frozen=True)
class ImageLayout:
    """Which sensing point each pixel of a body part's image shows.

    Attributes
    ----------
    label : numpy.ndarray of int32, shape (height, width)
        Index of the sensing point, -1 for the background.
    centres_px : numpy.ndarray, shape (n, 2)
        Disc centres as (column, row) [pixels], row 0 at the top.
    radius_px : float
    """

    label: np.ndarray
    centres_px: np.ndarray
    radius_px: float

    @property
    def height(self) -> int:
        return int(self.label.shape[0])

    @property
    def width(self) -> int:
        return int(self.label.shape[1])


def image_layout(points_2d: np.ndarray, size_px: int = 96, margin_px: int = 2) -> ImageLayout:
    """Lay sensing points (a flat layout [m], shape (n, 2), x right, y up) into a square image.

    Parameters
    ----------
    points_2d : numpy.ndarray, shape (n, 2)
    size_px : int
        Width and height of the image.
    margin_px : int
        Blank border.

    Returns
    -------
    ImageLayout

    Raises
    ------
    ValueError
        For no points, or an image too small to hold a disc per point.
    """
    pts = np.asarray(points_2d, dtype=float).reshape(-1, 2)
    n = len(pts)
    if n == 0:
        raise ValueError("a tactile image needs at least one sensing point")
    if size_px < 8 or 2 * margin_px >= size_px:
        raise ValueError(f"image of {size_px} px with a margin of {margin_px} px is too small")
    inner = size_px - 2 * margin_px
    span = np.ptp(pts, axis=0) if n > 1 else np.zeros(2)
    if n > 1:
        d, _ = cKDTree(pts).query(pts, k=2)
        nearest = float(d[:, 1].min())
    else:
        nearest = 0.0
    if n == 1 or span.max() <= 0:
        scale, radius = 1.0, 0.4 * inner
    else:
        # discs of 0.45 * nearest (in metres) must fit: extent + 2 * radius <= inner
        scale = inner / (span.max() + 0.9 * nearest)
        radius = 0.45 * nearest * scale
    if radius < 1.0:
        raise ValueError(f"{n} sensing points do not fit a {size_px} px image (discs of {radius:.2f} px)")
    centre = (pts.min(axis=0) + pts.max(axis=0)) / 2.0
    cols = (size_px - 1) / 2.0 + (pts[:, 0] - centre[0]) * scale
    rows = (size_px - 1) / 2.0 - (pts[:, 1] - centre[1]) * scale
    centres = np.stack([cols, rows], axis=1)
    yy, xx = np.mgrid[0:size_px, 0:size_px]
    dist, idx = cKDTree(centres).query(np.stack([xx.ravel(), yy.ravel()], axis=1))
    label = np.where(dist <= radius, idx, -1).astype(np.int32).reshape(size_px, size_px)
    return ImageLayout(label, centres, float(radius))


def render(layout: ImageLayout, rgb: np.ndarray, background: tuple[int, int, int] = BACKGROUND_RGB) -> np.ndarray:
    """The image of one frame: each disc in its point's colour, shape (height, width, 3), uint8.

    Parameters
    ----------
    layout : ImageLayout
    rgb : numpy.ndarray of uint8, shape (n, 3)
        One colour per sensing point (:func:`~.colormap.force_colours`).
    background : tuple of int
    """
    colours = np.asarray(rgb, dtype=np.uint8).reshape(-1, 3)
    if len(colours) != len(layout.centres_px):
        raise ValueError(f"{len(colours)} colours for {len(layout.centres_px)} sensing points")
    palette = np.vstack([colours, np.asarray(background, dtype=np.uint8)[None, :]])
    return palette[layout.label]  # -1 picks the background (the palette's last row)
