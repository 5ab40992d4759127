"""Online fusion latency, measured now on this machine and printed as a markdown table.

Each recording is streamed sample by sample (``imu_learn.fuse.experiments.online.stream``): the raw sample, the
input's refiner (``raw`` passes it through; ``proposed``: the causal model's ``step()``; ``learned``:
``WindowedStepper``, the bidirectional covariance model run once per completed window of the
checkpoint's windowing rule, releasing that window's settled samples with their variances, plus the
tlio-style displacement factors where that model is present), then ``IncrementalFusion.add_sample``
for each released sample (preintegration, and at keyframes the IMU and aiding factors and an iSAM2
update where a fix arrived). Aiding: simulated 1 Hz position fixes (sigma 0.1 m; the draw of
``configs/fuse_euroc.toml``'s ``gnss_1hz`` scenario, noise seed 0). Recordings: the shipped V1_01_easy
crop (60 s) and, when the data root has it, the whole V1_01_easy.

    python bench/bench_fuse_online.py [--checkpoint CAUSAL.pt] [--learned COV.pt] [--displacement TLIO.pt]
                                      [--inputs raw,proposed,learned] [--data-root DIR] [--threads 1] [--quick]

Per-sample latency is the wall time (``perf_counter_ns``) of the whole per-sample path, model step
included (``learned``: a window's model call is in the latency of the sample that completes it, so it
shows in p99 and max; "model run" is the latency at those samples); "update" is that latency at the samples where iSAM2 was updated (a fix arrived, or the
stream ended). The real-time factor is the recording's duration over the streaming loop's wall
time: above 1 the loop keeps up with the IMU (a sample whose update takes longer than the 5 ms
between 200 Hz samples is absorbed by an input buffer, which the following fast samples drain). The
algorithmic delay (``learned``) is each sample's wait for its window: the samples (and ms of stamps)
from its arrival to the arrival that released it to the fusion; the output delay adds the queue's.
Nothing is hard-coded: every figure printed is measured by this run.
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
# No causal model ships (the one this recipe trains is at raw IMU's accuracy: README); train it with
# python -m imu_learn.fit --config configs/euroc_paper.toml --name euroc_causal_s0 --model.causal true --model.fir_taps 0
CAUSAL_CANDIDATES = ("runs/euroc_causal_s0/best.pt",)
# The learned input of configs/fuse_euroc_learned.toml: its covariance model, and the tlio-style model
# its displacement factors come from (written by imu-learn evaluate, see docs/experiments/fusion.md).
LEARNED_DEFAULT = "models/euroc_adis16448_cov.pt"
DISPLACEMENT_DEFAULT = "reports/euroc_paper_tlio/methods/tlio-style.pt"
INPUTS = ("raw", "proposed", "learned")


def default_checkpoint() -> str:
    for c in CAUSAL_CANDIDATES:
        if (REPO / c).is_file():
            return str(REPO / c)
    return ""


def recordings(data_root: str, quick: bool):
    """(label, FuseConfig, RecordingSpec) of the crop and, where present, the whole recording."""
    from imu_learn.fuse.experiments.config import FuseConfig, RecordingSpec

    spec = RecordingSpec("euroc/V1_01_easy", "euroc", "euroc/V1_01_easy/groundtruth_state_20hz.csv", max_gap_s=0.06)
    out = [("V1_01_easy crop (shipped)", FuseConfig(data_root=str(REPO / "datasets")), spec)]
    if not quick:
        if data_root and (Path(data_root) / spec.path / "mav0").is_dir():
            out.append(("V1_01_easy (whole)", FuseConfig(data_root=data_root), spec))
        else:
            print(f"(no {spec.path} under the data root {data_root or '(none: set IMU_LEARN_DATA)'}: the crop only)")
    return out


def learned_models(path: str, displacement: str, wanted: bool, load):
    """(the learned input's covariance model or None, the tlio-style model or None), each announced."""
    if not wanted:
        return None, None
    if not path or not Path(path).is_file():
        print(f"learned: no covariance checkpoint at {path or '(none)'}: not timed")
        return None, None
    model = load(Path(path))
    w = model.windowing
    print(f"learned: {path} ({sum(p.numel() for p in model.parameters())} parameters, bidirectional, covariance head), "
          f"window {w.window} samples, overlap {w.overlap}: one model call per {w.window - w.overlap} samples")
    tlio = None
    if displacement and Path(displacement).is_file():
        from imu_learn.baselines.registry import load_method_class

        tlio = load_method_class("tlio-style")().load(Path(displacement))
        print(f"learned: + displacement factors of {displacement} (window {tlio.window} samples, one factor per 1 s)")
    else:
        print(f"learned: no tlio-style model at {displacement or '(none)'}: refined samples + learned variances only")
    return model, tlio


def displacement_hook(tlio, seq):
    """A fresh displacement-factor hook of the tlio-style model for one run (None without a model)."""
    if tlio is None:
        return None
    from imu_learn.fuse.factors.displacement import displacement_factors_for

    return displacement_factors_for(tlio, seq.t_ns, seq.gyro, seq.acc)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--checkpoint", default=None,
                    help=f"causal checkpoint for 'proposed' (default: the first of {', '.join(CAUSAL_CANDIDATES)} "
                         "that exists)")
    ap.add_argument("--data-root", default=os.environ.get("IMU_LEARN_DATA", ""),
                    help="data root holding euroc/V1_01_easy (default IMU_LEARN_DATA)")
    ap.add_argument("--learned", default=str(REPO / LEARNED_DEFAULT),
                    help=f"covariance checkpoint for 'learned' (default {LEARNED_DEFAULT}; not timed when missing)")
    ap.add_argument("--displacement", default=str(REPO / DISPLACEMENT_DEFAULT),
                    help=f"tlio-style model whose displacement factors 'learned' adds (default {DISPLACEMENT_DEFAULT} "
                         "when present; '' for none)")
    ap.add_argument("--inputs", default=",".join(INPUTS), help=f"inputs to time (default {','.join(INPUTS)})")
    ap.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    ap.add_argument("--quick", action="store_true", help="the shipped crop only")
    args = ap.parse_args(argv)

    import torch

    torch.set_num_threads(args.threads)
    from scipy.spatial.transform import Rotation

    from imu_learn.core.quat import wxyz_to_xyzw
    from imu_learn.fuse.experiments.batch import aiding_rng, load_recording_for_fusion, make_aiding
    from imu_learn.fuse.experiments.config import ScenarioSpec
    from imu_learn.fuse.experiments.online import machine, stream
    from imu_learn.fuse.score import score_online
    from imu_learn.fuse.settings import FusionSettings
    from imu_learn.infer.streaming import load_causal_model, load_learned_model

    ckpt = args.checkpoint if args.checkpoint is not None else default_checkpoint()
    model = None
    if ckpt and Path(ckpt).is_file():
        model = load_causal_model(Path(ckpt))
    m = machine()
    print(f"online fusion: {m['cpu']}, {m['cores_available']} cores available, torch threads {m['torch_threads']}, "
          f"RAYON_NUM_THREADS={m['RAYON_NUM_THREADS'] or '(unset)'}, OMP_NUM_THREADS={m['OMP_NUM_THREADS'] or '(unset)'}, "
          f"python {m['python']}, torch {torch.__version__}")
    if model is None:
        # Latency does not depend on the weights: without a trained causal checkpoint the same
        # architecture, freshly initialised, is timed (its RMSE is then meaningless, and labelled so).
        from imu_learn.nn.model import ImuRefiner, ModelConfig

        torch.manual_seed(0)
        model = ImuRefiner(ModelConfig(causal=True, fir_taps=0)).eval()
        print(f"proposed: no causal checkpoint ({', '.join(CAUSAL_CANDIDATES)} not found; pass --checkpoint CAUSAL.pt): "
              f"an UNTRAINED causal model of the recipe's architecture is timed ({sum(p.numel() for p in model.parameters())} "
              "parameters; latency only, its RMSE says nothing)")
    else:
        print(f"proposed: causal checkpoint {ckpt} ({sum(p.numel() for p in model.parameters())} parameters, "
              f"hidden {model.cfg.hidden}, layers {model.cfg.layers})")
    inputs = [i for i in args.inputs.split(",") if i]
    if set(inputs) - set(INPUTS):
        ap.error(f"--inputs: of {', '.join(INPUTS)}")
    learned, tlio = learned_models(args.learned, args.displacement, "learned" in inputs, load_learned_model)
    models = {"raw": None, "proposed": model, "learned": learned}
    inputs = [i for i in inputs if i != "learned" or learned is not None]
    scn = ScenarioSpec("gnss_1hz", "position", 1.0, 0.1)
    rows = []
    for label, cfg, spec in recordings(args.data_root, args.quick):
        seq, noise, leica = load_recording_for_fusion(cfg, spec)
        aiding = make_aiding(scn, seq, leica, aiding_rng(0, Path(spec.path).name, scn))
        R0 = Rotation.from_quat(wxyz_to_xyzw(seq.q_wxyz[0])).as_matrix()
        for name in inputs:
            hook = displacement_hook(tlio, seq) if name == "learned" else None
            res = stream(seq.t_ns, seq.gyro, seq.acc, (R0, seq.p[0], seq.v[0]), [aiding], models[name],
                         FusionSettings(noise, cfg.gravity, cfg.keyframe_hz), extra_factors=hook)
            st = res.stats()
            sc = score_online(res, seq.t_ns, seq.p, seq.q_wxyz)
            rows.append((label, name, st, sc))
            print(f"  {label} / {name}: done in {st['wall_s']:.1f} s", file=sys.stderr)
    print()
    print("| recording | input | samples (s) | per-sample latency median / p99 / max | keyframe update median / p99 (n) "
          "| model run median / max (n) | samples slower than 5 ms | algorithmic delay median / max | "
          "max output delay (algorithmic + queued) | real-time factor | causal position RMSE | torch threads |")
    print("|---|---|---:|---|---|---|---:|---|---:|---:|---:|---:|")
    for label, name, st, sc in rows:
        ps, up, mr, ad = st["per_sample"], st["update"], st["model_run"], st["algorithmic_delay"]
        runs = f"{mr['median_us'] / 1e3:.1f} ms / {mr['max_us'] / 1e3:.1f} ms ({mr['count']})" if mr["count"] else "-"
        print(f"| {label} | {name} | {st['samples']:,} ({st['duration_s']:.0f} s) | "
              f"{ps['median_us']:.0f} µs / {ps['p99_us']:.0f} µs / {ps['max_us'] / 1e3:.1f} ms | "
              f"{up['median_us'] / 1e3:.1f} ms / {up['p99_us'] / 1e3:.1f} ms ({up['count']}) | {runs} | "
              f"{st['over_period']:,} | {ad['median_samples']:.0f} samples ({ad['median_us'] / 1e3:.0f} ms) / "
              f"{ad['max_samples']} ({ad['max_us'] / 1e3:.0f} ms) | {st['output_delay']['max_us'] / 1e3:.1f} ms | "
              f"{st['real_time_factor']:.1f}× | {sc['pos_rmse_m']:.3f} m | {m['torch_threads']} |")
    print()
    print("Aiding: simulated 1 Hz position fixes (sigma 0.1 m). Latency: perf_counter_ns around the refiner (model "
          "step, or learned's buffering and, at a completed window, its model call) and IncrementalFusion.add_sample of "
          "the samples it released, per arriving sample; update: the samples where iSAM2 was updated (a Gauss-Newton "
          "step; after a coast over 2 s a batch re-solve); model run: the samples whose path ran learned's model on a "
          "window; samples slower than 5 ms: those slower than the IMU's sample period (200 Hz); algorithmic delay: a "
          "sample's wait for its window (learned), from its arrival to its release to the fusion, in samples and in "
          "stamps; max output delay: the longest time from a sample's stamp to its causal state if samples queue while "
          "the loop is busy, the algorithmic delay included; real-time factor: recording duration / streaming wall time.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
