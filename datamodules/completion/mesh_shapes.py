"""A real mesh as a completion shape: the counterpart of the procedural :class:`Shape`.

:func:`datamodules.completion.depth_voxels.make_sample` takes either. A procedural shape's target
comes from its primitives' analytic inside tests; a :class:`MeshShape`'s from
:func:`lit3d.geometry.solid_voxels.solid_voxels` (surface shell, enclosed cavities and the
generalised winding number for open meshes), made directly on the target grid: equal to the
256^3 solid max-pooled to it up to boundary voxels (tested), at a fraction of the cost.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from datamodules.completion.cad_models import CadModel, load_model_mesh


@dataclass
class MeshShape:
    """A category name and one triangle soup (object frame, +y up).

    Attributes:
        category: thesis category name.
        points: (V, 3) float64 vertices.
        faces: (F, 3) int64 triangles.
        model_id: where it came from (manifest id).
    """

    category: str
    points: np.ndarray
    faces: np.ndarray
    model_id: str = ""

    def vertices(self) -> np.ndarray:
        """(V', 3) vertices that triangles use (the view normalisation's bounding box)."""
        return self.points[np.unique(self.faces)]

    def mesh(self):
        """The triangle soup as a trimesh (for rendering)."""
        import trimesh

        return trimesh.Trimesh(self.points, self.faces, process=False)


def mesh_shape(model: CadModel, up_axis: str = "y") -> MeshShape:
    """A :class:`~datamodules.completion.cad_models.CadModel` loaded as a :class:`MeshShape`."""
    mesh = load_model_mesh(model, up_axis)
    return MeshShape(model.category, np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64),
                     model.model_id)
