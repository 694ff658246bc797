"""Meta-device model summaries: parameters, output shapes, activation memory per sample.

Nothing is allocated: the module is (copied and) moved to the ``meta`` device and run on meta
tensors, so paper-scale nets (a (B, 1, 256, 256, 256) generator output) cost no memory.

Activation memory = sum of the output bytes of every leaf module (modules without children),
skipping in-place modules (their output aliases their input), divided by the batch size. It is
an estimate of what autograd keeps for the backward pass: functional ops inside ``forward``
(``torch.cat``, ``F.interpolate``, SDPA internals) are not counted.
"""
from __future__ import annotations

import copy
import dataclasses
from collections.abc import Sequence

import torch
import torch.nn as nn

META = torch.device("meta")


def _is_shape(spec) -> bool:
    return isinstance(spec, (tuple, list, torch.Size)) and all(isinstance(v, int) for v in spec)


def _make(spec, dtype: torch.dtype):
    """A shape -> meta tensor; a list of shapes -> list of meta tensors."""
    if _is_shape(spec):
        return torch.zeros(tuple(spec), dtype=dtype, device=META)
    return [_make(s, dtype) for s in spec]


def _tensors(out) -> list[torch.Tensor]:
    if isinstance(out, torch.Tensor):
        return [out]
    if dataclasses.is_dataclass(out) and not isinstance(out, type):
        return [t for f in dataclasses.fields(out) for t in _tensors(getattr(out, f.name))]
    if isinstance(out, dict):
        return [t for v in out.values() for t in _tensors(v)]
    if isinstance(out, (list, tuple)):
        return [t for v in out for t in _tensors(v)]
    return []


def _shape_of(out):
    if isinstance(out, torch.Tensor):
        return tuple(out.shape)
    if dataclasses.is_dataclass(out) and hasattr(out, "logits"):
        return tuple(out.logits.shape)
    if isinstance(out, (list, tuple)):
        return [_shape_of(o) for o in out]
    return None


def _on_meta(module: nn.Module) -> bool:
    ts = list(module.parameters()) + list(module.buffers())
    return all(t.device.type == "meta" for t in ts)


def summarize(module: nn.Module, input_shapes: Sequence, dtype: torch.dtype = torch.float32) -> dict:
    """Run ``module`` on meta tensors of ``input_shapes`` (one entry per positional argument: a shape
    tuple, or a list of shapes for a list-of-tensors argument).

    Returns ``dict(params=int, output_shape=tuple | list, activation_bytes_per_sample=int)``; the
    batch size is ``input_shapes[0][0]``. ``module`` itself is not modified (a copy is moved to
    meta unless it already lives there in ``dtype``).
    """
    params = sum(p.numel() for p in module.parameters())
    float_dtypes = {p.dtype for p in module.parameters() if p.is_floating_point()}
    if not _on_meta(module) or float_dtypes - {dtype}:
        module = copy.deepcopy(module).to(device=META, dtype=dtype)
    first = input_shapes[0]
    batch = first[0] if _is_shape(first) else first[0][0]
    total = 0
    handles = []

    def hook(mod, inp, out):
        nonlocal total
        if getattr(mod, "inplace", False):
            return
        total += sum(t.numel() * t.element_size() for t in _tensors(out))

    for m in module.modules():
        if not any(True for _ in m.children()):
            handles.append(m.register_forward_hook(hook))
    try:
        with torch.no_grad():
            out = module(*[_make(s, dtype) for s in input_shapes])
    finally:
        for h in handles:
            h.remove()
    return dict(params=params, output_shape=_shape_of(out), activation_bytes_per_sample=total // max(batch, 1))


def _fmt_shape(s) -> str:
    if s is None:
        return "-"
    if isinstance(s, list):
        return ", ".join(_fmt_shape(x) for x in s)
    return "x".join(str(v) for v in s)


def format_summary_table(rows: list[dict]) -> str:
    """Markdown table: component, params, input shape, output shape, activation MB/sample.

    Row keys: ``component`` (or ``name``), ``params``, optional ``input``, ``output`` (or
    ``output_shape``), ``activation_bytes_per_sample`` (or ``activation_mb``).
    """
    header = ["component", "params", "input", "output", "activation MB/sample"]
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join(["---", "---:", "---", "---", "---:"]) + "|"]
    for r in rows:
        act = r.get("activation_mb")
        if act is None and r.get("activation_bytes_per_sample") is not None:
            act = r["activation_bytes_per_sample"] / 2**20
        cells = [
            str(r.get("component", r.get("name", "?"))),
            f"{int(r['params']):,}" if r.get("params") is not None else "-",
            _fmt_shape(r.get("input")),
            _fmt_shape(r.get("output", r.get("output_shape"))),
            f"{act:,.1f}" if act is not None else "-",
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
