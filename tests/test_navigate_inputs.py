"""``imu-learn navigate`` checks its side files before fusing: a positions-only ``--groundtruth`` is
refused first (exit 2, one line), with no track written (imu_learn.fuse.navigate.check_inputs)."""
from __future__ import annotations

import shutil
from pathlib import Path

from crops import CROP, SHIPPED
from imu_learn.cli import main

GT_REL = Path("mav0") / "state_groundtruth_estimate0" / "data.csv"


def test_positions_only_groundtruth_is_refused_before_fusion(tmp_path, capsys, monkeypatch):
    rec = tmp_path / "MH_04_difficult"
    shutil.copytree(SHIPPED / CROP / "mav0" / "imu0", rec / "mav0" / "imu0")
    rows = (SHIPPED / CROP / GT_REL).read_text().splitlines()[1::20]
    aiding = tmp_path / "fixes.tum"
    gt = tmp_path / "positions.tum"
    lines = [f"{int(r.split(',')[0]) * 1e-9:.9f} {' '.join(r.split(',')[1:4])}" for r in rows]
    aiding.write_text("\n".join(lines) + "\n")
    gt.write_text("\n".join(lines) + "\n")  # 4 columns: positions only

    from imu_learn.fuse import navigate as nav

    def no_fusion(*a, **k):
        raise AssertionError("fusion ran before the ground truth was checked")

    monkeypatch.setattr(nav, "fuse_run", no_fusion)
    out = tmp_path / "out"
    rc = main(["navigate", "--input", str(rec), "--aiding", str(aiding), "--aiding-kind", "position",
               "--groundtruth", str(gt), "--out", str(out), "--quiet", "--imu-noise", "1.7e-4,2e-3,1.9e-5,3e-3"])
    err = capsys.readouterr().err
    assert rc == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "--groundtruth" in lines[0] and "positions-only" in lines[0], err
    assert not out.exists() or not any(out.iterdir())
