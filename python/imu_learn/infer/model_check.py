"""Does a trained model improve a recording? Raw vs refined relative pose error on one recording.

:func:`compare_with_raw` refines a recording's IMU exactly as ``imu-learn refine`` does (the same
reader values, :func:`imu_learn.infer.refiner.refine_arrays` with the checkpoint's windowing rule,
:mod:`imu_learn.infer.windowing`, the rule fit selected and scored it with),
puts ground truth on the raw and on the refined IMU by the same alignment (so both have identical
segments and stamps), and scores both with the final table's metric (:mod:`imu_learn.score.metrics`,
as ``fit.evaluate_table`` does): relative pose RMSE over n IMU samples, windows every ``stride``
samples from ``startup_bias_s`` seconds into each segment on, open loop and with a start-up bias
(fitted on each input's first ``startup_bias_s`` seconds against ground truth, raw and refined
separately) subtracted. Settings left as None come from the checkpoint's run config
(``data.eval_stride``, ``data.startup_bias_s``, ``data.gravity``). A checkpoint whose device profile
runs before the model (carried, not held by it) is refused: this check applies the model alone
(``imu-learn refine --checkpoint`` applies both, through :mod:`imu_learn.calib.correction`).

Used by tests/test_models.py to check that a shipped model does not make its test crop worse, and
handy for a model card::

    from imu_learn.infer.model_check import compare_with_raw
    r = compare_with_raw("models/euroc_adis16448.pt", "datasets/euroc/V1_01_easy", "euroc",
                         groundtruth="datasets/euroc/V1_01_easy/groundtruth_state_20hz.csv", max_gap_s=0.06)
    r["ratio"]["bias_removed"]["200"]   # {"rot": refined/raw, "trans": refined/raw}
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Union

import numpy as np

from imu_learn.data.formats import CsvColumns, read_recording
from imu_learn.data.loading import AlignOptions, align
from imu_learn.data.types import ImuData
from imu_learn.data.types import Segment as Seq
from imu_learn.errors import ConfigError
from imu_learn.infer.checkpoint import imu_record, load_checkpoint, model_from_checkpoint
from imu_learn.infer.refiner import refine_arrays
from imu_learn.infer.windowing import windowing_of
from imu_learn.nn.device import pick_device
from imu_learn.score.metrics import GRAVITY, variant_table, without_fitted_bias
from imu_learn.score.protocol import VARIANTS

PathLike = Union[str, Path]


def _table(seqs: List[Seq], horizons: Sequence[int], stride: int, startup_bias_s: float,
           gravity: float) -> Dict[str, Any]:
    fixed, _ = without_fitted_bias(seqs, startup_bias_s, gravity)
    return variant_table(seqs, fixed, horizons, stride, startup_bias_s, gravity)


def compare_with_raw(
    checkpoint: PathLike,
    recording_path: PathLike,
    format: str = "auto",
    groundtruth: Optional[PathLike] = None,
    horizons: Sequence[int] = (10, 200),
    *,
    window: Optional[int] = None,
    overlap: Optional[int] = None,
    stride: Optional[int] = None,
    startup_bias_s: Optional[float] = None,
    gravity: Optional[float] = None,
    max_gap_s: float = 0.05,
    device: str = "cpu",
    columns: Optional[CsvColumns] = None,
) -> Dict[str, Any]:
    """Raw vs refined relative pose RMSE of one recording (see the module docstring).

    Returns ``{"raw": T, "refined": T, "ratio": R, "segments", "samples", "settings"}`` where
    ``T[protocol][str(n)]`` is ``{"rot_rad", "rot_deg", "trans_m", "windows"}`` for protocol
    ``open_loop`` or ``bias_removed`` and ``R[protocol][str(n)] = {"rot", "trans"}`` is refined / raw
    (below 1: the model helps). ``window``/``overlap`` override the checkpoint's windowing rule (None: its own);
    ``max_gap_s`` splits the recording at ground-truth gaps as :class:`imu_learn.AlignOptions`;
    ``columns``: the recording is a user's CSV of this layout (its ground truth is ``groundtruth``).
    """
    state = load_checkpoint(Path(checkpoint))
    record = imu_record(state)
    if record["profile"] and not record["profile_in_model"]:  # its floor runs before the model: not here
        raise ConfigError(f"{checkpoint}: the model runs after the device profile it carries, which this check does "
                          "not apply; score it with imu-learn refine --checkpoint (which applies both) and "
                          "imu-learn evaluate")
    data = (state.get("config") or {}).get("data") or {}
    stride = int(stride if stride is not None else data.get("eval_stride", 10))
    startup_bias_s = float(startup_bias_s if startup_bias_s is not None else data.get("startup_bias_s", 10.0))
    gravity = float(gravity if gravity is not None else data.get("gravity", GRAVITY))

    model = model_from_checkpoint(state).to(pick_device(device))
    imu, gt = read_recording(Path(recording_path), format, None if groundtruth is None else Path(groundtruth),
                             columns=columns)
    rule = windowing_of(model).replace(window, overlap)
    gyro, acc = refine_arrays(model, imu.gyro, imu.acc, window=rule.window, overlap=rule.overlap)
    options = AlignOptions(max_gap_s=max_gap_s)
    name = Path(recording_path).name
    raw = align(imu, gt, options, name=name).segments
    refined = align(ImuData(t_ns=imu.t_ns, gyro=gyro, acc=acc), gt, options, name=name).segments
    if not raw:
        raise ValueError(f"{recording_path}: no segment with ground truth to score")
    assert all(np.array_equal(a.t_ns, b.t_ns) for a, b in zip(raw, refined))

    t_raw = _table(raw, horizons, stride, startup_bias_s, gravity)
    t_ref = _table(refined, horizons, stride, startup_bias_s, gravity)
    ratio = {col: {str(n): {"rot": t_ref[col][str(n)]["rot_rad"] / max(t_raw[col][str(n)]["rot_rad"], 1e-12),
                            "trans": t_ref[col][str(n)]["trans_m"] / max(t_raw[col][str(n)]["trans_m"], 1e-12)}
                   for n in horizons}
             for col in VARIANTS}
    return {
        "checkpoint": str(checkpoint),
        "recording": str(recording_path),
        "segments": [s.name for s in raw],
        "samples": int(sum(len(s) for s in raw)),
        "settings": {"horizons": [int(n) for n in horizons], "stride": stride, "startup_bias_s": startup_bias_s,
                     "gravity": gravity, "window": rule.window, "overlap": rule.overlap, "max_gap_s": max_gap_s},
        "raw": t_raw,
        "refined": t_ref,
        "ratio": ratio,
    }


def format_comparison(res: Dict[str, Any]) -> str:
    """The comparison as a small text table (rot in deg, trans in m)."""
    lines = [f"{res['recording']} ({res['samples']} samples) with {res['checkpoint']}",
             f"{'':10}{'':9}" + "".join(f"{c + ' n=' + n:>22}" for c in VARIANTS for n in res["raw"][c])]
    for row in ("raw", "refined"):
        for key, fmt in (("rot_deg", "{:.4f}"), ("trans_m", "{:.5f}")):
            cells = [fmt.format(res[row][c][n][key]) for c in VARIANTS for n in res[row][c]]
            lines.append(f"{row if key == 'rot_deg' else '':10}{key:9}" + "".join(f"{x:>22}" for x in cells))
    return "\n".join(lines)
