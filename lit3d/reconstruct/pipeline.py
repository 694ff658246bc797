"""One depth image -> completed occupancy -> mesh in the camera frame, with per-step timings.

    completer = load_completer("logs/demo/train/checkpoints/best-009.ckpt", device="cpu")
    result = reconstruct(depth, Intrinsics.from_fov(49.124, 320, 240), completer)
    result.mesh            # trimesh.Trimesh, camera frame (x right, y down, z forward), metres
    result.occupancy       # (R, R, R) bool, grid axes [x, y up, depth] (see grid.py)

Steps (each timed in ``result.timings``, seconds): ``segment`` (mask / depth range / plane),
``backproject``, ``grid`` (placement in the checkpoint's training geometry, partial grid, pooled
input), ``network`` (the completion generator), ``threshold`` (the validation-chosen IoU
threshold stored in the checkpoint), ``mesh`` (marching cubes on the probabilities at that
threshold, back to camera coordinates).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lit3d.reconstruct.backproject import Intrinsics, backproject
from lit3d.reconstruct.depth_io import InputError
from lit3d.reconstruct.grid import GridGeometry, Placement, fit_placement, voxelise_points
from lit3d.reconstruct.segment import depth_range_mask, largest_depth_cluster, remove_plane
from lit3d.render.convert import ShapeError, voxels_to_mesh
from lit3d.utils.checkpoints import META_KEY, load_checkpoint
from lit3d.zoo.slim import load_state


@dataclass
class Completer:
    """A loaded completion checkpoint: the LightningModule (eval mode), its threshold and geometry."""
    task: object
    threshold: float
    geometry: GridGeometry
    path: str
    device: str
    notes: list[str] = field(default_factory=list)

    def probabilities(self, partial: np.ndarray) -> np.ndarray:
        """``(r, r, r) bool`` partial grid -> ``(R, R, R) float32`` occupancy probabilities."""
        import torch

        x = torch.from_numpy(partial.astype(np.float32))[None, None].to(self.device)
        with torch.inference_mode():
            return self.task(x)[0, 0].float().cpu().numpy()


def task_name(meta: dict) -> str:
    """The task a checkpoint's lit3d metadata names (``completion``, ``canonical``, ``quality``, ...)."""
    task = meta.get("task") or {}
    return str(task.get("name") or task.get("_target_", "?").rsplit(".", 1)[-1])


def load_task(path: str | Path, device: str, want: str):
    """``(module, checkpoint dict)`` of a lit3d checkpoint of task ``want`` ("completion" or
    "canonical"), loaded with ``weights_only=True`` on ``device``, in eval mode."""
    import torch

    ckpt = load_checkpoint(path, InputError)
    meta = ckpt.get(META_KEY) if isinstance(ckpt, dict) else None
    if not isinstance(meta, dict) or "hyper_parameters" not in ckpt:
        raise InputError(f"{path}: not a lit3d checkpoint (no '{META_KEY}' metadata)")
    name = task_name(meta)
    if want not in name.lower():
        raise InputError(f"{path}: checkpoint is for task '{name}', not '{want}'")
    if want == "completion":
        from lit3d.completion.checkpoint_upgrade import upgrade_checkpoint
        from lit3d.completion.module import CompletionTask as cls

        ckpt = upgrade_checkpoint(ckpt)  # one written before the completion settings were nodes, as today's
    else:
        from lit3d.canonical.checkpoint_upgrade import upgrade_checkpoint
        from lit3d.canonical.module import CanonicalTask as cls

        try:  # one written before the canonical settings were nodes, as today's
            ckpt = upgrade_checkpoint(ckpt, str(path))
        except ValueError as err:  # a parked option it used: the message names the file, the key and the git tag
            raise InputError(str(err)) from err
    task = cls(**ckpt["hyper_parameters"])
    task.on_load_checkpoint(ckpt)
    load_state(task, ckpt)  # a zoo file may be slim: fp16, training-only parts left out (lit3d.zoo.slim)
    try:
        task = task.to(torch.device(device)).eval()
    except (RuntimeError, AssertionError) as exc:
        raise InputError(f"--device {device}: {str(exc).splitlines()[0]}") from None
    return task, ckpt


def load_completer(path: str | Path, device: str = "cpu") -> Completer:
    """Load a completion checkpoint (see :class:`Completer`)."""
    task, ckpt = load_task(path, device, "completion")
    geom = GridGeometry.from_checkpoint(ckpt[META_KEY].get("data"), task.net_cfg)
    notes = [geom.note] if geom.note else []
    return Completer(task, float(task.threshold), geom, str(path), device, notes)


@dataclass
class Options:
    """How the object is cut from the image (all optional)."""
    mask: np.ndarray | None = None      # (H, W) bool
    near: float | None = None           # metres
    far: float | None = None            # metres
    remove_plane: bool = False
    largest_cluster: bool = False
    fuse_input: bool = True             # OR the visible surface voxels into the completed grid


@dataclass
class Result:
    """Everything one reconstruction produced (arrays described in the module doc)."""
    points: np.ndarray          # (N, 3) float64 visible points, camera frame, metres
    keep: np.ndarray            # (H, W) bool pixels used
    placement: Placement
    surface: np.ndarray         # (R, R, R) bool partial grid at the output resolution
    partial: np.ndarray         # (r, r, r) bool network input
    probs: np.ndarray           # (R, R, R) float32
    occupancy: np.ndarray       # (R, R, R) bool
    mesh: object                # trimesh.Trimesh, camera frame
    timings: dict[str, float]
    info: dict


def cut_object(depth: np.ndarray, intr: Intrinsics, opts: Options, label: str) -> tuple[np.ndarray, dict]:
    """``(H, W) bool`` object pixels after mask, depth range, plane removal, largest cluster."""
    keep = depth_range_mask(depth, opts.near, opts.far)
    if opts.mask is not None:
        keep &= opts.mask
    info: dict = {"foreground_pixels": int((depth > 0).sum())}
    if opts.remove_plane and keep.any():
        keep, info["plane"] = remove_plane(depth, intr, keep)
    if opts.largest_cluster and keep.any():
        keep = largest_depth_cluster(depth, keep)
    info["object_pixels"] = int(keep.sum())
    if info["object_pixels"] < 10:
        raise InputError(f"{label}: empty after cropping ({info['object_pixels']} object pixels left of "
                         f"{info['foreground_pixels']} after mask/depth range/plane removal)")
    return keep, info


def reconstruct(depth: np.ndarray, intr: Intrinsics, completer: Completer, opts: Options | None = None,
                label: str = "<depth>", canonical=None) -> Result:
    """Run every step on one ``(H, W) float32`` depth image in metres (0 = background).

    ``canonical`` (a :class:`lit3d.reconstruct.canonical.CanonicalMapper`) first maps the visible
    points to the subject's canonical pose (step ``canonical``), which is then completed.
    """
    from datamodules.completion.voxel_cache import max_pool_bool

    opts = opts or Options()
    geom = completer.geometry
    h, w = depth.shape
    intr.check(w, h, label)
    t: dict[str, float] = {}
    t0 = time.perf_counter()
    keep, info = cut_object(depth, intr, opts, label)
    t["segment"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    points = backproject(depth, intr, keep)
    t["backproject"] = time.perf_counter() - t0

    if canonical is not None:
        t0 = time.perf_counter()
        points, info["canonical"] = canonical.map_points(points, label)
        t["canonical"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    placement = fit_placement(points, geom)
    surface, outside = voxelise_points(points, placement, geom.push)
    if not surface.any():
        raise InputError(f"{label}: empty after cropping (no visible point falls inside the grid)")
    partial = max_pool_bool(surface, geom.input_factor)
    t["grid"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    probs = geom.to_network(completer.probabilities(geom.to_network(partial)))
    t["network"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    thr = completer.threshold
    occupancy = probs > thr
    if opts.fuse_input:
        occupancy |= surface
    t["threshold"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    field_ = np.where(surface, np.float32(1.0), probs) if opts.fuse_input else probs
    try:
        mesh = voxels_to_mesh(field_, label, level=thr)
    except ShapeError:
        raise InputError(f"{label}: the network predicts no occupied voxel at threshold {thr:.2f}") from None
    # marching cubes ran on the grid padded by one voxel: vertex v lies at continuous index v - 0.5
    mesh.vertices = placement.to_camera(np.asarray(mesh.vertices) - 0.5)
    if mesh.volume < 0:  # the y flip (grid y up -> camera y down) turns the winding inside out
        mesh.invert()
    t["mesh"] = time.perf_counter() - t0

    info.update(points=len(points), points_outside_grid=outside, partial_voxels=int(surface.sum()),
                input_voxels=int(partial.sum()), occupied_voxels=int(occupancy.sum()),
                mesh_vertices=len(mesh.vertices), mesh_faces=len(mesh.faces))
    return Result(points, keep, placement, surface, partial, probs, occupancy, mesh, t, info)


def index_to_camera_matrix(placement: Placement) -> np.ndarray:
    """``(4, 4) float64`` affine: homogeneous continuous grid index ``[i, j, k, 1]`` -> camera metres."""
    s, h = 1.0 / placement.scale, placement.res / 2
    m = np.diag([s, -s, s, 1.0])
    m[:3, 3] = np.asarray(placement.centre) + np.array([-h * s, h * s, -h * s])
    return m
