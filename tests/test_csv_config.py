"""A user's CSV as a config root (``format = "csv-columns"``): the recording reads through its column map and
units as the commands' options read it, so ``imu-learn evaluate`` and ``fit`` score and train on one's own
files (docs/your-device.md). Oracle: the same recording through its ASL layout."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crops import SHIPPED
from imu_learn.data.formats import read_recording
from imu_learn.data.splits import make_split
from imu_learn.errors import ConfigError
from imu_learn.train.config import load_config

REC = SHIPPED / "euroc" / "V1_01_easy"


def user_files(tmp_path):
    """V1_01's crop as a logger writes it (seconds, a temperature column, deg/s, g, ';'), its pose TUM beside."""
    imu, _ = read_recording(REC, "euroc", REC / "groundtruth_pose.tum")
    rows = [f"{t * 1e-9:.9f};25.0;{';'.join(f'{math.degrees(x):.9f}' for x in g)};"
            f"{';'.join(f'{x / 9.80665:.9f}' for x in a)}" for t, g, a in zip(imu.t_ns, imu.gyro, imu.acc)]
    csv = tmp_path / "mine.csv"
    csv.write_text("time_s;temp;wx;wy;wz;ax;ay;az\n" + "\n".join(rows) + "\n")
    return csv, REC / "groundtruth_pose.tum"


def config(tmp_path, csv, gt, columns='columns = "t,_,gx,gy,gz,ax,ay,az"'):
    cfg = tmp_path / "mine.toml"
    cfg.write_text(f'''name = "mine"
[data]
window = 200
[[data.roots]]
path = "{csv}"
format = "csv-columns"
{columns}
time_unit = "s"
gyro_unit = "deg/s"
acc_unit = "g"
groundtruth = "{gt}"
[[data.roots]]
path = "{REC}"
format = "euroc"
groundtruth = "{gt}"
[data.split]
train = ["mine[0:0.5]"]
val = ["mine[0.5:0.7]"]
test = ["V1_01_easy[0.7:1]"]
''')
    return cfg


def test_a_user_csv_root_reads_as_its_asl_twin(tmp_path):
    csv, gt = user_files(tmp_path)
    split = make_split(load_config(config(tmp_path, csv, gt)).data)
    twin = make_split(load_config(config(tmp_path, csv, gt)).data, min_len=0)
    assert split.record["train"][0]["format"] == "csv-columns" and split.train[0].name.startswith("mine")
    # the same samples as the ASL recording read directly (units converted back: 1e-9 relative)
    imu, _ = read_recording(REC, "euroc", gt)
    s = twin.train[0]
    i = np.searchsorted(imu.t_ns, s.t_ns - 1000)  # seconds as a float64 string: stamps within 1 us
    assert np.all(np.abs(imu.t_ns[i] - s.t_ns) <= 1000)
    np.testing.assert_allclose(s.gyro, imu.gyro[i], rtol=0, atol=1e-9)
    np.testing.assert_allclose(s.acc, imu.acc[i], rtol=0, atol=1e-8)


def test_a_user_csv_root_without_its_map_is_refused(tmp_path):
    csv, gt = user_files(tmp_path)
    with pytest.raises(ConfigError, match="csv-columns.*give its path, its columns"):
        make_split(load_config(config(tmp_path, csv, gt, columns="")).data)
