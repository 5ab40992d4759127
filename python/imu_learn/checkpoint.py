"""Checkpoints: everything needed to rebuild a run, loaded without executing pickled code.

A checkpoint is a ``torch.save`` of a dict holding only tensors and plain Python values (str, int,
float, bool, list, dict, None), and is always loaded with ``weights_only=True``. It stores the model
args (so the model can be rebuilt), the model weights (normalisation buffers included), the
optimiser state, the full run config, epoch, step, best metric, and the code version.
Writes go to a temporary file and are renamed into place, so a kill never leaves half a checkpoint
over a good one.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any, Dict, Optional

import torch

from imu_learn import __version__
from imu_learn.errors import ImuError
from imu_learn.model import ImuRefiner, ModelConfig

FORMAT = "imu_learn.checkpoint.v1"


class CheckpointError(ImuError):
    """A checkpoint is missing, corrupt, or of an unknown format."""


def save_checkpoint(
    path: Path,
    model: ImuRefiner,
    config: Dict[str, Any],
    epoch: int,
    step: int,
    best_metric: Optional[float],
    optimizer: Optional[torch.optim.Optimizer] = None,
    extra: Optional[Dict[str, Any]] = None,
) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    state = {
        "format": FORMAT,
        "code_version": __version__,
        "model_args": model.model_args(),
        "model": {k: v.detach().cpu() for k, v in model.state_dict().items()},
        "optimizer": None if optimizer is None else optimizer.state_dict(),
        "config": config,
        "epoch": int(epoch),
        "step": int(step),
        "best_metric": None if best_metric is None else float(best_metric),
        "extra": extra or {},
    }
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            torch.save(state, f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def load_checkpoint(path: Path, map_location: str = "cpu") -> Dict[str, Any]:
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(2, "No such file or directory", str(path))
    try:
        state = torch.load(path, map_location=map_location, weights_only=True)
    except Exception as e:  # torch raises many kinds for a damaged file; all mean "corrupt"
        raise CheckpointError(f"{path}: not a readable checkpoint ({type(e).__name__}: {e})") from e
    if not isinstance(state, dict) or state.get("format") != FORMAT:
        raise CheckpointError(f"{path}: not an imu_learn checkpoint of format {FORMAT}")
    return state


def model_from_checkpoint(state: Dict[str, Any]) -> ImuRefiner:
    model = ImuRefiner(ModelConfig(**state["model_args"]))
    model.load_state_dict(state["model"])
    model.eval()
    return model


def load_model(path: Path, map_location: str = "cpu") -> ImuRefiner:
    """The trained model of a checkpoint, in eval mode."""
    return model_from_checkpoint(load_checkpoint(path, map_location))
