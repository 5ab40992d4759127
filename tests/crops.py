"""The shipped EuRoC crops as the tests load them; the fixtures ``crop``, ``crop_easy`` and
``crop_split`` in conftest.py hand these out, ``cut`` takes samples [a, b) of any of them."""
from __future__ import annotations

from pathlib import Path
from typing import Tuple

from imu_learn.data.types import Segment

REPO = Path(__file__).resolve().parent.parent
SHIPPED = REPO / "datasets"
CROP = "euroc/MH_04_difficult"  # the crop fusion runs on (relative to the data root)
EASY = "euroc/MH_01_easy"  # the crop the baselines and labels tests fit and score on
SPLIT = (3000, 4000)  # crop_split: samples [0, 3000) train (15 s), [3000, 4000) validation (5 s)


def cut(seq: Segment, a: int, b: int) -> Segment:
    """Samples [a, b) of ``seq`` (views, not copies), same name."""
    return Segment(seq.name, seq.t_ns[a:b], seq.gyro[a:b], seq.acc[a:b], seq.p[a:b], seq.v[a:b], seq.q_wxyz[a:b])


def load_crop(root: Path = SHIPPED) -> Segment:
    """MH_04_difficult as fusion loads it: ground truth from the state estimate, gaps up to 50 ms
    bridged, the longest gap-free segment (the whole 60 s)."""
    from imu_learn import AlignOptions, load_recording

    rec = load_recording(root / CROP, "euroc", groundtruth=root / CROP / "mav0/state_groundtruth_estimate0/data.csv",
                         options=AlignOptions(max_gap_s=0.05))
    return max(rec.segments, key=len)


def load_easy(root: Path = SHIPPED) -> Segment:
    """MH_01_easy with the loader's defaults, its first segment (the whole 60 s)."""
    from imu_learn import load_sequence

    return load_sequence(root / EASY)[0]


def split(seq: Segment) -> Tuple[Segment, Segment]:
    a, b = SPLIT
    return cut(seq, 0, a), cut(seq, a, b)


# A run config over the shipped crops with paths relative to a data root (a folder holding
# euroc/<SEQ>); ``{data_root}`` is a line of the [data] table (empty, or data_root = "...").
CROP_RUN_TOML = """
name = "crops"
[data]
{data_root}
[[data.roots]]
path = "euroc/MH_01_easy"
[[data.roots]]
path = "euroc/V1_01_easy"
groundtruth = "euroc/V1_01_easy/groundtruth_state_20hz.csv"
max_gap_s = 0.06
[data.split]
train = ["MH_01_easy[0:0.8]"]
val = ["MH_01_easy[0.8:1]"]
test = ["V1_01_easy"]
"""


def whole_pass(model, g, a):
    """A refiner over the whole sequence in one forward pass (float64 raw + float32 correction, as
    the windowing rule composes it): the oracle stitched outputs are compared with."""
    import numpy as np
    import torch

    raw = np.c_[g, a]
    x = torch.from_numpy(raw.astype(np.float32))[None]
    with torch.no_grad():
        corr = (model(x) - x)[0].numpy()
    return raw + corr.astype(np.float64)
