"""Drawing primitives of the dashboard's image panels (cv2, BGR uint8 images): canvas, text, metre axes, colour
scales, PNG encoding, and the :class:`Plot` that maps metres to pixels with one scale on both axes."""
from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["BACKGROUND", "UNKNOWN", "TEXT", "AXIS", "FONT", "FONT_SCALE", "PNG_PARAMS", "png", "canvas",
           "nice_ticks", "text", "axes", "colour_lut", "colourbar", "Plot"]

BACKGROUND = (24, 24, 28)
UNKNOWN = (90, 90, 90)
TEXT = (230, 230, 230)
AXIS = (150, 150, 150)
FONT = cv2.FONT_HERSHEY_SIMPLEX
FONT_SCALE = 0.42
#: PNG settings of the panels: fastest deflate and the SUB row filter. libpng's default adaptive filtering tries
#: every filter on every row and cost ~3x the time (5.2 against 1.7 ms for an 880 x 330 camera panel, same size)
PNG_PARAMS = (cv2.IMWRITE_PNG_COMPRESSION, 1, cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_SUB)


def png(bgr: np.ndarray) -> bytes:
    """PNG bytes of a BGR uint8 image."""
    ok, buf = cv2.imencode(".png", bgr, PNG_PARAMS)
    if not ok:
        raise ValueError(f"PNG encoding failed for shape {bgr.shape}")
    return buf.tobytes()


@functools.lru_cache(maxsize=8)
def _blank(h: int, w: int) -> np.ndarray:
    """A (h, w, 3) BACKGROUND image, kept: callers draw on a copy (40x cheaper than np.full with a colour)."""
    img = np.full((h, w, 3), BACKGROUND, np.uint8)
    img.setflags(write=False)
    return img


def canvas(h: int, w: int) -> np.ndarray:
    """A fresh (h, w, 3) BGR image filled with BACKGROUND."""
    return _blank(h, w).copy()


def nice_ticks(lo: float, hi: float, n: int = 5) -> np.ndarray:
    """About ``n`` round tick values (1, 2 or 5 x 10^k apart) within [lo, hi]."""
    span = max(hi - lo, 1e-9)
    raw = span / max(n, 1)
    mag = 10.0 ** np.floor(np.log10(raw))
    step = next(m * mag for m in (1, 2, 5, 10) if m * mag >= raw)
    first = np.ceil(lo / step - 1e-9) * step
    return np.arange(first, hi + step * 1e-6, step)


def text(img, s: str, org: tuple[float, float], scale: float = FONT_SCALE, colour=TEXT) -> None:
    """``s`` with its baseline's left end at ``org`` (x, y px)."""
    cv2.putText(img, s, (int(org[0]), int(org[1])), FONT, scale, colour, 1, cv2.LINE_AA)


def axes(img, box, u_lim, v_lim, xlabel: str, ylabel: str, u_reversed: bool = False,
         v_down: bool = False, ticks: tuple[int, int] = (5, 5)) -> None:
    """Frame ``box`` (x0, y0, x1, y1 px) with metre ticks (about ``ticks`` along u and v): u from u_lim[0] at the
    left to u_lim[1] at the right (reversed: at the right to the left), v from v_lim[0] at the bottom to v_lim[1]
    at the top (v_down: top to bottom); axis titles ``xlabel`` under it and ``ylabel`` above it."""
    x0, y0, x1, y1 = box
    cv2.rectangle(img, (x0, y0), (x1, y1), AXIS, 1)
    for t in nice_ticks(*u_lim, ticks[0]):
        f = (t - u_lim[0]) / (u_lim[1] - u_lim[0])
        x = round(x1 - f * (x1 - x0)) if u_reversed else round(x0 + f * (x1 - x0))
        cv2.line(img, (x, y1), (x, y1 + 4), AXIS, 1)
        text(img, f"{t + 0.0:g}", (x - 8, y1 + 17))
    for t in nice_ticks(*v_lim, ticks[1]):
        f = (t - v_lim[0]) / (v_lim[1] - v_lim[0])
        y = round(y0 + f * (y1 - y0)) if v_down else round(y1 - f * (y1 - y0))
        cv2.line(img, (x0 - 4, y), (x0, y), AXIS, 1)
        text(img, f"{t + 0.0:g}", (max(2, x0 - 38), y + 5))
    text(img, xlabel, ((x0 + x1) // 2 - 4 * len(xlabel), y1 + 34))
    if ylabel:
        text(img, ylabel, (4, y0 - 10))


@functools.lru_cache(maxsize=4)
def colour_lut(cmap: int, first: int = 0) -> np.ndarray:
    """(256, 3) uint8 BGR: OpenCV colour map ``cmap`` from its level ``first`` (row 0) to 255 (row 255) (a
    ``first`` above 0 leaves out the map's darkest end, which a dark background swallows). Read-only."""
    levels = np.linspace(first, 255, 256).round().astype(np.uint8).reshape(-1, 1)
    lut = cv2.applyColorMap(levels, cmap).reshape(256, 3)
    lut.setflags(write=False)
    return lut


def colourbar(img, box, lo: float, hi: float, lut: np.ndarray, title: str, ticks: int = 4) -> None:
    """Vertical colour scale ``lut`` (256, 3) BGR in ``box`` (x0, y0, x1, y1) from ``lo`` (bottom, row 0 of
    the table) to ``hi`` (top, row 255), about ``ticks`` ticks."""
    x0, y0, x1, y1 = box
    ramp = np.linspace(255, 0, y1 - y0).round().astype(np.intp)
    img[y0:y1, x0:x1] = lut[ramp][:, None, :]
    cv2.rectangle(img, (x0, y0), (x1 - 1, y1 - 1), AXIS, 1)
    for t in nice_ticks(lo, hi, ticks):
        y = round(y1 - (t - lo) / max(hi - lo, 1e-9) * (y1 - y0))
        cv2.line(img, (x1, y), (x1 + 4, y), AXIS, 1)
        text(img, f"{t + 0.0:g}", (x1 + 6, y + 5))
    text(img, title, (x0 - 6, y0 - 8))


@dataclass(frozen=True)
class Plot:
    """Metres to pixels in a plot box (x0, y0, x1, y1 px): u (m) to the right, v (m) up, ``scale`` px per m on
    both axes, the box's centre at (``u_mid``, ``v_mid``)."""

    box: tuple[int, int, int, int]
    scale: float
    u_mid: float
    v_mid: float

    @classmethod
    def fit(cls, box, u_lim, v_lim, scale: float | None = None) -> "Plot":
        """The plot of ``box`` that shows u_lim x v_lim (m) whole, centred, at one scale (the largest that fits,
        or ``scale`` px per m)."""
        x0, y0, x1, y1 = box
        if scale is None:
            scale = min((x1 - x0) / max(u_lim[1] - u_lim[0], 1e-6), (y1 - y0) / max(v_lim[1] - v_lim[0], 1e-6))
        return cls(tuple(box), float(scale), (u_lim[0] + u_lim[1]) / 2, (v_lim[0] + v_lim[1]) / 2)

    @property
    def u_lim(self) -> tuple[float, float]:
        half = (self.box[2] - self.box[0]) / 2 / self.scale
        return self.u_mid - half, self.u_mid + half

    @property
    def v_lim(self) -> tuple[float, float]:
        half = (self.box[3] - self.box[1]) / 2 / self.scale
        return self.v_mid - half, self.v_mid + half

    def col(self, u):
        """Pixel column(s) (float) of u (m)."""
        return (self.box[0] + self.box[2]) / 2 + (np.asarray(u) - self.u_mid) * self.scale

    def row(self, v):
        """Pixel row(s) (float) of v (m)."""
        return (self.box[1] + self.box[3]) / 2 - (np.asarray(v) - self.v_mid) * self.scale

    def pixel(self, u: float, v: float) -> tuple[int, int]:
        """(column, row) of the point (u, v) m, rounded."""
        return int(round(float(self.col(u)))), int(round(float(self.row(v))))
