//! Files that parse but hold too few rows (empty, header only, one row) are `TooFewRows`, naming
//! the file, the last line read and what is missing; IMU and ground truth that never overlap are
//! `NoOverlap` with both spans.

use std::path::Path;

use imu_core::align::{align_from, AlignOptions, Sources};
use imu_core::error::ImuError;
use imu_core::io::{asl, kaist, tum, ReadOptions};
use imu_core::types::{GroundTruth, ImuSamples};

fn write(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// (line, found, message) of a `TooFewRows`, failing the test on anything else.
fn too_few<T: std::fmt::Debug>(r: Result<T, ImuError>, path: &Path) -> (usize, usize, String) {
    let err = r.expect_err("a file with too few rows must be refused");
    let msg = err.to_string();
    let ImuError::TooFewRows {
        path: p, line, found, ..
    } = err
    else {
        panic!("expected TooFewRows, got {msg}");
    };
    assert_eq!(p, path);
    assert!(msg.contains(&path.display().to_string()), "{msg}");
    (line, found, msg)
}

#[test]
fn asl_imu_empty_header_only_and_one_row() {
    let dir = tempfile::tempdir().unwrap();
    let o = ReadOptions::default();
    let p = write(dir.path(), "empty.csv", "");
    let (line, found, msg) = too_few(asl::read_imu(&p, &o), &p);
    assert_eq!((line, found), (0, 0));
    assert!(msg.contains("IMU file is empty"), "{msg}");

    let p = write(dir.path(), "header.csv", &format!("{}\n", asl::IMU_HEADER));
    let (line, found, msg) = too_few(asl::read_imu(&p, &o), &p);
    assert_eq!((line, found), (1, 0));
    assert!(msg.contains("IMU file has a header but no samples"), "{msg}");

    let p = write(
        dir.path(),
        "one.csv",
        &format!("{}\n1000,1,2,3,4,5,6\n\n", asl::IMU_HEADER),
    );
    let (line, found, msg) = too_few(asl::read_imu(&p, &o), &p);
    assert_eq!((line, found), (2, 1));
    assert!(msg.contains("only 1 sample") && msg.contains("at least 2"), "{msg}");

    let p = write(
        dir.path(),
        "two.csv",
        &format!("{}\n1000,1,2,3,4,5,6\n2000,1,2,3,4,5,6\n", asl::IMU_HEADER),
    );
    assert_eq!(asl::read_imu(&p, &o).unwrap().t_ns, vec![1000, 2000]);
}

#[test]
fn ground_truth_readers_need_two_poses() {
    let dir = tempfile::tempdir().unwrap();
    let o = ReadOptions::default();
    let p = write(dir.path(), "state.csv", &format!("{}\n", asl::STATE_HEADER_SHORT));
    let (_, _, msg) = too_few(asl::read_state(&p, &o), &p);
    assert!(msg.contains("ground-truth file has a header but no poses"), "{msg}");
    let p = write(
        dir.path(),
        "pose.csv",
        &format!("{}\n1000,0,0,0,1,0,0,0\n", asl::POSE_HEADER),
    );
    let (line, found, _) = too_few(asl::read_pose(&p, &o), &p);
    assert_eq!((line, found), (2, 1));
    let p = write(dir.path(), "gt.tum", "# t tx ty tz qx qy qz qw\n1.0 0 0 0 0 0 0 1\n");
    let (line, found, msg) = too_few(tum::read_tum(&p, &o), &p);
    assert_eq!((line, found), (2, 1));
    assert!(msg.contains("only 1 pose"), "{msg}");
    let p = write(dir.path(), "blank.tum", "\n \n");
    let (line, _, msg) = too_few(tum::read_tum(&p, &o), &p);
    assert_eq!(line, 0);
    assert!(msg.contains("is empty"), "{msg}");
}

#[test]
fn kaist_readers_need_two_rows() {
    let dir = tempfile::tempdir().unwrap();
    let o = ReadOptions::default();
    let p = write(dir.path(), "xsens_imu.csv", "");
    let (_, _, msg) = too_few(kaist::read_xsens_imu(&p, &o), &p);
    assert!(msg.contains("IMU file is empty"), "{msg}");
    let p = write(dir.path(), "global_pose.csv", "1000,1,0,0,0,0,1,0,0,0,0,1,0\n");
    let (_, found, _) = too_few(kaist::read_global_pose(&p, &o), &p);
    assert_eq!(found, 1);
}

#[test]
fn disjoint_spans_are_no_overlap_naming_both_files() {
    let imu_t: Vec<i64> = (0..10).map(|i| 30_000_000_000 + i * 5_000_000).collect();
    let gt_t: Vec<i64> = (0..10).map(|i| 10_000_000_000 + i * 5_000_000).collect();
    let imu = ImuSamples {
        t_ns: imu_t,
        gyro: vec![[0.0; 3]; 10],
        acc: vec![[0.0; 3]; 10],
    };
    let gt = GroundTruth {
        t_ns: gt_t,
        p: vec![[0.0; 3]; 10],
        q_wxyz: vec![[1.0, 0.0, 0.0, 0.0]; 10],
        ..GroundTruth::default()
    };
    let sources = Sources {
        imu: Some("rec/imu.csv".into()),
        gt: Some("rec/gt.tum".into()),
    };
    match align_from(&imu, &gt, &AlignOptions::default(), &sources) {
        Err(e @ ImuError::NoOverlap { .. }) => {
            let msg = e.to_string();
            assert!(
                msg.contains("ground truth rec/gt.tum covers 10.000-10.045 s")
                    && msg.contains("the IMU rec/imu.csv 30.000-30.045 s")
                    && msg.contains("never overlap")
                    && msg.contains("ends 19.955 s before the IMU starts"),
                "{msg}"
            );
        }
        other => panic!("expected NoOverlap, got {other:?}"),
    }
}
