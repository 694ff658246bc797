"""Round-trip check on a known mesh: render its depth, reconstruct, compare with its voxelisation.

    row = round_trip(mesh, completer)      # dict of the measures below
    python -m studies.reconstruct.check CKPT ../shared/data/meshes/*.obj ../shared/data/tosca8k/cat0.ply

Measures (grids in the reconstruction's own placement, so all are at the checkpoint's ``R``):

- ``iou_completed``: completed occupancy vs the mesh's solid voxelisation
  (:func:`lit3d.reconstruct.grid.solid_voxels`);
- ``iou_partial``: the visible surface voxels (what the depth image alone says is occupied);
- ``iou_input_upsampled``: the network input (max-pooled partial) upsampled back to ``R``, the
  completion task's input-as-prediction baseline;
- ``chamfer_visible_vox``: mean distance from the visible points to the output mesh, in voxels
  (``p95_visible_vox`` its 95th percentile): how well the mesh overlays the input points.
"""
from __future__ import annotations

import sys

import numpy as np

from lit3d.reconstruct.backproject import RECGAN_FOV_DEG, Intrinsics
from lit3d.metrics.voxel import occupancy_iou
from lit3d.reconstruct.grid import solid_voxels
from lit3d.reconstruct.pipeline import Completer, Options, reconstruct
from lit3d.reconstruct.synthetic import pose_in_front, render_depth_pinhole
from lit3d.metrics.mesh import directed_distances, surface_samples
from lit3d.reconstruct.pipeline import load_completer

WIDTH, HEIGHT = 320, 240


def round_trip(mesh, completer: Completer, azimuth: float = 30.0, elevation: float = 20.0, up_axis: int = 1,
               fuse_input: bool = True, label: str = "<mesh>") -> dict:
    """Render ``mesh`` (posed 1.5 m in front of the 3D-RecGAN++ camera), reconstruct it, measure."""
    posed = pose_in_front(mesh, azimuth=azimuth, elevation=elevation, up_axis=up_axis)
    intr = Intrinsics.from_fov(RECGAN_FOV_DEG, WIDTH, HEIGHT)
    depth = render_depth_pinhole(posed, intr, WIDTH, HEIGHT)
    res = reconstruct(depth, intr, completer, Options(fuse_input=fuse_input), label=label)
    truth = solid_voxels(posed, res.placement)
    f = completer.geometry.input_factor
    upsampled = res.partial.repeat(f, 0).repeat(f, 1).repeat(f, 2)
    d = directed_distances(res.points, surface_samples(res.mesh, 200_000, normalise=False)) * res.placement.scale
    return {"name": label, "iou_completed": occupancy_iou(res.occupancy, truth),
            "iou_partial": occupancy_iou(res.surface, truth), "iou_input_upsampled": occupancy_iou(upsampled, truth),
            "chamfer_visible_vox": float(d.mean()), "p95_visible_vox": float(np.percentile(d, 95)),
            "seconds": float(sum(res.timings.values())), "timings": res.timings, "result": res, "truth": truth}


def main(argv: list[str] | None = None) -> None:
    from pathlib import Path

    import trimesh

    argv = list(sys.argv[1:] if argv is None else argv)
    completer = load_completer(argv[0])
    print("| mesh | IoU completed | IoU visible voxels | IoU input upsampled | visible->mesh (voxels) |")
    print("|---|---|---|---|---|")
    for p in argv[1:]:
        m = trimesh.load(p, force="mesh")
        up = 2 if "tosca" in p else 1  # TOSCA's up axis is +z
        r = round_trip(m, completer, up_axis=up, label=Path(p).stem)
        print(f"| {r['name']} | {r['iou_completed']:.3f} | {r['iou_partial']:.3f} | {r['iou_input_upsampled']:.3f} "
              f"| {r['chamfer_visible_vox']:.2f} |", flush=True)


if __name__ == "__main__":
    main()
