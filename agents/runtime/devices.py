"""The torch device a run computes on: its name checked once, for training (``run.device``) and evaluation
(``--device``) alike. Imports torch: not re-exported by :mod:`agents.runtime` (whose face the reference venv reads).
"""

from __future__ import annotations

import torch

from agents.config import is_device_name


def check_device(name: str, key: str = "device") -> torch.device:
    """``cpu``, ``cuda`` or ``cuda:N``, usable on this machine (torch itself would fail later, on a CPU-only build
    with a bare AssertionError); a ValueError naming ``key``, the device and the valid choices otherwise. Training
    (``run.device``) and evaluation (``--device``) both check here."""
    if not is_device_name(name):
        raise ValueError(f"{key} {name!r} is invalid; valid choices: 'cpu', 'cuda', 'cuda:N'")
    if name != "cpu":
        if not torch.cuda.is_available():
            raise ValueError(f"{key} {name!r}, but CUDA is not available here; use 'cpu'")
        count, index = torch.cuda.device_count(), int(name[5:] or 0)
        if index >= count:
            raise ValueError(f"{key} {name!r}, but this machine has {count} CUDA device(s): cuda:0..cuda:{count - 1}")
    return torch.device(name)
