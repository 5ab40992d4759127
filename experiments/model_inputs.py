"""The statistics a shipped model's guard reads (``inputs``), recorded into checkpoints trained before
the trainer recorded them: the raw IMU statistics of each segment of the model's training split, as its
saved config reads it, and what the model adds to each (:func:`imu_learn.infer.checkpoint.with_training_inputs`,
the trainer's own record). With them ``refine`` and ``navigate`` warn when a recording does not look like
the model's training data (another device at the same rate: the EuRoC model on a TUM-VI room).

    IMU_LEARN_DATA=<root> python experiments/model_inputs.py models/euroc_adis16448.pt [...] [--write]

Writes: with ``--write``, each checkpoint in place (atomically; its weights and other entries unchanged),
else nothing; prints per model the segments and the largest residual RMS.
Data: the recordings of each checkpoint's training split under the data root.
"""
from __future__ import annotations

import argparse
import os
import sys
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from imu_learn.data.config import DataConfig
from imu_learn.data.splits import make_split
from imu_learn.infer.checkpoint import load_checkpoint, with_training_inputs, write_checkpoint
from imu_learn.settings import from_dict, merge


def record(path: Path, data_root: Path, write: bool) -> None:
    state = load_checkpoint(path)
    # the saved config's data part alone (a model's optimiser settings of an older version need not validate)
    data = merge(asdict(DataConfig()), {**((state.get("config") or {}).get("data") or {}), "data_root": str(data_root)})
    segs = make_split(from_dict(DataConfig, data)).train
    new = with_training_inputs(state, [(s.name, s.t_ns, s.gyro, s.acc) for s in segs])
    res = new["inputs"]["residual_rms"]
    top = np.max([r["gyro"] for r in res], axis=0), np.max([r["acc"] for r in res], axis=0)
    print(f"{path}: {len(segs)} training segments; largest residual RMS gyro {np.round(top[0], 5).tolist()} rad/s, "
          f"acc {np.round(top[1], 4).tolist()} m/s^2" + ("; written" if write else ""))
    if write:
        write_checkpoint(path, new)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("checkpoints", nargs="+", type=Path)
    ap.add_argument("--data-root", type=Path, default=Path(os.environ.get("IMU_LEARN_DATA", "data")))
    ap.add_argument("--write", action="store_true")
    a = ap.parse_args()
    torch.set_num_threads(1)
    for p in a.checkpoints:
        record(p, a.data_root, a.write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
