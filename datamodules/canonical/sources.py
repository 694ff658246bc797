"""Where canonical-form meshes come from: one class per data source, each enumerating subjects and
poses and loading meshes ``(V, 3) float, (F, 3) int`` unnormalised with y up; :func:`build_source` builds
one from its settings (:mod:`datamodules.canonical.settings`, the ``data.source`` node).

    synth    procedural humanoids / quadrupeds (``datamodules.canonical.figures``); canonical = T-pose
             / standing pose; no download.
    tosca    TOSCA meshes under ``root`` (.mat/.vert+.tri/.off/.ply); canonical = pose 0 (null pose).
    shrec14  SHREC'14 humans under ``root`` with a PSB ``.cla`` (classes = subjects); canonical =
             the pose at ``canonical_pose`` within each class.
    anny     people from the Anny body model (:mod:`lit3d.body_model.bodies`): ``n_subjects``
             phenotypes x ``n_poses`` joint-limit poses, both seeded; canonical = the rest pose.
    faust    FAUST registrations under ``root`` (:mod:`datamodules.canonical.posesets`); canonical =
             pose ``canonical_pose``, which is also an item (FAUST has no separate rest pose).
    sumner   Sumner & Popovic's animals under ``root``; canonical = each animal's reference pose.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from datamodules.cache import DataError
from datamodules.canonical import figures, shrec14, tosca
from datamodules.canonical.flow import skinned_canonical
from datamodules.canonical.posesets import index_faust, index_sumner
from datamodules.canonical.settings import (POSE_DRAWS, ROOTLESS, AnnySettings, SourceSettings,
                                            SynthSettings)
from datamodules.canonical.splits import OWN_POSE_BASE
from lit3d.body_model import bodies



class _Source:
    """Enumerates subjects and poses and loads meshes (unnormalised, y up)."""

    kind = "base"

    def subjects(self) -> list[str]: ...
    def poses(self, subject: str) -> list[int]: ...
    def canonical_pose(self, subject: str): ...
    def mesh(self, subject: str, pose) -> tuple[np.ndarray, np.ndarray]: ...
    def category(self, subject: str) -> str:
        return subject

    def correspondence(self, subject: str, pose, canon_verts: np.ndarray, canon_faces: np.ndarray,
                       posed_verts: np.ndarray, posed_faces: np.ndarray) -> np.ndarray | None:
        """Raw posed positions ``(V, 3)`` of the raw canonical mesh's vertices ``canon_verts``, or None
        when the two meshes do not correspond. Here: meshes with one vertex order (Anny, TOSCA, Sumner,
        FAUST), recognised by equal vertex counts and equal faces."""
        if len(canon_verts) != len(posed_verts) or not np.array_equal(canon_faces, posed_faces):
            return None
        return np.asarray(posed_verts, np.float64)


class SynthSource(_Source):
    """``n_subjects`` procedural figures (``kinds`` in turn) x ``n_poses`` poses drawn with ``pose_seed``: pose
    p is the same for every subject of a kind (``pose_draw="shared"``) or each subject's own (``"per_subject"``).
    ``own_poses`` = N: every subject has N more poses of its own (ids ``OWN_POSE_BASE + k``), which the
    splits give to training only (:func:`~datamodules.canonical.splits.fold_pairs`): many distinct
    training poses while the test keeps one pose set for every figure."""

    kind = "synth"

    def __init__(self, kinds: Sequence[str], n_subjects: int, n_poses: int, seed: int, mesh_resolution: int,
                 pose_seed: int, yaw_range: float, pose_strength: float, pose_draw: str = "shared", own_poses: int = 0):
        if pose_draw not in POSE_DRAWS:
            raise DataError(f"unknown pose_draw '{pose_draw}' ({', '.join(POSE_DRAWS)})")
        self.f = figures
        self.own_poses = int(own_poses)
        self.pose_draw = pose_draw
        self.kinds = list(kinds)
        self.n_subjects, self.n_poses = n_subjects, n_poses
        self.seed, self.res, self.pose_seed = seed, mesh_resolution, pose_seed
        self.yaw_range, self.strength = yaw_range, pose_strength
        self._subjects = {}
        for i in range(n_subjects):
            kind = self.kinds[i % len(self.kinds)]
            self._subjects[f"{kind}{i:03d}"] = (kind, seed * 1000 + i)

    def subjects(self):
        return list(self._subjects)

    def poses(self, subject):
        return list(range(self.n_poses)) + [OWN_POSE_BASE + k for k in range(self.own_poses)]

    def canonical_pose(self, subject):
        return "canonical"

    def category(self, subject):
        return self._subjects[subject][0]

    def _posing(self, subject, pose) -> tuple:
        """(figure, joint rotations or None, the pose's yaw, its whole turn in degrees as figure_mesh applies
        it: the yaw plus 90 for quadrupeds) of one pose."""
        kind, sseed = self._subjects[subject]
        subj = self.f.make_subject(kind, sseed)
        turn = 90.0 if kind == "quadruped" else 0.0  # figure_mesh shows quadrupeds from the side
        if pose == "canonical":
            return subj, None, 0.0, turn
        own_pose = pose >= OWN_POSE_BASE  # data.source.own_poses: the subject's pose pose - OWN_POSE_BASE
        if own_pose:
            pose = pose - OWN_POSE_BASE
        own = [int(subject[len(kind):])] if self.pose_draw == "per_subject" or own_pose else []  # the subject's own poses
        rng = np.random.default_rng([self.pose_seed, int(pose), 17] + own)
        yaw = float(rng.uniform(-self.yaw_range, self.yaw_range))
        rotations = self.f.make_pose(kind, int(pose), self.pose_seed, self.strength, *own)
        return subj, rotations, yaw, turn + yaw

    def mesh(self, subject, pose):
        subj, rotations, yaw, _ = self._posing(subject, pose)
        return self.f.figure_mesh(subj, rotations, self.res, yaw_deg=yaw)

    def correspondence(self, subject, pose, canon_verts, canon_faces, posed_verts, posed_faces):
        """The canonical mesh skinned to the pose (:func:`datamodules.canonical.flow.skinned_canonical`):
        each figure is remeshed per pose, so vertices move with their nearest bone."""
        subj, rotations, yaw, turn = self._posing(subject, pose)
        return skinned_canonical(subj, canon_verts, rotations, turn - yaw, turn)


class _MeshFileSource(_Source):
    """Subjects and poses indexed from mesh files: ``items`` maps (subject, pose) -> path; pose
    ``canon`` of every subject is its canonical pose; ``up_axis`` "z" meshes are turned to y-up."""

    items: dict
    canon: int
    up_axis: str

    def subjects(self):
        return sorted({s for s, _ in self.items})

    def poses(self, subject):
        return sorted(p for s, p in self.items if s == subject and p != self.canon)

    def canonical_pose(self, subject):
        return self.canon

    def mesh(self, subject, pose):
        v, f = tosca.read_mesh(self.items[(subject, int(pose))])
        return (tosca.z_up_to_y_up(v) if self.up_axis == "z" else v), f


class ToscaSource(_MeshFileSource):
    kind = "tosca"

    def __init__(self, root: str, classes: Sequence[str] | None, canonical_pose: int, up_axis: str):
        items = tosca.index_tosca(root, list(classes) if classes else None)
        self.items = {(it.cls, it.pose): it.path for it in items}
        self.canon = canonical_pose
        self.up_axis = up_axis
        missing = sorted({c for c, _ in self.items} - {c for c, p in self.items if p == canonical_pose})
        if missing:
            raise DataError(f"{root}: no canonical pose {canonical_pose} for class(es) {', '.join(missing)}")


class Shrec14Source(_MeshFileSource):
    kind = "shrec14"

    def __init__(self, root: str, cla: str | None, canonical_pose: int, up_axis: str):
        items = shrec14.index_shrec14(root, cla)
        self.items = {(it.subject, it.pose): it.path for it in items}
        self.canon, self.up_axis = canonical_pose, up_axis


class AnnySource(_Source):
    """``n_subjects`` Anny bodies (``anny<i>``, phenotypes drawn with ``seed``) x ``n_poses`` poses
    drawn with ``pose_seed``: pose p is the same for every subject (``pose_draw="shared"``) or each
    subject's own (``"per_subject"``: no two subjects share a pose). One subject's poses are posed
    in one batch and kept until another subject is asked for."""

    kind = "anny"
    BATCH = 16

    def __init__(self, n_subjects: int, n_poses: int, seed: int, pose_seed: int, yaw_range: float,
                 pose_strength: float, phenotypes: str = "uniform", pose_draw: str = "shared"):
        if pose_draw not in POSE_DRAWS:
            raise DataError(f"unknown pose_draw '{pose_draw}' ({', '.join(POSE_DRAWS)})")
        self.b = bodies
        self.model = bodies.BodyModel()
        self.n_subjects, self.n_poses, self.seed = n_subjects, n_poses, seed
        self.pose_seed, self.yaw_range, self.strength = pose_seed, yaw_range, pose_strength
        if phenotypes not in bodies.PHENOTYPE_MODES:
            raise DataError(f"unknown phenotypes '{phenotypes}' ({', '.join(bodies.PHENOTYPE_MODES)})")
        self.phenotypes = phenotypes
        self.pose_draw = pose_draw
        self._memo: tuple[str, dict] | None = None

    def subjects(self):
        return [f"anny{i:04d}" for i in range(self.n_subjects)]

    def poses(self, subject):
        return list(range(self.n_poses))

    def canonical_pose(self, subject):
        return "canonical"

    def category(self, subject):
        return "human"

    def _pose(self, subject, pose):
        if pose == "canonical":
            return None
        own = int(subject[len("anny"):]) if self.pose_draw == "per_subject" else None
        return self.b.sample_pose(self.pose_seed, int(pose), self.strength, self.yaw_range, subject=own)

    def phenotype(self, subject) -> dict[str, float]:
        """The subject's Anny phenotype ``{label: value in [0, 1]}``."""
        return self.b.sample_phenotype(self.seed, int(subject[len("anny"):]), self.phenotypes, self.model.model)

    def mesh(self, subject, pose):
        if self._memo is None or self._memo[0] != subject:
            pheno = self.phenotype(subject)
            keys = ["canonical"] + self.poses(subject)
            verts = {}
            for i in range(0, len(keys), self.BATCH):
                chunk = keys[i:i + self.BATCH]
                verts.update(zip(chunk, self.model.vertices(pheno, [self._pose(subject, k) for k in chunk])))
            self._memo = (subject, verts)
        key = pose if pose == "canonical" else int(pose)
        return self._memo[1][key].astype(np.float64), self.model.faces


class FaustSource(_MeshFileSource):
    """FAUST meshes (y up); every pose, the canonical one included, is an item."""

    kind = "faust"

    def __init__(self, root: str, canonical_pose: int):
        self.items, self.canon, self.up_axis = index_faust(root), canonical_pose, "y"
        missing = sorted({s for s, _ in self.items} - {s for s, p in self.items if p == canonical_pose})
        if missing:
            raise DataError(f"{root}: no canonical pose {canonical_pose} for subject(s) {', '.join(missing)}")

    def poses(self, subject):
        return sorted(p for s, p in self.items if s == subject)

    def category(self, subject):
        return "human"


class SumnerSource(_MeshFileSource):
    """Sumner & Popovic's animals (y up); canonical = the reference pose (index 0)."""

    kind = "sumner"

    def __init__(self, root: str, classes: Sequence[str] | None):
        self.items = index_sumner(root, list(classes) if classes else None)
        self.canon, self.up_axis = 0, "y"


def build_source(settings: SourceSettings, root: str | None = None) -> _Source:
    """The source of ``settings`` (:mod:`datamodules.canonical.settings`); ``root``: the mesh folder of the
    sources that read files (``data.root``)."""
    if settings.kind not in ROOTLESS and not root:
        raise DataError(f"data source '{settings.kind}' needs root=<folder with the meshes>")
    return SOURCE_BUILDERS[settings.kind](settings, root)


def _synth(s: SynthSettings, root) -> SynthSource:
    return SynthSource(s.kinds, s.n_subjects, s.n_poses, s.seed, s.mesh_resolution, s.pose_seed, s.yaw_range,
                       s.pose_strength, s.pose_draw, s.own_poses)


def _anny(s: AnnySettings, root) -> AnnySource:
    return AnnySource(s.n_subjects, s.n_poses, s.body_seed, s.pose_seed, s.yaw_range, s.pose_strength, s.phenotypes,
                      s.pose_draw)


SOURCE_BUILDERS = {
    "synth": _synth,
    "anny": _anny,
    "tosca": lambda s, root: ToscaSource(root, s.classes, s.canonical_pose, s.up_axis),
    "shrec14": lambda s, root: Shrec14Source(root, s.cla, s.canonical_pose, s.up_axis),
    "faust": lambda s, root: FaustSource(root, s.canonical_pose),
    "sumner": lambda s, root: SumnerSource(root, s.classes),
}
