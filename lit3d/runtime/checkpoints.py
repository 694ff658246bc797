"""Reading a lit3d checkpoint and its metadata (task, data config, W&B id)."""
from __future__ import annotations

from pathlib import Path

from lit3d.runtime.errors import UserError


def read_checkpoint(ckpt_path: str | Path) -> tuple[dict, dict]:
    """``(checkpoint dict, its lit3d metadata)`` (task, data config, W&B id).

    Loads with ``weights_only=True`` (see :func:`lit3d.utils.checkpoints.load_checkpoint`): a
    checkpoint that pickles arbitrary objects is refused, never executed. A canonical checkpoint comes in
    today's config layout (:func:`lit3d.canonical.checkpoint_upgrade.upgrade_checkpoint`).
    """
    from lit3d.utils.checkpoints import META_KEY, load_checkpoint

    ckpt = load_checkpoint(ckpt_path, UserError)
    meta = ckpt.get(META_KEY) if isinstance(ckpt, dict) else None
    if not isinstance(meta, dict):
        raise UserError(f"{Path(ckpt_path)}: not a lit3d checkpoint (no '{META_KEY}' metadata)")
    if (meta.get("task") or {}).get("name") == "canonical":  # maybe written before its settings were nodes
        from lit3d.canonical.checkpoint_upgrade import upgrade_checkpoint  # (imports its DataModule: only here)

        try:
            ckpt = upgrade_checkpoint(ckpt, str(ckpt_path))
        except ValueError as err:  # a parked option it used: the message names the file, the key and the git tag
            raise UserError(str(err)) from err
    return ckpt, ckpt[META_KEY]


def read_checkpoint_meta(ckpt_path: str | Path) -> dict:
    """The lit3d metadata stored in a checkpoint (:func:`read_checkpoint`)."""
    return read_checkpoint(ckpt_path)[1]
