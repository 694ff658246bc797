"""The completion data's item spec and plan: which items a cache holds and how one item is made.

Shared by the DataModule (:mod:`datamodules.completion.datamodule`) and the sources that prepare
items (:mod:`datamodules.completion.sources`, :mod:`datamodules.completion.meshes`), which import
it and nothing of each other.

- :class:`ItemSpec`: every setting that decides the planned items and their bytes (sizes,
  categories, seed, views, grid sizes, sensor, compression).
- :func:`synth_items`: the plan (cheap: names, splits, views; no geometry), deterministic in the seed.
- :func:`synth_pair` / :func:`view_pair`: one planned item -> ``(input, target)`` bool grids, from a
  procedural shape or any shape (a real mesh).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from datamodules.cache import DataError, stable_seed
from datamodules.completion.depth_voxels import VIEW_SETS, make_sample, view_index
from datamodules.completion.furniture import make_shape
from datamodules.completion.voxel_cache import DATA_SPLITS
from lit3d.sensing.sensor import Sensor

DEFAULT_SIZES = {"train": 240, "val": 40, "test_same": 40, "test_cross": 40, "test_unseen": 40}


class DataConfigError(DataError):
    """A data setting that cannot work (e.g. source=recgan without root)."""


def check_sizes(sizes: dict | None) -> dict:
    """``data.sizes`` as ``{split: int >= 0}``; an unknown split (``+data.sizes.trian=10``) or a
    count that is not a whole number >= 0 raises :class:`DataConfigError` listing the known splits,
    before any cache is touched (an unknown key would otherwise be dropped and change the cache hash)."""
    out = {}
    for k, v in dict(sizes or {}).items():
        if k not in DATA_SPLITS:
            raise DataConfigError(f"data.sizes.{k}: unknown split; known: {', '.join(DATA_SPLITS)}")
        n = 0 if v is None else v
        if isinstance(n, bool) or not isinstance(n, (int, float)) or n < 0 or n != int(n):
            raise DataConfigError(f"data.sizes.{k}={v!r}: expected a whole number of items >= 0")
        out[k] = int(n)
    return out


@dataclass(frozen=True)
class ItemSpec:
    """What decides the planned items of a synthetic or mesh source and the bytes of each.

    ``sizes``: items per split; ``categories`` / ``unseen_categories``: the seen and unseen
    categories; ``seed``: shapes, views and sensor noise; ``views_per_shape``, ``unseen_view_set``:
    the views (see :func:`synth_items`); ``target_res`` R, ``input_factor`` (input R / f),
    ``render_factor`` (depth image pixels per voxel), ``sensor``: the 2.5D input
    (:mod:`lit3d.sensing.sensor`); ``compress``: zlib-compress the packed bits.
    """

    sizes: Mapping[str, int]
    categories: tuple[str, ...]
    unseen_categories: tuple[str, ...]
    seed: int
    views_per_shape: int
    unseen_view_set: str
    target_res: int
    input_factor: int
    render_factor: int
    sensor: Sensor
    compress: bool

    def items(self) -> list[dict]:
        """The plan of every item (:func:`synth_items`)."""
        return synth_items(self.sizes, self.categories, self.unseen_categories, self.seed, self.views_per_shape,
                           self.unseen_view_set)


def synth_items(sizes: Mapping[str, int], categories: Sequence[str], unseen_categories: Sequence[str], seed: int,
                views_per_shape: int = 4, unseen_view_set: str = "same") -> list[dict]:
    """The plan of every synthetic item (cheap: no geometry), deterministic in ``seed``.

    Items cycle over the categories (balanced counts); the j-th item of a category
    shows shape ``j // views_per_shape`` of that category. Shape instances come from groups: train, val, test (shared by test_same
    and test_cross, as in 3D-RecGAN++ whose test_125/test_216 hold the same ids) and
    unseen. Views of one shape are distinct and drawn from the split's view set.
    """
    items = []
    for split in DATA_SPLITS:
        n = int(sizes.get(split, 0) or 0)
        cats = list(unseen_categories) if split.startswith("test_unseen") else list(categories)
        if n <= 0 or not cats:
            continue
        group = {"test_same": "test", "test_cross": "test", "test_unseen": "unseen",
                 "test_unseen_cross": "unseen"}.get(split, split)
        view_set = {"test_cross": "cross", "test_unseen": unseen_view_set, "test_unseen_cross": "cross"}.get(split, "same")
        views = VIEW_SETS[view_set]
        for i in range(n):
            category = cats[i % len(cats)]
            j = i // len(cats)  # item number within the category
            shape_index = j // views_per_shape
            vrng = np.random.default_rng(stable_seed(seed, "views", split, category, shape_index))
            chosen = vrng.choice(len(views), size=min(views_per_shape, len(views)), replace=False)
            v = int(chosen[j % len(chosen)])
            a, b, c = view_index(view_set, v)
            name = f"{category}_{group}{shape_index:04d}_{a}_{b}_{c}"
            items.append({
                "name": name, "split": split, "category": category, "view_set": view_set,
                "shape_group": group, "shape_index": shape_index, "view": [float(x) for x in views[v]],
                "file": f"items/{split}/{name}.npz",
            })
    return items


def synth_pair(item: dict, seed: int, target_res: int, input_factor: int, render_factor: int = 2,
               sensor: str | dict | Sensor | None = None):
    """Generate one planned synthetic item -> (input, target) bool grids.

    ``sensor``: :mod:`lit3d.sensing.sensor` (name or fields; None = orthographic, noise-free);
    its noise is drawn from a generator seeded by ``seed`` and the item's name.
    """
    rng = np.random.default_rng(stable_seed(seed, "shape", item["shape_group"], item["category"], item["shape_index"]))
    return view_pair(make_shape(item["category"], rng), item, seed, target_res, input_factor, render_factor, sensor)


def view_pair(shape, item: dict, seed: int, target_res: int, input_factor: int, render_factor: int = 2,
              sensor: str | dict | Sensor | None = None):
    """One planned item's view of ``shape`` (procedural or a real mesh) -> (input, target) bool grids;
    the sensor noise is drawn from a generator seeded by ``seed`` and the item's split and name."""
    noise = np.random.default_rng(stable_seed(seed, "sensor", item["split"], item["name"]))
    out = make_sample(shape, tuple(item["view"]), target_res=target_res, input_factor=input_factor,
                      render_factor=render_factor, sensor=sensor, rng=noise)
    return out["input"], out["target"]
