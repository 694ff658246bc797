"""FLOPs, dispatched ops and saved-for-backward bytes of a piece of training code, counted on any device
(the ``meta`` device: paper-scale nets at no memory or time cost).

:class:`CostCounter` is a ``TorchDispatchMode``: it sees every aten op that runs while it is active, the
backward passes' too (autograd sits above the dispatch mode), ``torch.autograd.grad(create_graph=True)``
included, which ``torch.utils.flop_counter.FlopCounterMode`` refuses (its module tracker). Each op's
FLOPs come from PyTorch's own formulas (``torch.utils.flop_counter.flop_registry``: mm, addmm, bmm,
convolution and its backward, the fused attention kernels), plus the CPU/meta attention kernel the
registry lacks; an op without a formula counts 0 FLOPs (element-wise work is not counted, as in
PyTorch's counter). Saved-for-backward bytes: :class:`SavedBytes` sums the storages autograd keeps for
backward (each storage once) while its graph lives.

    with CostCounter() as c, SavedBytes() as s:
        loss = net(x).sum(); loss.backward()
    c.flops, c.ops, s.peak
"""
from __future__ import annotations

import weakref
from collections import Counter

import torch
from torch.utils._python_dispatch import TorchDispatchMode
from torch.utils.flop_counter import flop_registry, sdpa_backward_flop_count, sdpa_flop_count

aten = torch.ops.aten


def _shape(t):
    return tuple(t.shape)


def _cpu_sdpa(q, k, v, *args, out_val=None, **kwargs) -> int:
    """``_scaled_dot_product_flash_attention_for_cpu`` (the kernel CPU and meta tensors take): q, k, v (B, H, N, d)."""
    return sdpa_flop_count(_shape(q), _shape(k), _shape(v))


def _cpu_sdpa_backward(grad_out, q, k, v, *args, out_val=None, **kwargs) -> int:
    return sdpa_backward_flop_count(_shape(grad_out), _shape(q), _shape(k), _shape(v))


EXTRA_FORMULAS = {}
for _name, _fn in (("_scaled_dot_product_flash_attention_for_cpu", _cpu_sdpa),
                   ("_scaled_dot_product_flash_attention_for_cpu_backward", _cpu_sdpa_backward)):
    if hasattr(aten, _name):
        EXTRA_FORMULAS[getattr(aten, _name)] = _fn

# metadata-only ops: not a kernel, not counted as one
_NO_KERNEL = {aten.detach, aten.view, aten._unsafe_view, aten.alias, aten.t, aten.transpose, aten.permute,
              aten.expand, aten.squeeze, aten.unsqueeze, aten.slice, aten.select, aten.as_strided, aten.split,
              aten.split_with_sizes, aten.unbind, aten.reshape, aten.flatten, aten.lift_fresh, aten.empty,
              aten.empty_like, aten.empty_strided}


class CostCounter(TorchDispatchMode):
    """Sums FLOPs (``torch.utils.flop_counter``'s formulas) and kernel-like ops over every aten op run while active.

    Attributes:
        flops: total FLOPs (a multiply-add counts 2).
        ops: aten ops that would launch a kernel (views, detaches and allocations excluded): a proxy of
            the kernel launches on a GPU.
        by_op: FLOPs per op name.
    """

    def __init__(self):
        super().__init__()
        self.flops = 0
        self.ops = 0
        self.by_op: Counter = Counter()

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        out = func(*args, **kwargs)
        packet = func._overloadpacket
        formula = EXTRA_FORMULAS.get(packet)
        if formula is not None:
            n = formula(*args, **kwargs, out_val=out)
        elif packet in flop_registry:
            n = flop_registry[packet](*args, **kwargs, out_val=out)
        else:
            n = 0
        if n:
            self.flops += int(n)
            self.by_op[str(packet).split(".")[-1]] += int(n)
        if packet not in _NO_KERNEL and not func.is_view:
            self.ops += 1
        return out


class SavedBytes:
    """Bytes of the tensors autograd saves for backward (activations; parameters too, once each), while active.

    A storage is counted once while any graph still holds it (keyed by its storage object, so it works on
    the ``meta`` device, where every data pointer is 0); :attr:`total` is what is held now, :attr:`peak`
    the highest total seen.
    """

    def __init__(self):
        self.live: dict[int, list] = {}  # storage -> [bytes, references]
        self.total = 0
        self.peak = 0
        self._ctx = None

    def _pack(self, t: torch.Tensor):
        storage = t.untyped_storage()
        key = storage._cdata
        entry = self.live.setdefault(key, [storage.nbytes(), 0])
        if entry[1] == 0:
            self.total += entry[0]
            self.peak = max(self.peak, self.total)
        entry[1] += 1
        handle = _Handle(t)
        weakref.finalize(handle, self._release, key)
        return handle

    def _release(self, key: int) -> None:
        entry = self.live.get(key)
        if entry is None:
            return
        entry[1] -= 1
        if entry[1] == 0:
            self.total -= entry[0]
            del self.live[key]

    def __enter__(self):
        self._ctx = torch.autograd.graph.saved_tensors_hooks(self._pack, lambda h: h.tensor)
        self._ctx.__enter__()
        return self

    def __exit__(self, *exc) -> None:
        self._ctx.__exit__(*exc)


class _Handle:
    __slots__ = ("tensor", "__weakref__")

    def __init__(self, tensor: torch.Tensor):
        self.tensor = tensor
