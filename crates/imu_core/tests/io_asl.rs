mod common;
mod io_common;

// The data root and `have` (skip visibly, or fail under IMU_LEARN_REQUIRE_DATA=1) from the shared
// helper; the rest (headers, row builders, message checks) from the readers' helpers.
use common::{data, have};
use imu_core::io::asl::{read_imu, read_imu_header, read_pose, read_state, write_imu, IMU_HEADER as LIB_IMU_HEADER};
use imu_core::io::ReadOptions;
use imu_core::{ImuError, ImuSamples};
use io_common::*;

fn strict() -> ReadOptions {
    ReadOptions::default()
}

const MH01: &str = "euroc/MH_01_easy/mav0/imu0/data.csv";
const V101: &str = "euroc/V1_01_easy/mav0/imu0/data.csv";
const QUIRKS: &str = "quirks/MH_01_easy_imu0_spreadsheet_export.csv";

fn assert_bits_eq(a: &ImuSamples, b: &ImuSamples) {
    assert_eq!(a.t_ns, b.t_ns);
    let bits = |s: &ImuSamples| -> Vec<u64> {
        s.gyro
            .iter()
            .chain(s.acc.iter())
            .flatten()
            .map(|x| x.to_bits())
            .collect()
    };
    assert_eq!(bits(a), bits(b));
}

#[test]
fn reads_mh01_imu() {
    if !(have(MH01)) {
        return;
    }
    let imu = read_imu(data(MH01), &strict()).unwrap();
    assert_eq!(imu.len(), 36_820);
    assert_eq!(imu.t_ns[0], 1_403_636_579_758_560_000);
    assert_eq!(imu.gyro[0], [-0.0991347015, 0.1473057889, 0.0272271363]);
    assert_eq!(imu.acc[0], [8.1476917083, -0.3759215833, -2.40262925]);
    assert_eq!(imu.t_ns[36_819], 1_403_636_763_853_560_000);
    assert_eq!(imu.acc[36_819], [9.1365289167, -0.760015375, -2.770378625]);
}

// The literals are the file's text, digit for digit.
#[allow(clippy::excessive_precision)]
#[test]
fn reads_v101_imu_full_precision() {
    if !(have(V101)) {
        return;
    }
    let imu = read_imu(data(V101), &strict()).unwrap();
    assert_eq!(imu.len(), 29_120);
    assert_eq!(imu.t_ns[0], 1_403_715_273_262_142_976);
    assert_eq!(
        imu.gyro[0],
        [-0.0020943951023931952, 0.017453292519943295, 0.07749261878854824]
    );
    assert_eq!(
        imu.acc[0],
        [9.0874956666666655, 0.13075533333333333, -3.6938381666666662]
    );
    assert_eq!(imu.t_ns[29_119], 1_403_715_418_857_143_040);
}

#[test]
fn quirks_file_needs_the_option_and_then_matches_the_clean_file() {
    if !(have(QUIRKS) && have(MH01)) {
        return;
    }
    let p = data(QUIRKS);
    let err = read_imu(&p, &strict()).unwrap_err();
    match &err {
        ImuError::FloatTimestamp {
            path,
            line,
            column,
            field,
            value,
        } => {
            assert_eq!((path, *line, *column), (&p, 2, 1));
            assert_eq!(
                (field.as_str(), value.as_str()),
                ("timestamp [ns]", "1.40363657975856E+018")
            );
        }
        e => panic!("{e:?}"),
    }
    assert_message(&err, &p, 2, Some("timestamp [ns]"));

    let quirky = read_imu(
        &p,
        &ReadOptions {
            allow_float_timestamps: true,
        },
    )
    .unwrap();
    let clean = read_imu(data(MH01), &strict()).unwrap();
    assert_eq!(quirky.len(), 36_820);
    assert_bits_eq(&quirky, &clean);
}

#[test]
fn imu_header_is_checked() {
    let dir = tempfile::tempdir().unwrap();
    let swapped = "#timestamp [ns],a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1]";
    let mut l = imu_lines(2);
    l[0] = swapped.into();
    let p = write(&dir, "a.csv", &join(&l));
    let err = read_imu(&p, &strict()).unwrap_err();
    match &err {
        ImuError::Header {
            path,
            line,
            expected,
            found,
        } => {
            assert_eq!((path, *line), (&p, 1));
            assert_eq!(expected, LIB_IMU_HEADER);
            assert_eq!(found, swapped);
        }
        e => panic!("{e:?}"),
    }
    assert_message(&err, &p, 1, None);
    assert!(err.to_string().contains("w_RS_S_x") && err.to_string().contains(swapped));

    // A missing header shows the data row it found instead.
    let p = write(&dir, "b.csv", &join(&imu_lines(2)[1..]));
    assert!(matches!(
        read_imu(&p, &strict()).unwrap_err(),
        ImuError::Header { line: 1, .. }
    ));
    assert!(matches!(
        read_imu_header(&p).unwrap_err(),
        ImuError::Header { line: 1, .. }
    ));

    // Units, '#' and spaces are not part of a name.
    let mut l = imu_lines(2);
    l[0] = "# timestamp, w_RS_S_x, w_RS_S_y, w_RS_S_z, a_RS_S_x, a_RS_S_y, a_RS_S_z".into();
    let p = write(&dir, "c.csv", &join(&l));
    assert_eq!(read_imu(&p, &strict()).unwrap().len(), 2);
}

#[test]
fn read_imu_header_returns_the_first_line() {
    if !(have(MH01)) {
        return;
    }
    assert_eq!(read_imu_header(data(MH01)).unwrap(), IMU_HEADER);
    let err = read_imu_header(data("euroc/nope.csv")).unwrap_err();
    assert!(matches!(err, ImuError::NotFound { .. }));
}

#[test]
fn write_imu_round_trips_bit_for_bit() {
    if !(have(V101)) {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let clean = read_imu(data(V101), &strict()).unwrap();
    let out = dir.path().join("imu0.csv");
    write_imu(&out, &clean, None).unwrap();
    assert_bits_eq(&read_imu(&out, &strict()).unwrap(), &clean);
    assert_eq!(read_imu_header(&out).unwrap(), LIB_IMU_HEADER);

    let odd = ImuSamples {
        t_ns: vec![-5, 0, 1_700_000_000_000_000_000],
        gyro: vec![
            [1.0 / 3.0, -0.0, 1e-300],
            [f64::MIN_POSITIVE, 5e-324, f64::MAX],
            [0.1, 0.2, 0.3],
        ],
        acc: vec![
            [9.81, -9.81, 1.2345678901234567e10],
            [0.0, 1.0, -1.0],
            [2.0f64.sqrt(), std::f64::consts::PI, 1e22],
        ],
    };
    let custom = "# timestamp , w_RS_S_x,w_RS_S_y,w_RS_S_z,a_RS_S_x,a_RS_S_y,a_RS_S_z";
    write_imu(&out, &odd, Some(custom)).unwrap();
    assert_bits_eq(&read_imu(&out, &strict()).unwrap(), &odd);
    assert_eq!(read_imu_header(&out).unwrap(), custom);
    // Nothing but the target is left behind.
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, vec![std::ffi::OsString::from("imu0.csv")]);
}

#[test]
fn write_imu_rejects_what_would_not_read_back() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("imu0.csv");
    let good = ImuSamples {
        t_ns: vec![1, 2],
        gyro: vec![[0.0; 3]; 2],
        acc: vec![[0.0; 3]; 2],
    };
    assert!(matches!(
        write_imu(&out, &good, Some("#t,a,b")),
        Err(ImuError::InvalidInput(_))
    ));
    assert!(matches!(
        write_imu(&out, &good, Some(&format!("{IMU_HEADER}\n1,2"))),
        Err(ImuError::InvalidInput(_))
    ));
    let mut bad = good.clone();
    bad.gyro[1][2] = f64::NAN;
    assert!(matches!(write_imu(&out, &bad, None), Err(ImuError::InvalidInput(_))));
    let mut bad = good.clone();
    bad.t_ns[1] = 1;
    assert!(matches!(write_imu(&out, &bad, None), Err(ImuError::InvalidInput(_))));
    let mut bad = good.clone();
    bad.acc.pop();
    assert!(matches!(write_imu(&out, &bad, None), Err(ImuError::InvalidInput(_))));
    assert!(!out.exists());
}

#[test]
fn reads_v101_state_short_header() {
    if !(have("euroc/V1_01_easy/groundtruth_state_20hz.csv")) {
        return;
    }
    let gt = read_state(data("euroc/V1_01_easy/groundtruth_state_20hz.csv"), &strict()).unwrap();
    assert_eq!(gt.len(), 2895);
    assert_eq!(gt.t_ns[0], 1_403_715_273_262_142_976);
    assert_eq!(gt.p[0], [0.878895, 2.1834, 0.948427]);
    assert_eq!(gt.q_wxyz[0], [0.069433, -0.824237, -0.106942, -0.551702]);
    assert_eq!(gt.v.as_ref().unwrap()[0], [0.00157587, 0.00179383, -0.00231615]);
    assert_eq!(gt.bias_gyro.as_ref().unwrap()[0], [-0.00224703, 0.0215352, 0.0770299]);
    assert_eq!(gt.bias_acc.as_ref().unwrap()[0], [-0.0180115, 0.0659796, 0.0309774]);
    assert_eq!(gt.bias_acc.as_ref().unwrap().len(), 2895);
}

#[test]
fn reads_all_official_state_files() {
    if !(have("euroc") && have("euroc-groundtruth")) {
        return;
    }
    for (name, rows) in [
        ("MH_04_difficult", 0),
        ("MH_05_difficult", 0),
        ("V1_03_difficult", 0),
        ("V2_01_easy", 22_401),
        ("V2_02_medium", 0),
        ("V2_03_difficult", 0),
    ] {
        let p = data(&format!("euroc-groundtruth/{name}.csv"));
        let gt = read_state(&p, &strict()).unwrap();
        let lines = std::fs::read_to_string(&p).unwrap().lines().count();
        assert_eq!(gt.len(), lines - 1, "{name}");
        if rows > 0 {
            assert_eq!(gt.len(), rows);
        }
        assert_eq!(gt.v.as_ref().unwrap().len(), gt.len());
        for q in &gt.q_wxyz {
            let n: f64 = q.iter().map(|x| x * x).sum::<f64>().sqrt();
            assert!((n - 1.0).abs() < 1e-3, "{name}: {q:?}");
        }
    }
    let gt = read_state(data("euroc-groundtruth/V2_01_easy.csv"), &strict()).unwrap();
    assert_eq!(gt.t_ns[0], 1_413_393_213_480_760_576);
    assert_eq!(gt.q_wxyz[0], [0.606377, -0.005788, -0.795108, 0.008771]);
    assert_eq!(gt.bias_acc.as_ref().unwrap()[0], [-0.023601, 0.121044, 0.074783]);
}

#[test]
fn state_header_and_rows_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(
        &dir,
        "s.csv",
        "#time(ns),px,py,pz,qx,qy,qz,qw,vx,vy,vz,bwx,bwy,bwz,bax,bay,baz\n",
    );
    let err = read_state(&p, &strict()).unwrap_err();
    match &err {
        ImuError::Header {
            line, expected, found, ..
        } => {
            assert_eq!(*line, 1);
            assert!(expected.contains("p_RS_R_x") && expected.contains("#time(ns),px"));
            assert!(found.starts_with("#time(ns),px,py,pz,qx"));
        }
        e => panic!("{e:?}"),
    }
    assert_message(&err, &p, 1, None);

    let p = write(
        &dir,
        "t.csv",
        "#time(ns),px,py,pz,qw,qx,qy,qz,vx,vy,vz,bwx,bwy,bwz,bax,bay,baz\n\
         100,0,0,0,1,0,0,0,0,0,0,0,0,0,0,0,0\n\
         200,0,0,0,1,0,0,0,0,0,0,0,0,oops,0,0,0\n",
    );
    let err = read_state(&p, &strict()).unwrap_err();
    match &err {
        ImuError::NotNumeric {
            line, column, field, ..
        } => assert_eq!((*line, *column, field.as_str()), (3, 14, "bwz")),
        e => panic!("{e:?}"),
    }
    assert_message(&err, &p, 3, Some("bwz"));
}

#[test]
fn reads_tum_vi_mocap_pose() {
    let dir = tempfile::tempdir().unwrap();
    let header = "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []";
    let p = write(
        &dir,
        "data.csv",
        &format!("{header}\n1520530308199447626,0.98,2.04,1.35,0.70,-0.01,0.71,0.02\n1520530308209447626,0.99,2.05,1.36,0.71,-0.02,0.70,0.03\n"),
    );
    let gt = read_pose(&p, &strict()).unwrap();
    assert_eq!(gt.t_ns, vec![1_520_530_308_199_447_626, 1_520_530_308_209_447_626]);
    assert_eq!(gt.p[1], [0.99, 2.05, 1.36]);
    assert_eq!(gt.q_wxyz[0], [0.70, -0.01, 0.71, 0.02]);
    assert!(gt.v.is_none() && gt.bias_gyro.is_none());

    let p = write(&dir, "bad.csv", &format!("{header}\n1,0,0,0,1,0,0\n"));
    let err = read_pose(&p, &strict()).unwrap_err();
    match &err {
        ImuError::ColumnCount {
            line, expected, found, ..
        } => assert_eq!((*line, *expected, *found), (2, 8, 7)),
        e => panic!("{e:?}"),
    }
    assert_message(&err, &p, 2, None);
}

/// Timing against the real file: `cargo test --release --test io_asl -- --ignored --nocapture`.
#[test]
#[ignore]
fn time_read_imu_mh01() {
    let p = data(MH01);
    let _ = read_imu(&p, &strict()).unwrap();
    let n = 50;
    let start = std::time::Instant::now();
    for _ in 0..n {
        std::hint::black_box(read_imu(&p, &strict()).unwrap());
    }
    let per = start.elapsed() / n;
    println!(
        "read_imu MH_01 (36,820 rows, 3.3 MB): {per:?} per read, {} threads",
        rayon::current_num_threads()
    );
}
