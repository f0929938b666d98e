"""Paint scenes with Pillow: PNG files, `rgb_array` frames and animated GIFs.

No anti-aliasing on purpose: every filled region keeps its exact style colour, which keeps
pictures small (GIF palettes) and lets tests check the colour at a cell's centre.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from cfteach.render.scene import Scene
from cfteach.render.shapes import Circle, Line, Polygon, Rect, Text, scene_shapes


def to_image(scene: Scene, cell_px: int = 48) -> Image.Image:
    """The scene as an RGB Pillow image of size `(width*cell_px+1, height*cell_px+1)`."""
    cv, shapes = scene_shapes(scene, cell_px)
    img = Image.new("RGB", cv.size, "#ffffff")
    draw = ImageDraw.Draw(img)
    for s in shapes:
        if isinstance(s, Rect):
            box = (s.x, s.y, s.x + s.w - 1, s.y + s.h - 1)
            draw.rectangle(box, fill=s.fill, outline=s.stroke, width=round(s.stroke_width))
        elif isinstance(s, Circle):
            box = (s.cx - s.r, s.cy - s.r, s.cx + s.r, s.cy + s.r)
            width = round(s.stroke_width) if s.stroke else 0
            draw.ellipse(box, fill=s.fill, outline=s.stroke, width=width)
        elif isinstance(s, Polygon):
            draw.polygon(list(s.points), fill=s.fill)
        elif isinstance(s, Line):
            draw.line(list(s.points), fill=s.stroke, width=max(1, round(s.width)), joint="curve")
        elif isinstance(s, Text):
            font = ImageFont.load_default(size=s.size)
            draw.text((s.x, s.y), s.text, fill=s.fill, font=font)
    return img


def to_rgb_array(scene: Scene, cell_px: int = 48) -> np.ndarray:
    """The scene as a `uint8` array `[height_px, width_px, 3]` (Gymnasium's `rgb_array`)."""
    return np.asarray(to_image(scene, cell_px), dtype=np.uint8)


def save_png(scene: Scene, path: str | Path, cell_px: int = 48) -> Path:
    """Write the scene as a PNG file and return its path."""
    path = Path(path)
    to_image(scene, cell_px).save(path, format="PNG", optimize=True)
    return path


def save_gif(
    frames: Sequence[Scene],
    path: str | Path,
    cell_px: int = 32,
    *,
    frame_ms: int = 450,
    hold_last_ms: int = 1500,
) -> Path:
    """Write an animated GIF, one frame per scene, looping forever, the last frame held."""
    if not frames:
        raise ValueError("an animation needs at least one frame")
    path = Path(path)
    images = [to_image(f, cell_px) for f in frames]
    # One shared adaptive palette keeps colours stable between frames.
    w, h = images[0].size
    montage = Image.new("RGB", (w, h * len(images)))
    for i, im in enumerate(images):
        montage.paste(im, (0, i * h))
    palette_src = montage.quantize(colors=64, method=Image.Quantize.MEDIANCUT)
    pal = [im.quantize(palette=palette_src, dither=Image.Dither.NONE) for im in images]
    durations = [frame_ms] * (len(pal) - 1) + [hold_last_ms]
    pal[0].save(
        path,
        format="GIF",
        save_all=True,
        append_images=pal[1:],
        duration=durations,
        loop=0,
        optimize=False,
        disposal=1,
    )
    return path
