"""Canonical forms: training step and inference per image, retrieval descriptor, pair generation.

Rows (CPU, one intra-op thread):
- the paper-size CanonicalNet (``experiment=canonical_paper``: LFE 32-64-128, MSFE grid 40,
  fuser 48,000 -> 500 -> 500, ...) at 128^2 (batch 4) and at the thesis's 500^2 (batch 2):
  one training step (forward, masked depth + mask loss, backward, Adam) through a real
  Lightning ``fit``, and inference (``no_grad`` forward), per image. Baseline in the same run:
  the plain U-Net of the thesis's comparison (``task.arch=unet``), same data, losses, batch;
- the CM-BOF-style retrieval descriptor per shape from one canonical depth image
  (back-projection, PCA pose, depth views, SIFT, bag-of-words histogram) at the demo (18
  views of 96^2) and paper (66 views of 128^2) settings; codebook fitting, done once per
  collection, is given in the note; the view-matched distance of one shape pair (baseline: comparing
  all V x V view pairs, the former way);
- synthetic posed/canonical pair generation (``CanonicalDataModule.prepare_data``) at demo
  (128^2, mesh resolution 56) and paper (500^2, mesh resolution 96) settings.
"""
from __future__ import annotations

import statistics
import tempfile
import time

import numpy as np
import torch

from benchmarks.bench_completion import _cfg
from benchmarks.common import median_time, num_threads, row, trainer_step_times
from lit3d.runtime.build import build_datamodule, build_task

CMD = "make bench"


def _batches(n: int, batch: int, size: int, seed: int = 0) -> list[dict]:
    """Depth-like batches: a smooth random field inside a disc (depth in [0.2, 1], 0 outside)."""
    g = torch.Generator().manual_seed(seed)
    yy, xx = torch.meshgrid(torch.linspace(-1, 1, size), torch.linspace(-1, 1, size), indexing="ij")
    disc = ((xx**2 + yy**2) < 0.5).float()[None, None]
    out = []
    for _ in range(n):
        low = torch.rand(batch, 1, 8, 8, generator=g)
        field = torch.nn.functional.interpolate(low, size=(size, size), mode="bilinear", align_corners=False)
        d = (0.2 + 0.8 * field) * disc
        out.append({"depth": d, "mask": disc.expand(batch, -1, -1, -1).clone(), "canon_depth": d.flip(-1),
                    "canon_mask": disc.expand(batch, -1, -1, -1).flip(-1).clone()})
    return out


def _net_times(size: int, batch: int, arch: str, steps: int, warmup: int) -> tuple[float, float, int]:
    """(train s/image, inference s/image, parameters) of the paper-size net at ``size``^2."""
    cfg = _cfg("canonical_paper", tempfile.mkdtemp(),
               [f"task.net.image_size={size}", f"data.image_size={size}", f"task.arch={arch}",
 "evaluation.retrieval=null"])
    task = build_task(cfg.task)
    params = sum(p.numel() for p in task.net.parameters())
    batches = _batches(steps + warmup, batch, size)
    train = statistics.median(trainer_step_times(task, batches, warmup=warmup)) / batch
    task.eval()
    b = batches[0]
    with torch.no_grad():
        infer = median_time(lambda: task(b["depth"], b["mask"]), repeats=3, warmup=1) / batch
    return train, infer, params


def _net_rows() -> list[dict]:
    rows = []
    for size, batch, steps in ((128, 4, 4), (500, 2, 3)):
        ours_t, ours_i, n_ours = _net_times(size, batch, "canonical", steps, 1)
        unet_t, unet_i, n_unet = _net_times(size, batch, "unet", steps, 1)
        common = f"paper-size nets; batch {batch}; CanonicalNet {n_ours / 1e6:.1f} M parameters, U-Net {n_unet / 1e6:.1f} M"
        rows.append(row(f"canonical train step per image, {size}^2, paper-size CanonicalNet, fp32, CPU", CMD, ours_t,
                        unet_t, unit="s/image", baseline_name="plain U-Net (task.arch=unet)", threads=1,
                        note=f"forward + masked depth/mask loss + backward + Adam in Lightning fit; {common}; "
                             f"{1 / ours_t:.2f} images/s"))
        rows.append(row(f"canonical inference per image, {size}^2, paper-size CanonicalNet, fp32, CPU", CMD, ours_i,
                        unet_i, unit="s/image", baseline_name="plain U-Net (task.arch=unet)", threads=1,
                        note=f"no_grad forward; {common}; {1 / ours_i:.1f} images/s"))
    return rows


def _canonical_depth(dm, size: int) -> tuple[np.ndarray, np.ndarray]:
    from lit3d.render.depth import render_depth

    subject = dm.source.subjects()[0]
    v, f = dm.normalized_mesh(subject, "canonical")
    return render_depth(v, f, size)


def _descriptor_row(depth: np.ndarray, mask: np.ndarray, level: int, view_size: int, vocab: int, label: str) -> dict:
    from lit3d.render.depth import depth_to_mesh
    from lit3d.retrieval.descriptor import (DescriptorConfig, bow_histogram, fit_codebook, octahedron_views,
                                            view_features)

    cfg = DescriptorConfig(level=level, view_size=view_size, vocab=vocab)
    dirs = octahedron_views(level)
    state = {}

    def per_shape():
        v, f = depth_to_mesh(np.asarray(depth, np.float64), np.asarray(mask), cfg.max_jump)
        state["feats"] = view_features(v, f, cfg, dirs)
        state["n_faces"] = len(f)
        if "centres" in state:
            np.stack([bow_histogram(d, state["centres"]) for d in state["feats"]])

    per_shape()
    # a codebook from 12 copies of this shape's descriptors stands in for a test collection
    t0 = time.perf_counter()
    state["centres"] = fit_codebook(state["feats"] * 12, cfg.vocab, cfg.kmeans_samples, cfg.seed)
    t_codebook = time.perf_counter() - t0
    t = median_time(per_shape, repeats=3, warmup=1)
    n_desc = sum(len(d) for d in state["feats"])
    return row(f"retrieval descriptor per shape, {label}: {len(dirs)} views of {view_size}^2, vocab {vocab}", CMD, t,
               None, unit="s/shape", threads=1,
               note=f"from a {depth.shape[0]}^2 canonical depth image: back-projection ({state['n_faces']} faces), PCA "
                    f"pose, {len(dirs)} depth views (EGL), SIFT ({n_desc} descriptors), word histogram; codebook fit "
                    f"(once per collection, 12 shapes' descriptors): {t_codebook:.2f} s; no baseline")


def _all_view_pairs(hists: list[np.ndarray], perms: np.ndarray) -> np.ndarray:
    """The baseline of the distance row: every shape pair compares all V x V view pairs, then picks the
    rotations' matches (lit3d's comparison before 2026-11-27)."""
    H = torch.from_numpy(np.stack(hists)).float()
    n, V = H.shape[:2]
    perms_t = torch.from_numpy(perms).long()
    D = np.zeros((n, n))
    for a in range(n):
        for b in range(a + 1, n):
            cost = 1 - torch.minimum(H[a][:, None, :], H[b][None, :, :]).sum(-1)  # (V, V)
            D[a, b] = D[b, a] = float(cost[torch.arange(V)[None, :], perms_t].mean(1).min())
    return D


def _distance_row(level: int, vocab: int, n_shapes: int = 30, words_per_view: int = 200) -> dict:
    from lit3d.retrieval.descriptor import octahedron_views, shape_distances, view_permutations

    perms = view_permutations(octahedron_views(level))
    rng = np.random.default_rng(0)
    hists = []
    for _ in range(n_shapes):
        counts = np.stack([np.bincount(rng.integers(0, vocab, words_per_view), minlength=vocab) for _ in perms[0]])
        hists.append(counts / words_per_view)
    ours, base = {}, {}
    t = median_time(lambda: ours.setdefault("D", shape_distances(hists, perms)), repeats=3, warmup=0)
    tb = median_time(lambda: base.setdefault("D", _all_view_pairs(hists, perms)), repeats=3, warmup=0)
    assert np.allclose(ours["D"], base["D"], atol=1e-6)
    pairs = n_shapes * (n_shapes - 1) // 2
    return row(f"retrieval distance per shape pair, demo settings: {perms.shape[1]} views, {len(perms)} rotations, "
               f"vocab {vocab}", CMD, t / pairs, tb / pairs, unit="s/pair", threads=1,
               baseline_name="all V x V view pairs, then the rotations' matches",
               note=f"shape_distances on {n_shapes} shapes' word histograms ({words_per_view} words a view, random); "
                    f"the same distances as the baseline (checked); 216 test items = {216 * 215 // 2} pairs")


def _gen(experiment: str, tmp: str, subjects: int, poses: int):
    cfg = _cfg(experiment, tmp, [f"data.source.n_subjects={subjects}", f"data.source.n_poses={poses}",
                                 "data.source.own_poses=0", "data.split.val_poses=training", "data.prepare_workers=0"])
    dm = build_datamodule(cfg.data)
    t0 = time.perf_counter()
    dm.prepare_data()
    dt = time.perf_counter() - t0
    pairs = subjects * poses * len(cfg.data.render.azimuths)
    return dm, cfg, row(f"synthetic canonical pair generation, {experiment.split('_')[1]} {cfg.data.image_size}^2, "
                        f"mesh resolution {cfg.data.source.mesh_resolution}", CMD, pairs / dt, None, unit="pairs/s",
                        threads=1, note=f"CanonicalDataModule.prepare_data: {subjects} subjects x {poses} poses "
                                        f"(+ 1 canonical render per subject), procedural figures, depth render "
                                        f"(EGL), compressed write; no baseline")


def run() -> list[dict]:
    rows = []
    with num_threads(1):
        rows += _net_rows()
        with tempfile.TemporaryDirectory() as tmp_demo, tempfile.TemporaryDirectory() as tmp_paper:
            dm_demo, cfg_demo, r_demo = _gen("canonical_demo", tmp_demo, 3, 3)
            dm_paper, cfg_paper, r_paper = _gen("canonical_paper", tmp_paper, 3, 2)
            rows += [r_demo, r_paper]
            d, m = _canonical_depth(dm_demo, int(cfg_demo.data.image_size))
            rc = cfg_demo.evaluation.retrieval
            rows.append(_descriptor_row(d, m, int(rc.level), int(rc.view_size), int(rc.vocab), "demo settings"))
            rows.append(_distance_row(int(rc.level), int(rc.vocab)))
            d, m = _canonical_depth(dm_paper, int(cfg_paper.data.image_size))
            rc = cfg_paper.evaluation.retrieval
            rows.append(_descriptor_row(d, m, int(rc.level), int(rc.view_size), int(rc.vocab), "paper settings"))
    return rows
