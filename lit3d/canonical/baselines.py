"""Non-learned canonical-form baselines of thesis 5.4 scored with the task's retrieval descriptor,
and the intrinsic ShapeDNA row (the full-mesh ceiling)."""
from __future__ import annotations

import time

import numpy as np

from lit3d.geometry.canonical_forms import canonical_forms_multi
from lit3d.geometry.spectral import shape_dna, shape_dna_distances
from lit3d.metrics.retrieval import retrieval_scores
from lit3d.retrieval.descriptor import DescriptorConfig, distance_matrix_from_features, mesh_features
from lit3d.utils.progress import progress

SHAPEDNA = "shapedna"


def baseline_retrieval(meshes, labels, methods, cfg=None, max_vertices: int | None = None, max_iter: int = 300,
                       eps: float = 1e-4, landmarks: int | None = 300) -> dict[str, dict]:
    """Retrieval scores of non-learned canonical forms: each mesh ``(verts, faces)`` -> its canonical
    form by every method -> the view-based descriptor (:mod:`lit3d.retrieval.descriptor`, config
    ``cfg``) -> distance matrix -> :func:`lit3d.metrics.retrieval.retrieval_scores` with ``labels``
    ``(n,)``. ``shapedna`` among ``methods`` adds the ShapeDNA row. Returns ``{method: {"nn", "ft",
    "st", "e", "dcg", "seconds"}}``."""
    cfg = cfg or DescriptorConfig()
    labels = np.asarray(labels)
    feats, dists, secs = mesh_rows(meshes, methods, cfg, max_vertices, landmarks, eps, max_iter)
    out = {}
    for m, fm in feats.items():
        t1 = time.perf_counter()
        out[m] = dict(retrieval_scores(distance_matrix_from_features(fm, cfg), labels))
        out[m]["seconds"] = secs[m] + time.perf_counter() - t1
    for m, D in dists.items():
        out[m] = dict(retrieval_scores(D, labels), seconds=secs[m])
    return out


def mesh_rows(meshes, methods, cfg: DescriptorConfig, max_vertices: int | None = None, landmarks: int | None = 300,
              eps: float = 1e-4, max_iter: int = 300) -> tuple[dict, dict, dict]:
    """The mesh rows' inputs for a seed study: ``({method: descriptor features}, {"shapedna": (n, n)
    distances}, {row: seconds})`` for the canonical forms of ``methods`` (full resolution, landmark
    geodesics; :func:`lit3d.geometry.canonical_forms.canonical_forms_multi`) and ShapeDNA."""
    methods = list(methods)
    forms_methods = [m for m in methods if m != SHAPEDNA]
    feats, dists, secs = {}, {}, {}
    if forms_methods:
        t0 = time.perf_counter()
        forms = canonical_forms_multi(meshes, forms_methods, max_vertices, max_iter, eps, landmarks)
        t_forms = (time.perf_counter() - t0) / len(forms_methods)
        for m, fm in forms.items():
            t1 = time.perf_counter()
            feats[m] = mesh_features(fm, cfg)
            secs[m] = t_forms + time.perf_counter() - t1
    if SHAPEDNA in methods:
        t0 = time.perf_counter()
        dists[SHAPEDNA] = shape_dna_distances(np.stack([shape_dna(v, f) for v, f in progress(meshes, SHAPEDNA)]))
        secs[SHAPEDNA] = time.perf_counter() - t0
    return feats, dists, secs
