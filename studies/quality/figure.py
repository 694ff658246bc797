"""Scatter panels of scores against the opinion scores, one panel per score, stimuli coloured by distortion family
(the CPCD2 study's picture: ``python -m studies.quality.cpcd2_study --root DATA --fusion --figure PNG``)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from lit3d.quality.correlation import spearman
from lit3d.utils.curves import nice_ticks, tick_labels
from lit3d.utils.figures import font

PANEL = 420  # px a side
MARGIN = (70, 40, 20, 60)  # left, top, right, bottom inside a panel
FAMILY_COLOURS = {"G": (31, 119, 180), "V": (214, 39, 40), "N": (44, 160, 44)}


def scatter_figure(mos: np.ndarray, families: list[str], scores: dict[str, np.ndarray], names: dict[str, str],
                   title: str) -> Image.Image:
    """``mos (N,)`` against each ``scores[key] (N,)`` (higher = better), one ``PANEL`` px panel per score titled
    with its label ``names[key]`` and its SROCC; points coloured by family (legend in the title line)."""
    cols = 2 if len(scores) == 4 else min(3, len(scores))
    rows = -(-len(scores) // cols)
    img = Image.new("RGB", (cols * PANEL, 50 + rows * PANEL), "white")
    draw = ImageDraw.Draw(img)
    draw.text((10, 12), title, fill="black", font=font(18))
    x = img.width - 10
    for fam, colour in reversed(list(FAMILY_COLOURS.items())):
        label = {"G": "G-PCC", "V": "V-PCC", "N": "colour noise"}[fam]
        x -= int(draw.textlength(label, font=font(15))) + 30
        draw.ellipse([x, 18, x + 10, 28], fill=colour)
        draw.text((x + 14, 23), label, fill=colour, font=font(15), anchor="lm")
    fams = np.array(families)
    for i, (key, v) in enumerate(scores.items()):
        ox, oy = (i % cols) * PANEL, 50 + (i // cols) * PANEL
        left, top, right, bottom = MARGIN
        px0, px1, py0, py1 = ox + left, ox + PANEL - right, oy + top, oy + PANEL - bottom
        xt, yt = nice_ticks(float(v.min()), float(v.max())), nice_ticks(1.0, 5.0)
        sx = lambda t: px0 + (t - xt[0]) / (xt[-1] - xt[0]) * (px1 - px0)  # noqa: E731
        sy = lambda t: py1 - (t - yt[0]) / (yt[-1] - yt[0]) * (py1 - py0)  # noqa: E731
        for t, text in zip(xt, tick_labels(xt)):
            draw.line([(sx(t), py0), (sx(t), py1)], fill=(230, 230, 230))
            draw.text((sx(t), py1 + 5), text, fill="black", font=font(12), anchor="mt")
        for t, text in zip(yt, tick_labels(yt)):
            draw.line([(px0, sy(t)), (px1, sy(t))], fill=(230, 230, 230))
            draw.text((px0 - 6, sy(t)), text, fill="black", font=font(12), anchor="rm")
        draw.rectangle([px0, py0, px1, py1], outline="black")
        draw.text((ox + 10, oy + 8), f"{names[key]}: SROCC {spearman(v, mos):.3f}", fill="black", font=font(15))
        draw.text(((px0 + px1) / 2, py1 + 24), "score (higher = better)", fill="black", font=font(13), anchor="mt")
        draw.text((ox + 8, (py0 + py1) / 2), "MOS", fill="black", font=font(13), anchor="lm")
        for fam, colour in FAMILY_COLOURS.items():
            for s, m in zip(v[fams == fam], mos[fams == fam]):
                draw.ellipse([sx(s) - 4, sy(m) - 4, sx(s) + 4, sy(m) + 4], fill=colour)
    return img


def write_figure(path: str | Path, *args, **kwargs) -> Path:
    """:func:`scatter_figure` saved as PNG at ``path``."""
    path = Path(path)
    scatter_figure(*args, **kwargs).save(path)
    return path
