"""Autocast's casts on the ``meta`` device, where ``torch.autocast`` does not run (no autocast device type 'meta').

The cost model (:mod:`lit3d.utils.step_cost`) counts training code on meta tensors; code that runs a part under
``torch.autocast(dtype=torch.bfloat16)`` would count that part in fp32 there. :class:`MetaAutocast` casts the
floating inputs of autocast's lower-precision ops (convolutions, matrix products, ``linear``, scaled dot-product
attention) to ``dtype``, above autograd (a ``TorchFunctionMode``, as autocast sits above autograd), so autograd
saves the cast tensors for backward as under autocast. Other ops run on what they get (type promotion: a bf16
activation times an fp32 parameter is fp32, as under autocast). Not emulated: autocast's fp32 list (``softmax``,
``sum``...), which runs those ops on fp32 inputs; the nets counted here call none of them on a cast activation
outside the attention kernel.

    with MetaAutocast(torch.bfloat16):
        d = critic(x, y)           # its convs and attention on bf16 inputs, as under torch.autocast
"""
from __future__ import annotations

import torch
import torch.nn.functional as F
from torch.overrides import TorchFunctionMode

# torch.autocast's lower-precision ops (CUDA and CPU lists) that nn modules reach through these functions
LOWER_PRECISION = {torch.conv1d, torch.conv2d, torch.conv3d, torch.conv_transpose1d, torch.conv_transpose2d,
                   torch.conv_transpose3d, torch.matmul, torch.mm, torch.bmm, torch.addmm, torch.baddbmm,
                   F.linear, F.scaled_dot_product_attention, torch.Tensor.matmul, torch.Tensor.__matmul__}


def _cast(v, dtype: torch.dtype):
    if isinstance(v, torch.Tensor) and v.is_floating_point() and v.dtype != dtype:
        return v.to(dtype)
    if isinstance(v, (list, tuple)):
        return type(v)(_cast(u, dtype) for u in v)
    return v


class MetaAutocast(TorchFunctionMode):
    """Runs :data:`LOWER_PRECISION` ops on ``dtype`` copies of their floating inputs (autocast's casts, on any device)."""

    def __init__(self, dtype: torch.dtype = torch.bfloat16):
        super().__init__()
        self.dtype = dtype

    def __torch_function__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        if func in LOWER_PRECISION:
            args, kwargs = _cast(args, self.dtype), {k: _cast(v, self.dtype) for k, v in kwargs.items()}
        return func(*args, **kwargs)
