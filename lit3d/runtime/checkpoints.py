"""Reading a lit3d checkpoint and its metadata (task, data config, W&B id)."""
from __future__ import annotations

from pathlib import Path

from lit3d.runtime.errors import UserError


def read_checkpoint(ckpt_path: str | Path) -> tuple[dict, dict]:
    """``(checkpoint dict, its lit3d metadata)`` (task, data config, W&B id).

    Loads with ``weights_only=True`` (see :func:`lit3d.utils.checkpoints.load_checkpoint`): a
    checkpoint that pickles arbitrary objects is refused, never executed. A checkpoint written before its
    task's or data's settings were config nodes comes in today's layout (:func:`upgrade_checkpoint`).
    """
    from lit3d.utils.checkpoints import META_KEY, load_checkpoint

    ckpt = load_checkpoint(ckpt_path, UserError)
    meta = ckpt.get(META_KEY) if isinstance(ckpt, dict) else None
    if not isinstance(meta, dict):
        raise UserError(f"{Path(ckpt_path)}: not a lit3d checkpoint (no '{META_KEY}' metadata)")
    try:
        ckpt = upgrade_checkpoint(ckpt, str(ckpt_path))
    except ValueError as err:  # a parked canonical option it used: the message names the file, the key and the git tag
        raise UserError(str(err)) from err
    return ckpt, ckpt[META_KEY]


def upgrade_checkpoint(ckpt: dict, source: str | None = None) -> dict:
    """``ckpt`` (a loaded lit3d checkpoint dict) with its hyper-parameters, task config and data config in
    today's layout, by its task (:mod:`lit3d.completion.checkpoint_upgrade`,
    :mod:`lit3d.canonical.checkpoint_upgrade`, :mod:`lit3d.quality.checkpoint_upgrade`); in place, returned.
    Each upgrade is imported only for its own task (it imports that task's DataModule). ``source`` (the file)
    names it in the canonical upgrade's refusal of a parked option (a ValueError)."""
    from lit3d.utils.checkpoints import META_KEY

    name = ((ckpt.get(META_KEY) or {}).get("task") or {}).get("name")
    if name == "completion":
        from lit3d.completion.checkpoint_upgrade import upgrade_checkpoint as upgrade
    elif name == "canonical":
        from lit3d.canonical.checkpoint_upgrade import upgrade_checkpoint as canonical

        return canonical(ckpt, source)
    elif name == "quality":
        from lit3d.quality.checkpoint_upgrade import upgrade_checkpoint as upgrade
    else:
        return ckpt
    return upgrade(ckpt)


def read_checkpoint_meta(ckpt_path: str | Path) -> dict:
    """The lit3d metadata stored in a checkpoint (:func:`read_checkpoint`)."""
    return read_checkpoint(ckpt_path)[1]
