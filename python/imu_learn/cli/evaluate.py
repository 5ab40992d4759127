"""``imu-learn evaluate``: fit methods on a train split and score them on a test split
(the protocol run is :mod:`imu_learn.eval.run`)."""
from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any, Callable, List, Optional, Sequence, Tuple

from imu_learn.baselines.registry import REGISTRY, is_method, known
from imu_learn.cli.common import add_data_root, run_command
from imu_learn.errors import ConfigError
from imu_learn.eval import report
from imu_learn.eval.run import load_eval_config, run_evaluation
from imu_learn.util.extras import require_extra

OVERRIDES = True
DESCRIPTION = """Fit methods on the train split and evaluate them on the held-out test split (paper
Section V): relative pose errors against horizon, AirIMU's short-horizon figures, a report folder
(report.md, CSV tables, plots, methods/); the summary table is printed to stdout."""
EPILOG = """examples:
  imu-learn evaluate --config configs/eval_default.toml            the shipped crops
  imu-learn evaluate --config configs/eval_euroc.toml --data-root ~/data --methods raw,traditional
  imu-learn evaluate --config configs/eval_euroc.toml --checkpoint runs/euroc/best.pt --reuse
overrides: --fit.steps 100 --eval.stride 20 --eval.horizons '[10, 200]' --data.split.test '["V1_01_easy"]'"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", type=Path, metavar="TOML",
                   help="eval config (configs/eval_*.toml); default: built-in defaults on the shipped crops")
    p.add_argument("--methods", metavar="NAME,...", help=f"comma list (default: the config's; known: {', '.join(REGISTRY)}; and profile:PATH, a "
                        "device profile's floor as it ships)")
    p.add_argument("--checkpoint", type=Path, metavar="PT",
                   help="also evaluate this `imu-learn fit` checkpoint (best.pt), as the row 'proposed (fit run)'")
    p.add_argument("--out", type=Path, metavar="DIR", help="report folder (default <reports_dir>/<config name>)")
    add_data_root(p, "the config's recording paths")
    p.add_argument("--reuse", action="store_true",
                   help="load fitted methods from the report folder when settings and split match")


def _stamp(path: Path) -> Optional[Tuple[int, int]]:
    """``path``'s inode and modification time (None: absent): a report swapped in is another file."""
    try:
        st = path.stat()
    except FileNotFoundError:
        return None
    return st.st_ino, st.st_mtime_ns


def run(args: argparse.Namespace, rest: List[str], keep: Callable[[Any], None]) -> int:
    t0 = time.time()
    require_extra("eval", "imu-learn evaluate")  # before any fitting: its report needs polars and matplotlib
    if any(a == "--data.data_root" or a.startswith("--data.data_root=") for a in rest):
        raise ConfigError("--data.data_root: set the data root with --data-root DIR (or IMU_LEARN_DATA)")
    if args.data_root:
        rest = [*rest, "--data.data_root", args.data_root]
    res = load_eval_config(args.config, rest)  # no --config: defaults, data = the fit defaults (crops)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()] if args.methods else list(res.cfg.methods)
    for m in methods:
        if not is_method(m):
            raise ConfigError(f"--methods: unknown method {m!r} (known: {known()})")
    if args.checkpoint is not None and not args.checkpoint.exists():
        raise FileNotFoundError(2, "No such file or directory", str(args.checkpoint))
    out = args.out or Path(res.cfg.reports_dir) / res.cfg.name
    report.check_out(out)  # a report.md (or CSV) of the user's in OUT: refused before any fitting
    before = _stamp(out / "report.md")

    def kept() -> str:
        now = _stamp(out / "report.md")
        report = ("no report is written" if now is None else "the report is the previous run's, whole" if now == before
                  else "the report is this run's, complete")
        return f"methods fitted so far are in {out / 'methods'} (rerun with --reuse); {report}"

    keep(kept)
    result = run_evaluation(res, methods, out, reuse=args.reuse, checkpoint=args.checkpoint,
                            progress=not args.quiet, t_start=t0)
    print(report.summary_text(result))
    print(f"report: {out / 'report.md'}")
    print(f"total wall time: {time.time() - t0:.1f} s")
    return 0


def main(argv: Optional[Sequence[str]] = None) -> int:
    """``imu-learn evaluate ARGV``."""
    return run_command("evaluate", argv)
