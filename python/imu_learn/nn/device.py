"""The one device picker: ``"auto"`` (CUDA when present, else the CPU), ``"cpu"``, ``"cuda"``, ``"cuda:N"``.

Every place that runs a model (training, refine, the baselines, model checks) resolves its device
setting here, so ``"auto"`` means the same everywhere and asking for CUDA on a machine without it is
one typed error (:class:`imu_learn.errors.ConfigError`) instead of a torch error at the first copy.
"""
from __future__ import annotations

import torch

from imu_learn.errors import ConfigError


def pick_device(spec: str, local_rank: int = 0) -> torch.device:
    """The torch device for ``spec``; ``local_rank`` picks the GPU of a distributed process under "auto"."""
    if spec == "auto":
        return torch.device(f"cuda:{local_rank}" if torch.cuda.is_available() else "cpu")
    if spec.startswith("cuda") and not torch.cuda.is_available():
        raise ConfigError(f"device: {spec!r} asked for but CUDA is not available")
    return torch.device(spec)
