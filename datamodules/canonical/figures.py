"""Procedural articulated figures: humanoids and quadrupeds with per-subject proportions.

A figure is a skeleton (joint tree with rest offsets), per-bone radii and a pose
(local joint rotations). Forward kinematics places the joints; every bone becomes
a tapered capsule; the capsules are blended with a smooth minimum into one signed
distance field, and marching cubes turns the field into a closed triangle mesh.

Conventions: y is up, units are about 1 per body height; humanoids face +z (the camera sees
them from the front), quadrupeds face +x (seen from the side).
Canonical pose: T-pose for humanoids (arms horizontal, legs straight), standing
pose for quadrupeds (legs straight down, neck and tail at rest). The same pose
index gives the same joint angles for every subject of a kind (as in SHREC'14,
where poses repeat across subjects), so subjects and poses are separable split
units.

    subject = make_subject("humanoid", seed=3)
    pose = make_pose("humanoid", pose_index=5, seed=0)
    verts, faces = figure_mesh(subject, pose, resolution=64)
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

GENERATOR_VERSION = "figures-1"
KINDS = ("humanoid", "quadruped")


@dataclass
class Subject:
    """Skeleton with rest offsets (joint -> parent, world frame in the canonical pose) and radii."""

    kind: str
    seed: int
    names: list[str]
    parents: list[int]
    offsets: np.ndarray  # (J, 3) offset of each joint from its parent in the canonical pose
    radii: np.ndarray    # (J,) body radius at each joint
    root: np.ndarray     # (3,) root joint position
    params: dict = field(default_factory=dict)


def _rot(axis: str, deg: float) -> np.ndarray:
    a = np.deg2rad(deg)
    c, s = np.cos(a), np.sin(a)
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == "y":
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _build(kind, seed, spec, params) -> Subject:
    names = [n for n, _, _, _ in spec]
    index = {n: i for i, n in enumerate(names)}
    parents = [index[p] if p is not None else -1 for _, p, _, _ in spec]
    offsets = np.array([o for _, _, o, _ in spec], dtype=float)
    radii = np.array([r for _, _, _, r in spec], dtype=float)
    return Subject(kind, seed, names, parents, offsets, radii, np.zeros(3), params)


def make_subject(kind: str, seed: int) -> Subject:
    """A subject of ``kind`` with proportions drawn from ``seed`` (limb lengths, girth, head...)."""
    rng = np.random.default_rng([seed, 7919])
    u = lambda lo, hi: float(rng.uniform(lo, hi))  # noqa: E731
    if kind == "humanoid":
        p = {"leg": u(0.40, 0.52), "shin_ratio": u(0.9, 1.1), "torso": u(0.28, 0.36), "arm": u(0.28, 0.38),
             "forearm_ratio": u(0.85, 1.1), "shoulder": u(0.13, 0.21), "hip": u(0.07, 0.11),
             "girth": u(0.75, 1.35), "head": u(0.085, 0.12), "neck": u(0.05, 0.08)}
        g = p["girth"]
        thigh, shin = p["leg"] / (1 + p["shin_ratio"]), p["leg"] * p["shin_ratio"] / (1 + p["shin_ratio"])
        upper, fore = p["arm"] / (1 + p["forearm_ratio"]), p["arm"] * p["forearm_ratio"] / (1 + p["forearm_ratio"])
        t = p["torso"]
        spec = [
            ("pelvis", None, (0, 0, 0), 0.085 * g),
            ("spine", "pelvis", (0, t * 0.5, 0), 0.08 * g),
            ("chest", "spine", (0, t * 0.5, 0), 0.095 * g),
            ("neck", "chest", (0, p["neck"], 0), 0.035 * g),
            ("head", "neck", (0, p["head"] * 1.1, 0), p["head"]),
        ]
        for side, sx in (("l", 1), ("r", -1)):
            spec += [
                (f"shoulder_{side}", "chest", (sx * p["shoulder"], -0.01, 0), 0.05 * g),
                (f"elbow_{side}", f"shoulder_{side}", (sx * upper, 0, 0), 0.038 * g),
                (f"wrist_{side}", f"elbow_{side}", (sx * fore, 0, 0), 0.028 * g),
                (f"hand_{side}", f"wrist_{side}", (sx * 0.06, 0, 0), 0.03 * g),
                (f"hip_{side}", "pelvis", (sx * p["hip"], -0.03, 0), 0.07 * g),
                (f"knee_{side}", f"hip_{side}", (0, -thigh, 0), 0.05 * g),
                (f"ankle_{side}", f"knee_{side}", (0, -shin, 0), 0.035 * g),
                (f"toe_{side}", f"ankle_{side}", (0, -0.03, 0.09), 0.03 * g),
            ]
        return _build(kind, seed, spec, p)
    if kind == "quadruped":
        p = {"body": u(0.45, 0.75), "leg": u(0.22, 0.42), "neck": u(0.12, 0.35), "head": u(0.07, 0.11),
             "snout": u(0.05, 0.14), "tail": u(0.1, 0.35), "girth": u(0.7, 1.3), "width": u(0.07, 0.11)}
        g, b, leg = p["girth"], p["body"], p["leg"]
        spec = [
            ("hips", None, (0, 0, 0), 0.09 * g),
            ("mid", "hips", (0, 0.01, b * 0.5), 0.1 * g),
            ("withers", "mid", (0, 0.01, b * 0.5), 0.095 * g),
            ("neck", "withers", (0, p["neck"] * 0.8, p["neck"] * 0.6), 0.05 * g),
            ("head", "neck", (0, 0.02, p["head"]), p["head"]),
            ("snout", "head", (0, -0.02, p["snout"]), p["head"] * 0.5),
            ("tail1", "hips", (0, 0.02, -p["tail"] * 0.5), 0.03 * g),
            ("tail2", "tail1", (0, -0.02, -p["tail"] * 0.5), 0.018 * g),
        ]
        for side, sx in (("l", 1), ("r", -1)):
            for end, anchor in (("f", "withers"), ("b", "hips")):
                spec += [
                    (f"{end}shoulder_{side}", anchor, (sx * p["width"], -0.03, 0), 0.06 * g),
                    (f"{end}knee_{side}", f"{end}shoulder_{side}", (0, -leg * 0.5, 0), 0.04 * g),
                    (f"{end}foot_{side}", f"{end}knee_{side}", (0, -leg * 0.5, 0), 0.03 * g),
                ]
        return _build(kind, seed, spec, p)
    raise ValueError(f"unknown figure kind '{kind}' (known: {', '.join(KINDS)})")


def make_pose(kind: str, pose_index: int, seed: int = 0, strength: float = 1.0,
              subject: int | None = None) -> dict[str, np.ndarray]:
    """Local joint rotations (3x3) of pose ``pose_index``; ``{}`` is the canonical pose.

    The same (kind, pose_index, seed) gives the same angles for every subject; ``subject`` (an index)
    draws that subject's own pose instead (no two subjects share one). ``strength`` scales all angles
    (0 = canonical).
    """
    rng = np.random.default_rng([seed, pose_index, 104729, KINDS.index(kind)] + ([] if subject is None else [subject]))
    u = lambda lo, hi: float(rng.uniform(lo, hi)) * strength  # noqa: E731
    R: dict[str, np.ndarray] = {}
    if kind == "humanoid":
        R["spine"] = _rot("x", u(-15, 25)) @ _rot("y", u(-25, 25)) @ _rot("z", u(-12, 12))
        R["neck"] = _rot("x", u(-20, 25)) @ _rot("y", u(-40, 40))
        for side, sx in (("l", 1), ("r", -1)):
            # arms: from horizontal (T) down/up, forwards/backwards; elbows bend
            R[f"shoulder_{side}"] = _rot("y", sx * u(-30, 70)) @ _rot("z", sx * u(-80, 60))
            R[f"elbow_{side}"] = _rot("y", sx * u(0, 120))
            R[f"hip_{side}"] = _rot("x", u(-70, 35)) @ _rot("z", sx * u(-5, 30))
            R[f"knee_{side}"] = _rot("x", u(0, 100))
        return R
    if kind == "quadruped":
        R["mid"] = _rot("y", u(-25, 25)) @ _rot("x", u(-10, 10))
        R["withers"] = _rot("y", u(-20, 20))
        R["neck"] = _rot("x", u(-35, 45)) @ _rot("y", u(-45, 45))
        R["tail1"] = _rot("x", u(-40, 50)) @ _rot("y", u(-40, 40))
        for side in ("l", "r"):
            for end in ("f", "b"):
                R[f"{end}shoulder_{side}"] = _rot("x", u(-45, 45)) @ _rot("z", u(-15, 15))
                R[f"{end}knee_{side}"] = _rot("x", u(-60, 60) if end == "f" else u(-60, 10))
        return R
    raise ValueError(f"unknown figure kind '{kind}'")


def joint_frames(subject: Subject, pose: dict[str, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Forward kinematics: joint positions ``(J, 3)`` and world rotations ``(J, 3, 3)`` for a pose
    (None/{} = canonical, every rotation the identity)."""
    pose = pose or {}
    J = len(subject.names)
    G = np.zeros((J, 3, 3))
    P = np.zeros((J, 3))
    for j in range(J):
        par = subject.parents[j]
        local = pose.get(subject.names[j], np.eye(3))
        if par < 0:
            G[j] = local
            P[j] = subject.root
        else:
            P[j] = P[par] + G[par] @ subject.offsets[j]
            G[j] = G[par] @ local
    return P, G


def joint_positions(subject: Subject, pose: dict[str, np.ndarray] | None = None) -> np.ndarray:
    """Forward kinematics: ``(J, 3)`` joint positions for a pose (None/{} = canonical)."""
    return joint_frames(subject, pose)[0]


SPHERE_JOINTS = ("head", "pelvis", "chest", "hips", "mid", "withers")


def capsule_bones(subject: Subject) -> list[tuple[int, int]]:
    """Per capsule of :func:`capsules` (same order): (anchor joint, joint whose world rotation moves it).
    A bone capsule from parent p to joint j moves with p's frame about p; a sphere with its own joint."""
    bones = [(par, par) for par in subject.parents if par >= 0]
    return bones + [(subject.names.index(n),) * 2 for n in SPHERE_JOINTS if n in subject.names]


def capsules(subject: Subject, pose=None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Tapered capsules (a, b, ra, rb) for every bone, plus a sphere for the head/hands (a == b)."""
    P = joint_positions(subject, pose)
    A, B, RA, RB = [], [], [], []
    for j, par in enumerate(subject.parents):
        if par < 0:
            continue
        A.append(P[par]); B.append(P[j]); RA.append(subject.radii[par]); RB.append(subject.radii[j])  # noqa: E702
    for name in SPHERE_JOINTS:
        if name in subject.names:
            j = subject.names.index(name)
            A.append(P[j]); B.append(P[j]); RA.append(subject.radii[j]); RB.append(subject.radii[j])  # noqa: E702
    return np.array(A), np.array(B), np.array(RA), np.array(RB)


def sdf(points: np.ndarray, caps, smooth: float = 0.03) -> np.ndarray:
    """Smooth-union signed distance of ``(N, 3)`` points to the tapered capsules (negative inside)."""
    A, B, RA, RB = caps
    out = np.full(len(points), np.inf)
    for a, b, ra, rb in zip(A, B, RA, RB):
        ab = b - a
        L2 = float(ab @ ab)
        t = np.zeros(len(points)) if L2 < 1e-12 else np.clip((points - a) @ ab / L2, 0.0, 1.0)
        d = np.linalg.norm(points - (a + t[:, None] * ab), axis=1) - (ra + t * (rb - ra))
        if np.isinf(out).all():
            out = d
            continue
        # polynomial smooth minimum (blends joints into a body)
        h = np.clip(0.5 + 0.5 * (d - out) / smooth, 0.0, 1.0)
        out = d * (1 - h) + out * h - smooth * h * (1 - h)
    return out


def figure_mesh(subject: Subject, pose=None, resolution: int = 64, smooth: float = 0.03,
                yaw_deg: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Closed triangle mesh ``(V, 3) float64, (F, 3) int64`` of a posed figure (marching cubes).

    ``resolution`` voxels along the longest side of the padded bounding box.
    ``yaw_deg`` turns the whole figure about the up axis.
    """
    from skimage.measure import marching_cubes

    caps = capsules(subject, pose)
    A, B, RA, RB = caps
    pts = np.concatenate([A, B])
    r = np.concatenate([RA, RB])
    lo = (pts - r[:, None]).min(0) - 2 * smooth
    hi = (pts + r[:, None]).max(0) + 2 * smooth
    step = (hi - lo).max() / (resolution - 1)
    shape = np.ceil((hi - lo) / step).astype(int) + 3
    lo = lo - step
    axes = [lo[i] + step * np.arange(shape[i]) for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    field_ = sdf(grid, caps, smooth).reshape(shape)
    verts, faces, _, _ = marching_cubes(field_, level=0.0, spacing=(step,) * 3)
    verts = verts + lo
    faces = faces.astype(np.int64)  # skimage order gives outward normals for an SDF negative inside
    yaw = yaw_deg + (90.0 if subject.kind == "quadruped" else 0.0)  # quadrupeds face +x: side view
    if yaw:
        verts = verts @ _rot("y", yaw).T
    return verts, faces


def canonical_mesh(subject: Subject, resolution: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """The subject in its canonical pose (T-pose / standing)."""
    return figure_mesh(subject, None, resolution)
