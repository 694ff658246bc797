"""Slim a trained lit3d checkpoint into a zoo file: what inference needs, nothing of the training.

    info = slim_checkpoint("logs/zoo_completion/train/checkpoints/best-027.ckpt", "lit3d/zoo/completion-furniture.pt",
                           drop_prefixes=("critic.",))

A Lightning checkpoint carries optimiser states, loops and callbacks beside the weights (the demo's completion
checkpoint: 97 MB). The slim copy keeps ``hyper_parameters``, the lit3d metadata (task, data config) and the
``state_dict``; floating-point tensors of at least :data:`HALF_MIN_NUMEL` elements are stored in fp16 (small
ones, such as the validation-chosen threshold, stay as they were), and whole sub-modules that only training
uses (the completion critic) can be left out. What was done is written into the metadata (``slim``), so that
:func:`load_state` knows which missing keys are expected; loading casts fp16 back to the module's dtype.
"""
from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from lit3d.utils.checkpoints import META_KEY, load_checkpoint
from lit3d.utils.io import atomic_write_bytes

HALF_MIN_NUMEL = 1024          # smaller float tensors (thresholds, norms' scalars) keep their dtype
KEEP_KEYS = ("hyper_parameters", "state_dict", META_KEY, "pytorch-lightning_version")


def slim_checkpoint(src: str | Path, dst: str | Path, *, half: bool = True,
                    drop_prefixes: Sequence[str] = (), data_overrides: Mapping[str, Any] | None = None) -> dict:
    """Write the slim copy of checkpoint ``src`` to ``dst`` (atomically; ``dst`` must not be ``src``).
    ``data_overrides``: top-level keys of the stored data config to replace (a path on the training
    machine, such as the body task's ``faust_root``, set to None: the user gives their own).
    Returns the ``slim`` record: ``{"from": name of src, "half": bool, "dropped": [prefixes],
    "dropped_tensors": n, "bytes": size of dst}``."""
    import torch

    src, dst = Path(src), Path(dst)
    if src.resolve() == dst.resolve():
        raise ValueError(f"{dst}: the slim copy would replace its own checkpoint")
    ckpt = load_checkpoint(src)
    missing = [k for k in ("hyper_parameters", "state_dict", META_KEY) if k not in ckpt]
    if missing:
        raise ValueError(f"{src}: not a lit3d training checkpoint (no {', '.join(missing)})")
    state, dropped = {}, 0
    for key, value in ckpt["state_dict"].items():
        if any(key.startswith(p) for p in drop_prefixes):
            dropped += 1
            continue
        if half and value.is_floating_point() and value.numel() >= HALF_MIN_NUMEL:
            value = value.to(torch.float16)
        state[key] = value.clone()
    record = {"from": src.name, "half": bool(half), "dropped": list(drop_prefixes), "dropped_tensors": dropped}
    out = {k: ckpt[k] for k in KEEP_KEYS if k in ckpt}
    out["state_dict"] = state
    out[META_KEY] = {**dict(ckpt[META_KEY]), "slim": record}
    if data_overrides:
        out[META_KEY]["data"] = {**dict(out[META_KEY].get("data") or {}), **dict(data_overrides)}
    buf = io.BytesIO()
    torch.save(out, buf)
    atomic_write_bytes(dst, buf.getvalue())
    return {**record, "bytes": dst.stat().st_size}


def load_state(module, ckpt: dict) -> None:
    """``module.load_state_dict(ckpt["state_dict"])``; for a slim checkpoint (its metadata has ``slim``) the
    keys under its dropped prefixes may be missing, and no other key may be. fp16 tensors are cast to the
    module's own dtypes by ``load_state_dict``'s copy."""
    slim = (ckpt.get(META_KEY) or {}).get("slim")
    if not slim or not slim.get("dropped"):
        module.load_state_dict(ckpt["state_dict"])
        return
    result = module.load_state_dict(ckpt["state_dict"], strict=False)
    prefixes = tuple(slim["dropped"])
    unexpected = list(result.unexpected_keys) + [k for k in result.missing_keys if not k.startswith(prefixes)]
    if unexpected:
        raise ValueError(f"slim checkpoint does not match its task: {', '.join(unexpected[:5])}")
