"""The GRU recurrence over packed sequences, with a backward pass written for the CPU.

``nn.GRU``'s packed CPU path differentiates step by step: every step adds its own slice of the recurrent weight
gradient (a 3H x H matrix) and scatters its input-gate gradient into a zero tensor of the whole batch. Here the
input projection of all steps is one matrix product done by the caller (under autocast: one bfloat16 product), the
recurrence keeps only what it must do step by step, and the backward computes every per-step coefficient for all
steps at once and the recurrent weight gradient as one product. The maths is ``nn.GRU``'s (PyTorch's gate layout:
reset, update, new), checked against it in the tests; its parameters stay in the ``nn.GRU`` module.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor, nn
from torch.nn import functional as F


class _PackedGRURecurrence(torch.autograd.Function):
    """Given the input gates of all steps (N, 3H) in packed order (``batch_sizes`` rows per step, non-increasing),
    run h_t = GRU(h_{t-1}) from ``h0`` (S, H); returns every step's output (N, H) in float32. The recurrent product
    runs in ``w_hh``'s dtype (bfloat16 under mixed precision), everything else in float32."""

    @staticmethod
    def forward(ctx, gates_x: Tensor, h0: Tensor, w_hh: Tensor, b_hh: Tensor, batch_sizes: tuple[int, ...]) -> Tensor:
        hidden = h0.shape[1]
        with torch.autocast(h0.device.type, enabled=False):  # the dtypes are chosen here, explicitly
            out, h_prev_all, n_all, ghn_all = (gates_x.new_empty(gates_x.shape[0], hidden) for _ in range(4))
            rz_all = gates_x.new_empty(gates_x.shape[0], 2 * hidden)
            w_t, h, start = w_hh.t(), h0, 0
            for b in batch_sizes:
                end = start + b
                h = h[:b]  # sequences are sorted longest first: the ones still running are the first b
                h_prev_all[start:end] = h
                gh = torch.addmm(b_hh, h.to(w_hh.dtype), w_t).float()
                gx = gates_x[start:end]
                rz = torch.sigmoid(gx[:, : 2 * hidden] + gh[:, : 2 * hidden], out=rz_all[start:end])
                ghn = ghn_all[start:end]
                ghn.copy_(gh[:, 2 * hidden :])
                n = torch.tanh(torch.addcmul(gx[:, 2 * hidden :], rz[:, :hidden], ghn), out=n_all[start:end])
                h = torch.addcmul(n, rz[:, hidden:], h - n, out=out[start:end])  # (1 - z) * n + z * h
                start = end
        ctx.batch_sizes, ctx.h0_shape, ctx.bias_dtype = batch_sizes, h0.shape, b_hh.dtype
        ctx.save_for_backward(w_hh, h_prev_all, rz_all, n_all, ghn_all)
        return out

    @staticmethod
    def backward(ctx, grad_out: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor, None]:
        w_hh, h_prev, rz, n, ghn = ctx.saved_tensors
        hidden = h_prev.shape[1]
        r, z = rz[:, :hidden], rz[:, hidden:]
        # With dh the gradient reaching a step's output: d(new-gate pre-activation) = dh * a, and the gradient of
        # the recurrent gate products (reset, update, new) is dh * coef, for all steps at once.
        a = (1 - z) * (1 - n * n)
        coef = torch.cat((a * ghn * r * (1 - r), (h_prev - n) * z * (1 - z), a * r), dim=1)
        d_gh, dh_all = torch.empty_like(coef), torch.empty_like(h_prev)
        ends = torch.tensor(ctx.batch_sizes).cumsum(0).tolist()
        carry = None  # the gradient that flows into the previous step's state
        for b, end in zip(reversed(ctx.batch_sizes), reversed(ends), strict=True):
            start = end - b
            dh = dh_all[start:end]
            dh.copy_(grad_out[start:end])
            if carry is not None:
                dh[: carry.shape[0]] += carry
            step_gh = torch.mul(dh.repeat(1, 3), coef[start:end], out=d_gh[start:end])
            carry = dh * z[start:end] + (step_gh.to(w_hh.dtype) @ w_hh).float()
        d_h0 = grad_out.new_zeros(ctx.h0_shape)
        d_h0[: carry.shape[0]] = carry
        d_gates_x = d_gh.clone()
        d_gates_x[:, 2 * hidden :] = dh_all * a
        d_w_hh = d_gh.t().to(w_hh.dtype) @ h_prev.to(w_hh.dtype)
        return d_gates_x, d_h0, d_w_hh, d_gh.sum(0).to(ctx.bias_dtype), None


def packed_gru(
    rnn: nn.GRU, inputs: Tensor, h0: Tensor, batch_sizes: Sequence[int], dtype: torch.dtype, layer: int = 0
) -> Tensor:
    """Run layer ``layer`` of the GRU ``rnn`` over packed ``inputs`` (N, F) from ``h0`` (1, S, H), computing the
    matrix products in ``dtype``; returns the outputs (N, H) in float32, in packed order."""
    w_ih, w_hh, b_ih, b_hh = (
        getattr(rnn, f"{name}_l{layer}") for name in ("weight_ih", "weight_hh", "bias_ih", "bias_hh")
    )
    gates_x = F.linear(inputs.to(dtype), w_ih.to(dtype), b_ih.to(dtype)).float()
    sizes = tuple(int(b) for b in batch_sizes)
    return _PackedGRURecurrence.apply(gates_x, h0[0].float(), w_hh.to(dtype), b_hh.to(dtype), sizes)
