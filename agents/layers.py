"""Building blocks shared by the model and the memory modules: the authors' initialisation and the compute dtype."""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn

HIDDEN_GAIN = math.sqrt(2)
POLICY_GAIN = 0.1
VALUE_GAIN = 1.0


def compute_dtype(weight: Tensor) -> torch.dtype:
    """The dtype a layer computes in: the autocast type when autocast is on, else its weights' own type."""
    device = weight.device.type
    return torch.get_autocast_dtype(device) if torch.is_autocast_enabled(device) else weight.dtype


def orthogonal(layer: nn.Module, gain: float) -> nn.Module:
    """Orthogonal weights with ``gain``, in place; returns the layer. Biases keep PyTorch's default init, except a
    recurrent layer's, which start at zero (as in the authors' code, baselines.md section 1)."""
    recurrent = isinstance(layer, nn.RNNBase)
    for name, param in layer.named_parameters():
        if "weight" in name:
            nn.init.orthogonal_(param, gain)
        elif "bias" in name and recurrent:
            nn.init.zeros_(param)
    return layer
