"""``imu-learn navigate`` for a real device with GNSS: an RTKLIB ``.pos`` found by its content (no
--aiding-format, no --aiding-kind), the tracks written as latitude/longitude/height, KML and GeoJSON
(WGS-84 ENU -> geodetic, the inverse of the reader's geodetic -> ENU), the ENU origin and the time
system in summary.json, the IMU noise (and floor) of a device profile, the one warning line of the
built-in noise, and the progress bar. On the synthetic car of tests/test_navigate_gnss.py."""
from __future__ import annotations

import json
import logging
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from imu_learn.calib.profile import NoiseTerm, Profile, noise_only
from imu_learn.fuse import geo
from imu_learn.fuse.aiding import rtklib
from imu_learn.fuse.aiding.detect import detect
from imu_learn.fuse.aiding.types import AidingRows
from imu_learn.fuse.navigate import Sources, warn_unaided_end
from test_navigate_gnss import DELAY_S, H0, LAT0, LEVER, LON0, RPY, run, synthetic_car

NOISE = {"gyroscope_noise_density": 1e-4, "accelerometer_noise_density": 1e-3, "gyroscope_random_walk": 1e-5,
         "accelerometer_random_walk": 1e-4}


def car_args(imu, pos, out):
    return ["--input", imu, "--aiding", pos, "--imu-rotation-rpy-deg", ",".join(map(str, RPY)), "--imu-delay-s",
            -DELAY_S, "--lever-arm", ",".join(map(str, LEVER)), "--keyframe-hz", 4, "--out", out]


def write_profile(path, floor=None):
    terms = {k: NoiseTerm(np.full(3, v), v, v / 10, "", "residuals") for k, v in NOISE.items()}
    prof = noise_only("test-car", 100.0, terms)
    if floor is not None:
        prof.floor = floor
    prof.save(path)
    return path


# --- geodesy ---------------------------------------------------------------------------------------

def test_enu_to_geodetic_round_trips_with_the_readers_geodetic_to_enu():
    rng = np.random.default_rng(0)
    for origin in ((LAT0, LON0, H0), (-33.9, 151.2, 40.0), (78.2, 15.6, 10.0), (0.0, 0.0, 0.0)):
        enu = rng.uniform(-20_000, 20_000, (500, 3)) * [1, 1, 0.02]
        llh = geo.enu_to_llh(enu, origin)
        back = geo.llh_to_enu(llh, origin)
        assert np.abs(back - enu).max() < 1e-6  # < 1 micrometre (the brief: < 1 mm)
        # the reader's own formulas: ECEF of each point, then its scalar ECEF -> geodetic
        x = rtklib.llh_to_ecef(llh[:5, 0], llh[:5, 1], llh[:5, 2])
        for k in range(5):
            assert np.allclose(rtklib.ecef_to_llh(x[k]), llh[k], rtol=0, atol=1e-9)


def test_the_pos_file_is_found_by_its_content(tmp_path):
    _imu, pos, _ = synthetic_car(tmp_path, seconds=6.0)
    assert detect(pos) == "rtklib"
    renamed = tmp_path / "fixes.txt"
    renamed.write_text(pos.read_text())
    assert detect(renamed) == "rtklib"  # the name plays no part
    (tmp_path / "a.tum").write_text("# t x y z qx qy qz qw\n1.0 0 0 0 0 0 0 1\n")
    (tmp_path / "a.csv").write_text("t,x,y,z,qx,qy,qz,qw\n1.0,0,0,0,0,0,0,1\n")
    (tmp_path / "a_asl.csv").write_text("#timestamp,px,py,pz,qw,qx,qy,qz\n1403636579758555392,0,0,0,1,0,0,0\n")
    assert [detect(tmp_path / n) for n in ("a.tum", "a.csv", "a_asl.csv")] == ["tum", "csv", "asl"]
    # ns in float notation (Fetch's motion capture: float64 printed in full) is ASL too, read as ns
    (tmp_path / "f_asl.csv").write_text("# timestamp, x, y, z, qw, qx, qy, qz\n"
                                        "1.691116804683040768e+18,-1.3765,1.2738,0.3642,1,0,0,0\n"
                                        "1.691116804694800128e+18,-1.3766,1.2738,0.3642,1,0,0,0\n")
    (tmp_path / "s.csv").write_text("t,x,y,z,qx,qy,qz,qw\n1.691116804e+09,0,0,0,0,0,0,1\n")
    assert detect(tmp_path / "f_asl.csv") == "asl" and detect(tmp_path / "s.csv") == "csv"
    from imu_learn.fuse.aiding.tum import read_trajectory
    assert read_trajectory(tmp_path / "f_asl.csv", "asl").t_ns.tolist() == [1691116804683040768, 1691116804694800128]
    (tmp_path / "run.bag").write_bytes(b"")
    assert detect(tmp_path / "run.bag") == "bag"
    utc = tmp_path / "utc.pos"
    utc.write_text(pos.read_text().replace("%  GPST ", "%  UTC  "))
    assert detect(utc) == "rtklib"  # then the reader says it takes GPST only
    with pytest.raises(FileNotFoundError):
        detect(tmp_path / "none.pos")


# --- the car through imu-learn navigate ------------------------------------------------------------

def test_gnss_run_writes_geodetic_tracks_origin_and_time_system(tmp_path, capsys):
    imu, pos, _ = synthetic_car(tmp_path, seconds=16.0)
    out = tmp_path / "nav"
    rc, stdout, err = run(car_args(imu, pos, out) + ["--imu-noise", "1e-4,1e-3,1e-5,1e-4", "--quiet"], capsys)
    assert rc == 0, err
    assert err == ""  # --quiet, and --imu-noise given: no warning, no bar
    s = json.loads((out / "summary.json").read_text())
    assert s["aiding_format"] == "rtklib" and s["aiding_kind"] == "position"
    o = s["enu_origin"]
    origin = rtklib.read_pos(pos).origin_llh  # the first fix: the antenna, at LEVER from the IMU near LAT0, LON0, H0
    assert (o["latitude_deg"], o["longitude_deg"], o["height_m"]) == pytest.approx(origin, abs=1e-9)
    assert np.allclose(geo.llh_to_enu(np.array([origin]), (LAT0, LON0, H0))[0][:2], 0.0, atol=1.0)
    assert s["time_system"].startswith("GPST") and "east-north-up" in s["frame"]
    assert s["imu_noise"]["source"] == "--imu-noise" and s["imu_noise"]["gyroscope_noise_density"] == 1e-4
    for name in ("causal_llh.csv", "smoothed_llh.csv", "track.kml", "track.geojson"):
        assert (out / name).is_file(), name
        assert s["outputs"][{"track.kml": "kml", "track.geojson": "geojson"}.get(name, name[:-4])] == str(out / name)
    tum = np.loadtxt(out / "smoothed.tum", ndmin=2)
    llh = np.loadtxt(out / "smoothed_llh.csv", delimiter=",", skiprows=1, ndmin=2)
    assert (out / "smoothed_llh.csv").read_text().splitlines()[0] == "t_s,latitude_deg,longitude_deg,height_m"
    np.testing.assert_allclose(llh[:, 0], tum[:, 0], rtol=0, atol=1e-6)
    enu = geo.llh_to_enu(llh[:, 1:], origin)
    assert np.abs(enu - tum[:, 1:4]).max() < 1e-3  # 10 decimals of a degree, 0.1 mm of height
    # KML: parses, one LineString per track, lon,lat,h triples equal to the CSV
    root = ET.parse(out / "track.kml").getroot()
    ns = {"k": geo.KML_NS}
    marks = root.findall(".//k:Placemark", ns)
    assert [m.find("k:name", ns).text for m in marks] == ["causal", "smoothed"]
    coords = np.array([[float(v) for v in c.split(",")]
                       for c in marks[1].find(".//k:LineString/k:coordinates", ns).text.split()])
    assert np.all(np.abs(coords[:, [1, 0, 2]] - llh[:, 1:]).max(axis=0) <= [1e-8, 1e-8, 1e-3])
    # GeoJSON: a FeatureCollection of LineStrings in lon, lat order
    gj = json.loads((out / "track.geojson").read_text())
    assert gj["type"] == "FeatureCollection" and len(gj["features"]) == 2
    for f in gj["features"]:
        assert f["type"] == "Feature" and f["geometry"]["type"] == "LineString"
        c = np.asarray(f["geometry"]["coordinates"])
        assert c.shape[1] == 3 and len(c) >= 2
        assert np.all(np.abs(c[:, 0] - LON0) < 0.01) and np.all(np.abs(c[:, 1] - LAT0) < 0.01)  # lon first
    np.testing.assert_allclose(np.asarray(gj["features"][1]["geometry"]["coordinates"])[:, [1, 0]], llh[:, 1:3],
                               atol=1e-8)


def test_noise_from_a_profile_else_one_warning_naming_the_built_in(tmp_path, capsys):
    imu, pos, _ = synthetic_car(tmp_path, seconds=14.0)
    rc, _out, err = run(car_args(imu, pos, tmp_path / "plain") + ["--quiet"], capsys)
    assert rc == 0, err
    warnings = [ln for ln in err.splitlines() if "warning" in ln]
    assert len(warnings) == 1 and "EuRoC ADIS16448" in warnings[0] and "--profile" in warnings[0], err
    s = json.loads((tmp_path / "plain" / "summary.json").read_text())
    assert "EuRoC ADIS16448 sensor.yaml" in s["imu_noise"]["source"] and s["profile"] is None  # the class default
    prof = write_profile(tmp_path / "calib" / "profile.json")
    rc, _out, err = run(car_args(imu, pos, tmp_path / "prof") + ["--quiet", "--profile", prof], capsys)
    assert rc == 0, err
    assert err == ""
    s = json.loads((tmp_path / "prof" / "summary.json").read_text())
    # the profile's noise; its white noise raised only where the fixes' innovations say the moving IMU is noisier
    # (this synthetic car's IMU is exact: no fit there, said so)
    noise = dict(s["imu_noise"])
    assert noise.pop("source").startswith(f"profile {prof}; no in-motion fit from the aiding's innovations")
    assert noise == NOISE
    assert s["profile"] == str(prof) and s["profile_floor"] is False and s["imu_input"] == "raw"


def test_a_profiles_floor_is_applied_in_the_imu_frame(tmp_path, capsys):
    """The car's gyro carries a bias in the IMU frame; the profile's floor removes it: the bias the
    graph estimates is then near zero, against the bias itself (in the body frame) without it."""
    from imu_learn.baselines.traditional import TraditionalTiming
    from imu_learn.data.formats import gnss_imu

    imu, pos, _ = synthetic_car(tmp_path, seconds=14.0)
    b = np.array([0.02, -0.015, 0.01])  # rad/s, IMU frame
    lines = imu.read_text().split("\n")
    for i in range(1, len(lines) - 1):
        c = lines[i].split(",")
        c[3:6] = [f"{float(v) + np.degrees(bk):.6f}" for v, bk in zip(c[3:6], b)]
        lines[i] = ",".join(c)
    imu.write_text("\n".join(lines))
    m = TraditionalTiming()
    m.params.b_g = b.copy()
    m.params.cutoff_gyro = m.params.cutoff_acc = None
    m.params.time_offset = 0.0
    prof = write_profile(tmp_path / "calib" / "profile.json", floor=m.to_dict())
    assert Profile.load(prof).has_floor
    args = car_args(imu, pos, tmp_path / "floor") + ["--quiet", "--profile", prof]
    rc, _out, err = run(args, capsys)
    assert rc == 0, err
    s = json.loads((tmp_path / "floor" / "summary.json").read_text())
    assert s["profile_floor"] is True and "floor of profile" in s["imu_input"]
    assert np.abs(s["final_bias"][:3]).max() < 0.003, s["final_bias"]
    rc, _out, err = run(car_args(imu, pos, tmp_path / "raw") + ["--quiet", "--imu-noise", "1e-4,1e-3,1e-5,1e-4"],
                        capsys)
    assert rc == 0, err
    raw = json.loads((tmp_path / "raw" / "summary.json").read_text())
    np.testing.assert_allclose(raw["final_bias"][:3], gnss_imu.mounting_rotation(RPY) @ b, atol=0.003)


def test_progress_bar_on_stderr_unless_quiet(tmp_path, capsys, monkeypatch):
    from imu_learn.fuse import navigate

    monkeypatch.setattr(navigate, "PROGRESS_DELAY_S", 0.0)  # a short run shows its bar too
    imu, pos, _ = synthetic_car(tmp_path, seconds=12.0)
    noise = ["--imu-noise", "1e-4,1e-3,1e-5,1e-4"]
    rc, _out, err = run(car_args(imu, pos, tmp_path / "a") + noise, capsys)
    assert rc == 0, err
    assert "navigate" in err and "sample" in err
    rc, _out, err = run(car_args(imu, pos, tmp_path / "b") + noise + ["--quiet"], capsys)
    assert rc == 0 and err == ""


# --- a cut of the real drive -----------------------------------------------------------------------

from test_navigate_gnss import DRIVE, crop_drive  # noqa: E402


@pytest.mark.skipif(not (DRIVE / "imu_1934.csv").is_file(), reason="the gnss-imu drive is not on this machine "
                    "(set IMU_LEARN_DATA to the data root)")
def test_real_drive_cut_from_its_pos_file_alone(tmp_path, capsys):
    imu = crop_drive(tmp_path, 50.0)
    pos = DRIVE / "gnss_1934_sf.pos"
    out = tmp_path / "drive"
    rc, stdout, err = run(["--input", imu, "--aiding", pos, "--imu-rotation-rpy-deg", "180,-6.79,185.35",
                           "--imu-delay-s", -0.125, "--out", out, "--quiet"], capsys)
    assert rc == 0, err
    s = json.loads((out / "summary.json").read_text())
    assert s["aiding_format"] == "rtklib" and s["aiding_kind"] == "position"
    first = next(ln for ln in pos.read_text().splitlines() if not ln.startswith("%")).split()
    o = s["enu_origin"]
    assert [o["latitude_deg"], o["longitude_deg"], o["height_m"]] == [float(v) for v in first[2:5]]
    root = ET.parse(out / "track.kml").getroot()
    assert len(root.findall(f".//{{{geo.KML_NS}}}LineString")) == 2
    gj = json.loads((out / "track.geojson").read_text())
    c = np.asarray(gj["features"][1]["geometry"]["coordinates"])
    assert np.all(np.abs(c[:, 0] - o["longitude_deg"]) < 0.01) and np.all(np.abs(c[:, 1] - o["latitude_deg"]) < 0.01)


def test_aiding_hz_thins_the_gnss_fixes(tmp_path, capsys):
    imu, pos, _ = synthetic_car(tmp_path, seconds=16.0)
    counts = {}
    for hz in (None, 1.0):
        out = tmp_path / f"nav{hz}"
        extra = [] if hz is None else ["--aiding-hz", hz]
        rc, _, err = run(car_args(imu, pos, out) + ["--imu-noise", "1e-4,1e-3,1e-5,1e-4", "--quiet"] + extra, capsys)
        assert rc == 0, err
        s = json.loads((out / "summary.json").read_text())
        counts[hz] = (s["aiding_rows_used"], s["aiding_dropped"].get("thinned", 0))
    used, thinned = counts[1.0]
    assert counts[None][1] == 0 and thinned > 0 and used + thinned == counts[None][0]
    assert used == pytest.approx(counts[None][0] / 4, abs=2)  # 4 Hz fixes kept at 1 Hz


def test_an_aiding_that_stops_long_before_the_imu_is_named(caplog):
    """A .pos cut short (the walk's at 65 of 134 s) left the tracks' last minute dead reckoning, exit 0, with no
    word; a --gaps window that runs to the end says so on purpose, and a short tail is a receiver's usual end."""
    t_ns = np.arange(0, 134_000, 5, dtype=np.int64) * 1_000_000  # 134 s of IMU
    rows = lambda last_s: AidingRows(np.zeros(2, int), np.array([0, int(last_s * 1e9)]), np.zeros(2, np.int64),  # noqa: E731
                                     np.zeros((2, 3)), None)
    src = Sources(Path("imu.csv"), Path("rover.pos"))
    with caplog.at_level(logging.WARNING, logger="imu_learn.fuse.navigate"):
        warn_unaided_end(src, rows(65.0), t_ns, ())
        assert len(caplog.records) == 1 and "the tracks' last 69.0 s are the IMU's alone" in caplog.text
        caplog.clear()
        warn_unaided_end(src, rows(131.0), t_ns, ())  # 3 s: a receiver's usual end
        warn_unaided_end(src, rows(65.0), t_ns, ((60.0, 80.0),))  # the user's own outage to the end
        assert not caplog.records
