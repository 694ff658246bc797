"""A view-based retrieval descriptor in the spirit of CM-BOF (Lian et al. 2010).

Pipeline per shape: centre (area-weighted centroid), scale (RMS radius 1/2 of the view
box), PCA alignment; depth views from the vertices of a subdivided octahedron (level 2 =
66 views, as CM-BOF); OpenCV SIFT on each view (difference-of-Gaussian keypoints plus a
dense grid on the foreground, so small views still get features); bag of words over a
k-means codebook fitted on the descriptors of the shapes being compared; one L1-normalised
histogram per view.

Distance of two shapes: 1 - histogram intersection per pair of corresponding views,
averaged over views, minimised over the 24 rotations of the cube (which permute the
octahedron's views among themselves; PCA leaves axis order and sign ambiguous, and these
rotations cover it).

    cfg = DescriptorConfig(level=2, view_size=128, vocab=1000)
    D = distance_matrix_from_meshes([(verts, faces), ...], cfg)    # (n, n)
    D = distance_matrix_from_depths(depths, masks, cfg)            # back-projected depth images
    feats = mesh_features(meshes, cfg)                             # once; then per codebook seed:
    D = distance_matrix_from_features(feats, cfg, seed=3)
"""
from __future__ import annotations

import itertools
import multiprocessing as mp
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np
import torch

from lit3d.render.camera import OrthoCamera, look_at, render_ortho_depth
from lit3d.render.depth import depth_to_mesh
from lit3d.utils.progress import progress


@dataclass
class DescriptorConfig:
    level: int = 2               # octahedron subdivision: 0 -> 6 views, 1 -> 18, 2 -> 66
    view_size: int = 128         # pixels per view side
    vocab: int = 1000            # bag-of-words size (capped by the number of descriptors / 4)
    dense_step: int = 8          # dense SIFT grid step in pixels (0 = DoG keypoints only)
    kmeans_samples: int = 40000  # descriptors sampled to fit the codebook
    max_jump: float = 0.08       # back-projection: depth step that splits the surface
    rotations: bool = True       # minimise over the 24 cube rotations
    seed: int = 0
    workers: int = 0             # > 1: the view descriptors in that many spawned processes (the same features)


# ----------------------------------------------------------------------------------- geometry
def octahedron_views(level: int = 2) -> np.ndarray:
    """Unit view directions: vertices of the octahedron subdivided ``level`` times ``(V, 3)``.

    Level 0: 6, level 1: 18, level 2: 66 (the 66 CM-BOF views)."""
    verts = [np.array(v, float) for v in ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1))]
    faces = [(0, 2, 4), (2, 1, 4), (1, 3, 4), (3, 0, 4), (2, 0, 5), (1, 2, 5), (3, 1, 5), (0, 3, 5)]
    for _ in range(level):
        cache: dict[tuple[int, int], int] = {}

        def mid(i, j):
            key = (min(i, j), max(i, j))
            if key not in cache:
                m = verts[i] + verts[j]
                verts.append(m / np.linalg.norm(m))
                cache[key] = len(verts) - 1
            return cache[key]

        new = []
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new
    return np.array(verts)


def cube_rotations() -> np.ndarray:
    """The 24 proper rotations of the cube as ``(24, 3, 3)`` signed permutation matrices."""
    out = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1, -1), repeat=3):
            R = np.zeros((3, 3))
            for i, (p, s) in enumerate(zip(perm, signs)):
                R[i, p] = s
            if np.linalg.det(R) > 0:
                out.append(R)
    return np.array(out)


def view_permutations(dirs: np.ndarray) -> np.ndarray:
    """``(24, V)``: for rotation r, view i of a rotated shape is view ``perm[r, i]`` of the original."""
    perms = []
    for R in cube_rotations():
        rd = dirs @ R  # R^T applied to each direction
        perms.append(np.argmax(rd @ dirs.T, axis=1))
    return np.array(perms)


def normalize_pose(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Centre (area-weighted), scale (RMS radius 0.5), PCA-align the principal axes to x, y, z."""
    tri = verts[faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    cent = tri.mean(1)
    w = area / max(area.sum(), 1e-12) if area.sum() > 0 else np.full(len(cent), 1 / max(len(cent), 1))
    c = (w[:, None] * cent).sum(0)
    v = verts - c
    p = cent - c
    cov = (w[:, None, None] * p[:, :, None] * p[:, None, :]).sum(0)
    _, vecs = np.linalg.eigh(cov)
    vecs = vecs[:, ::-1]
    if np.linalg.det(vecs) < 0:
        vecs[:, 2] *= -1
    v = v @ vecs
    rms = np.sqrt((w * (np.linalg.norm(p, axis=1) ** 2)).sum())
    return v * (0.5 / max(rms, 1e-12))


VIEW_DISTANCE = 4.0
VIEW_CAMERA = OrthoCamera(half_width=1.6, znear=1.0, zfar=7.0)
Y_AXIS, X_AXIS = np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0])


def view_poses(dirs: np.ndarray, distance: float = VIEW_DISTANCE) -> np.ndarray:
    """``(V, 4, 4)`` camera-to-world poses at ``distance`` along each unit direction ``(V, 3)``,
    looking at the origin, up = +y (+x for views within 8 degrees of the y axis)."""
    return np.stack([look_at(d * distance, up=Y_AXIS, fallback_up=X_AXIS, parallel_cos=0.99) for d in dirs])


def render_views(verts: np.ndarray, faces: np.ndarray, dirs: np.ndarray, size: int) -> np.ndarray:
    """``(V, S, S) uint8`` depth views (near = bright, background 0) of a pose-normalised mesh."""
    dist, mag = VIEW_DISTANCE, VIEW_CAMERA.half_width
    z, fg = render_ortho_depth(verts, faces, view_poses(dirs, dist), size, VIEW_CAMERA, cull_faces=False)
    img = np.zeros(z.shape)
    img[fg] = np.clip(1 - (z[fg] - (dist - mag)) / (2 * mag), 0, 1) * 215 + 40
    return img.astype(np.uint8)


def sift_features(img: np.ndarray, dense_step: int = 8) -> np.ndarray:
    """``(n, 128) float32`` SIFT descriptors of one uint8 view (DoG keypoints + dense foreground grid)."""
    import cv2

    sift = cv2.SIFT_create()
    kps = list(sift.detect(img, None))
    if dense_step:
        s = img.shape[0]
        for yy in range(dense_step // 2, s, dense_step):
            for xx in range(dense_step // 2, s, dense_step):
                if img[yy, xx] > 0:
                    kps.append(cv2.KeyPoint(float(xx), float(yy), float(2 * dense_step)))
    if not kps:
        return np.zeros((0, 128), np.float32)
    _, desc = sift.compute(img, kps)
    return np.zeros((0, 128), np.float32) if desc is None else desc.astype(np.float32)


# ----------------------------------------------------------------------------------- bag of words
def fit_codebook(descs: list[np.ndarray], vocab: int, samples: int, seed: int) -> np.ndarray:
    """k-means centres ``(K, 128)`` from a sample of the pooled descriptors."""
    from sklearn.cluster import MiniBatchKMeans

    pool = np.concatenate([d for d in descs if len(d)]) if any(len(d) for d in descs) else np.zeros((0, 128))
    if len(pool) == 0:
        return np.zeros((1, 128), np.float32)
    rng = np.random.default_rng(seed)
    if len(pool) > samples:
        pool = pool[rng.choice(len(pool), samples, replace=False)]
    k = int(max(2, min(vocab, len(pool) // 4)))
    km = MiniBatchKMeans(n_clusters=k, random_state=seed, n_init=3, batch_size=2048).fit(pool)
    return km.cluster_centers_.astype(np.float32)


def bow_histogram(desc: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """L1-normalised word histogram ``(K,)`` (zeros when there are no descriptors)."""
    h = np.zeros(len(centres))
    if len(desc):
        d = torch.cdist(torch.from_numpy(desc), torch.from_numpy(centres))
        h = np.bincount(d.argmin(1).numpy(), minlength=len(centres)).astype(float)
        h /= h.sum()
    return h


def shape_distances(hists: list[np.ndarray], perms: np.ndarray | None, diagonal: bool = False) -> np.ndarray:
    """``(n, n)`` distances from per-shape ``(V, K)`` histograms: mean over views of
    1 - intersection, minimised over the view permutations ``perms`` ``(R, V)`` (None = identity).
    ``diagonal``: also each shape against itself (what an identical copy scores: not 0 where a view has
    no words); else the diagonal is 0. Each shape's views are put in every rotation's order once
    (``(R, V, K)``), so a pair compares the R x V matched views only, not all V x V. The rotations are a
    group (each one's inverse is among them), so one order of a pair gives both entries."""
    n = len(hists)
    H = torch.from_numpy(np.stack(hists)).float()  # (n, V, K)
    V = H.shape[1]
    perms_t = torch.from_numpy(perms if perms is not None else np.arange(V)[None]).long()
    D = np.zeros((n, n))
    for b in range(n):
        turned = H[b][perms_t]  # (R, V, K): view perms[r, v] of shape b, matched to view v of the other
        for a in range(b + 1 if diagonal else b):
            cost = 1 - torch.minimum(H[a][None], turned).sum(-1)  # (R, V)
            D[a, b] = D[b, a] = float(cost.mean(1).min())
    return D


# ----------------------------------------------------------------------------------- entry points
def view_features(verts: np.ndarray, faces: np.ndarray, cfg: DescriptorConfig, dirs: np.ndarray) -> list[np.ndarray]:
    """SIFT descriptors of each view of one shape (empty mesh -> no features)."""
    if len(faces) == 0:
        return [np.zeros((0, 128), np.float32) for _ in dirs]
    v = normalize_pose(verts, faces)
    views = render_views(v, faces, dirs, cfg.view_size)
    return [sift_features(img, cfg.dense_step) for img in views]


def _mesh_view_features(mesh: tuple[np.ndarray, np.ndarray], cfg: DescriptorConfig) -> list[np.ndarray]:
    """:func:`view_features` of one ``(verts, faces)`` from every view of ``cfg`` (a worker job)."""
    return view_features(mesh[0], mesh[1], cfg, octahedron_views(cfg.level))


def distinct(keys: list) -> tuple[np.ndarray, np.ndarray]:
    """``(first, inverse)`` of hashable ``keys``: the index of the first of each distinct key, in order of
    appearance, and for every key the position of its first in ``first``."""
    seen: dict = {}
    inverse = np.array([seen.setdefault(k, len(seen)) for k in keys], dtype=np.int64)
    return np.unique(inverse, return_index=True)[1].astype(np.int64), inverse  # labels are in order of appearance


def mesh_features(meshes: list[tuple[np.ndarray, np.ndarray]], cfg: DescriptorConfig) -> list[list[np.ndarray]]:
    """Per mesh, per view: the SIFT descriptors ``(n, 128) float32`` (the expensive part: rendering
    and SIFT; independent of the codebook seed), in ``cfg.workers`` spawned processes when > 1.
    Identical meshes (every pose of a subject shares one true canonical image) are described once and
    share one list, so :func:`distance_matrix_from_features` compares them once too."""
    first, inverse = distinct([np.asarray(v).tobytes() + np.asarray(f).tobytes() for v, f in meshes])
    unique = [meshes[i] for i in first]
    if cfg.workers <= 1 or len(unique) < 2:
        dirs = octahedron_views(cfg.level)
        feats = [view_features(v, f, cfg, dirs) for v, f in progress(unique, "view descriptors")]
    else:
        with ProcessPoolExecutor(int(cfg.workers), mp_context=mp.get_context("spawn")) as pool:
            jobs = pool.map(_mesh_view_features, unique, itertools.repeat(cfg),
                            chunksize=max(1, len(unique) // (8 * cfg.workers)))
            feats = list(progress(jobs, "view descriptors", total=len(unique)))
    return [feats[k] for k in inverse]


def distance_matrix_from_features(feats: list[list[np.ndarray]], cfg: DescriptorConfig, seed: int | None = None,
                                  return_hists: bool = False):
    """``(n, n)`` distances from :func:`mesh_features`: codebook (k-means seeded by ``seed``, default
    ``cfg.seed``), histograms, view-matched distances. Cheap next to the features, so a study over
    codebook seeds computes the features once. Entries that are one list (identical shapes, as
    :func:`mesh_features` gives them) get one histogram and are compared once (a copy's distance is the
    shape's distance to itself); the codebook still weighs each entry, so the distances are those of
    comparing every entry."""
    first, inverse = distinct([id(fs) for fs in feats])
    centres = fit_codebook([d for fs in feats for d in fs], cfg.vocab, cfg.kmeans_samples,
                           cfg.seed if seed is None else int(seed))
    hists = [np.stack([bow_histogram(d, centres) for d in feats[i]]) for i in first]
    D = shape_distances(hists, view_permutations(octahedron_views(cfg.level)) if cfg.rotations else None,
                        diagonal=len(first) < len(feats))[np.ix_(inverse, inverse)]
    np.fill_diagonal(D, 0.0)
    return (D, [hists[k] for k in inverse]) if return_hists else D


def distance_matrix_from_meshes(meshes: list[tuple[np.ndarray, np.ndarray]], cfg: DescriptorConfig | None = None,
                                return_hists: bool = False):
    """``(n, n)`` descriptor distances of meshes ``[(verts, faces), ...]``."""
    cfg = cfg or DescriptorConfig()
    return distance_matrix_from_features(mesh_features(meshes, cfg), cfg, return_hists=return_hists)


def depth_meshes(depths: np.ndarray, masks: np.ndarray,
                 cfg: DescriptorConfig | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each ``(S, S)`` normalised depth + mask back-projected to a surface ``(verts, faces)``."""
    cfg = cfg or DescriptorConfig()
    return [depth_to_mesh(np.asarray(d, np.float64), np.asarray(m), cfg.max_jump) for d, m in zip(depths, masks)]


def distance_matrix_from_depths(depths: np.ndarray, masks: np.ndarray, cfg: DescriptorConfig | None = None) -> np.ndarray:
    """Back-project each ``(S, S)`` normalised depth + mask to a surface, then as above (identical images are
    described and compared once)."""
    cfg = cfg or DescriptorConfig()
    return distance_matrix_from_meshes(depth_meshes(depths, masks, cfg), cfg)
