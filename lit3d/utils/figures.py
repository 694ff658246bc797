"""Labelled picture grids (Pillow): a title, column headers, a label per row, cells of equal size.

Used by the completion figures and the canonical contact sheets; cells are ``(cell, cell, 3)
uint8`` images (shaded renders, depth maps), at least 256 px for readability.
"""
from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw, ImageFont


def font(size: int = 15):
    """Pillow's default font at ``size`` px (a fixed small bitmap font on Pillow < 10.1)."""
    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1
        return ImageFont.load_default()


def labelled_grid(rows: list[dict], columns: list[str], title: str, cell: int = 256, left: int = 210,
                  header: int = 44) -> Image.Image:
    """Lay out labelled cells on white.

    Args:
        rows: ``{"label": str (may hold newlines), "cells": [(cell, cell, 3) uint8 per column]}``.
        columns: column headers.
        title: text above the headers.
        cell: cell side in pixels.
        left: width of the row-label margin; header: height of the title and of the header band.
    """
    ncol = len(columns)
    w, h = left + ncol * cell, 2 * header + len(rows) * cell
    img = Image.new("RGB", (w, h), "white")
    draw = ImageDraw.Draw(img)
    draw.text((8, 8), title, fill="black", font=font(22))
    head = font(20)
    for c, name in enumerate(columns):
        draw.text((left + c * cell + cell // 2, header + header // 2), name, fill="black", font=head, anchor="mm")
    small = font(17)
    for r, row in enumerate(rows):
        y = 2 * header + r * cell
        for c, tile in enumerate(row["cells"]):
            img.paste(Image.fromarray(np.asarray(tile, np.uint8)), (left + c * cell, y))
        draw.multiline_text((8, y + cell // 2), row["label"], fill="black", font=small, anchor="lm", spacing=6)
        draw.line([(0, y), (w, y)], fill=(200, 200, 200), width=1)
    for c in range(1, ncol):
        x = left + c * cell
        draw.line([(x, header), (x, h)], fill=(200, 200, 200), width=1)
    return img
