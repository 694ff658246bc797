"""Non-learned canonical-form baselines of thesis 5.4 scored with the task's retrieval descriptor."""
from __future__ import annotations

import time

import numpy as np

from lit3d.geometry.canonical_forms import canonical_forms_multi
from lit3d.metrics.retrieval import retrieval_scores
from lit3d.retrieval.descriptor import DescriptorConfig, distance_matrix_from_meshes


def baseline_retrieval(meshes, labels, methods, cfg=None, max_vertices: int = 1000, max_iter: int = 300,
                       eps: float = 1e-4) -> dict[str, dict]:
    """Retrieval scores of non-learned canonical forms: each mesh ``(verts, faces)`` -> its canonical
    form by every method -> the view-based descriptor (:mod:`lit3d.retrieval.descriptor`, config
    ``cfg``) -> distance matrix -> :func:`lit3d.metrics.retrieval.retrieval_scores` with ``labels``
    ``(n,)``. Returns ``{method: {"nn", "ft", "st", "e", "dcg", "seconds"}}``."""
    cfg = cfg or DescriptorConfig()
    labels = np.asarray(labels)
    t0 = time.perf_counter()
    forms = canonical_forms_multi(meshes, methods, max_vertices, max_iter, eps)
    t_forms = (time.perf_counter() - t0) / max(len(list(methods)), 1)
    out = {}
    for m, fm in forms.items():
        t1 = time.perf_counter()
        scores = dict(retrieval_scores(distance_matrix_from_meshes(fm, cfg), labels))
        scores["seconds"] = t_forms + time.perf_counter() - t1
        out[m] = scores
    return out
