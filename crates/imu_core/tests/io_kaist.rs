mod io_common;
use io_common as common;

use common::*;
use imu_core::io::kaist::{read_global_pose, read_xsens_imu};
use imu_core::io::ReadOptions;
use imu_core::ImuError;

const FIXTURES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/kaist");

fn strict() -> ReadOptions {
    ReadOptions::default()
}

#[test]
fn reads_xsens_imu_fixture() {
    let imu = read_xsens_imu(format!("{FIXTURES}/sensor_data/xsens_imu.csv"), &strict()).unwrap();
    assert_eq!(imu.len(), 3);
    assert_eq!(imu.t_ns[0], 1_544_590_798_711_913_000);
    assert_eq!(imu.gyro[0], [0.0012, -0.0034, 0.0101]);
    assert_eq!(imu.acc[0], [0.1830, -0.2442, 9.8061]);
    assert_eq!(imu.gyro[2], [-0.0004, -0.0031, 0.0105]);
}

#[test]
fn reads_global_pose_fixture() {
    let gt = read_global_pose(format!("{FIXTURES}/global_pose.csv"), &strict()).unwrap();
    assert_eq!(gt.len(), 3);
    assert_eq!(gt.t_ns[0], 1_544_590_798_702_862_000);
    assert_eq!(gt.p[0], [332466.25, 4140619.12, 19.99]);
    assert!(gt.v.is_none());
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let expect = [
        [h, 0.0, 0.0, h],
        [1.0, 0.0, 0.0, 0.0],
        [15f64.to_radians().cos(), 15f64.to_radians().sin(), 0.0, 0.0],
    ];
    for (q, e) in gt.q_wxyz.iter().zip(expect) {
        for k in 0..4 {
            assert!((q[k] - e[k]).abs() < 1e-7, "{q:?} vs {e:?}");
        }
    }
}

#[test]
fn xsens_bad_rows_name_fixed_fields() {
    let dir = tempfile::tempdir().unwrap();
    let good = std::fs::read_to_string(format!("{FIXTURES}/sensor_data/xsens_imu.csv")).unwrap();
    let mut lines: Vec<String> = good.lines().map(String::from).collect();

    let mut l = lines.clone();
    l[1] = l[1].replacen(",-0.0028,", ",?,", 1);
    let p = write(&dir, "a.csv", &join(&l));
    let err = read_xsens_imu(&p, &strict()).unwrap_err();
    match &err {
        ImuError::NotNumeric {
            line,
            column,
            field,
            value,
            ..
        } => {
            assert_eq!((*line, *column, field.as_str(), value.as_str()), (2, 10, "gyro_y", "?"));
        }
        e => panic!("{e:?}"),
    }
    assert_message(&err, &p, 2, Some("gyro_y"));

    lines[2] = lines[2].rsplit_once(',').unwrap().0.to_string();
    let p = write(&dir, "b.csv", &join(&lines));
    let err = read_xsens_imu(&p, &strict()).unwrap_err();
    match &err {
        ImuError::ColumnCount {
            line, expected, found, ..
        } => assert_eq!((*line, *expected, *found), (3, 17, 16)),
        e => panic!("{e:?}"),
    }
    assert_message(&err, &p, 3, None);
}

#[test]
fn global_pose_rejects_non_rotations() {
    let dir = tempfile::tempdir().unwrap();
    // Second row: the scale of R is 1.01.
    let p = write(
        &dir,
        "g.csv",
        "1,1,0,0,0,0,1,0,0,0,0,1,0\n2,1.01,0,0,0,0,1.01,0,0,0,0,1.01,0\n",
    );
    let err = read_global_pose(&p, &strict()).unwrap_err();
    match &err {
        ImuError::InvalidInput(msg) => {
            assert!(msg.contains(&format!("{}:2:", p.display())), "{msg}");
            assert!(msg.contains("not a rotation"), "{msg}");
        }
        e => panic!("{e:?}"),
    }
    // A reflection is orthogonal but not a rotation.
    let p = write(&dir, "h.csv", "1,-1,0,0,0,0,1,0,0,0,0,1,0\n");
    assert!(matches!(
        read_global_pose(&p, &strict()),
        Err(ImuError::InvalidInput(_))
    ));

    let p = write(&dir, "i.csv", "1,1,0,0,0,0,1,0,0,0,0,1,inf\n");
    let err = read_global_pose(&p, &strict()).unwrap_err();
    match &err {
        ImuError::NonFinite {
            line, column, field, ..
        } => assert_eq!((*line, *column, field.as_str()), (1, 13, "tz")),
        e => panic!("{e:?}"),
    }
    assert_message(&err, &p, 1, Some("tz"));
}
