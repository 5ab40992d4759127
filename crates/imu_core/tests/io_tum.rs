mod common;
mod io_common;

// The data root and `have` (skip visibly, or fail under IMU_LEARN_REQUIRE_DATA=1) from the shared
// helper; the rest (headers, row builders, message checks) from the readers' helpers.
use common::{data, have};
use imu_core::error::TimestampProblem;
use imu_core::io::tum::{read_trajectory, read_tum, write_tum, TrajectoryLayout, TrajectoryOptions};
use imu_core::io::ReadOptions;
use imu_core::{GroundTruth, ImuError};
use io_common::*;

fn strict() -> ReadOptions {
    ReadOptions::default()
}

fn bits(gt: &GroundTruth) -> Vec<u64> {
    let v = gt.v.iter().flatten().flatten();
    gt.p.iter()
        .flatten()
        .chain(gt.q_wxyz.iter().flatten())
        .chain(v)
        .map(|x| x.to_bits())
        .collect()
}

#[test]
fn reads_euroc_tum_ground_truth() {
    if !(have("euroc/MH_01_easy/groundtruth_pose.tum") && have("euroc/V1_01_easy/groundtruth_pose.tum")) {
        return;
    }
    let gt = read_tum(data("euroc/MH_01_easy/groundtruth_pose.tum"), &strict()).unwrap();
    assert_eq!(gt.len(), 36_382);
    assert_eq!(gt.t_ns[0], 1_403_636_580_838_560_000);
    assert_eq!(gt.p[0], [4.688319, -1.786938, 0.783338]);
    // File order x,y,z,w; core order w,x,y,z.
    assert_eq!(gt.q_wxyz[0], [0.534108, -0.153029, -0.827383, -0.082152]);
    assert!(gt.v.is_none());
    assert_eq!(*gt.t_ns.last().unwrap(), 1_403_636_762_743_560_000);

    let gt = read_tum(data("euroc/V1_01_easy/groundtruth_pose.tum"), &strict()).unwrap();
    assert_eq!(gt.len(), 28_712);
    assert_eq!(gt.t_ns[0], 1_403_715_274_302_140_000);
    assert_eq!(gt.q_wxyz[0], [0.060514, -0.828459, -0.058956, -0.553641]);
}

#[test]
fn reads_blackbird_with_velocity_and_full_stamp_precision() {
    if !(have("blackbird/clover_yawForward_maxSpeed5p0")) {
        return;
    }
    for split in ["train", "val"] {
        let p = data(&format!(
            "blackbird/clover_yawForward_maxSpeed5p0/{split}/stamped_groundtruth_imu.txt"
        ));
        let gt = read_tum(&p, &strict()).unwrap();
        let rows = std::fs::read_to_string(&p)
            .unwrap()
            .lines()
            .filter(|l| !l.starts_with('#'))
            .count();
        assert_eq!(gt.len(), rows);
        assert_eq!(gt.v.as_ref().unwrap().len(), rows);
    }
    let gt = read_tum(
        data("blackbird/clover_yawForward_maxSpeed5p0/train/stamped_groundtruth_imu.txt"),
        &strict(),
    )
    .unwrap();
    assert_eq!(gt.len(), 9100);
    // 1525745925.001598119736 s: 12 fractional digits, rounded at the 9th.
    assert_eq!(gt.t_ns[0], 1_525_745_925_001_598_120);
    assert_eq!(gt.t_ns[1], 1_525_745_925_011_598_110);
    assert_eq!(gt.p[0], [-1.195960179995, 1.420202832248, 1.491985563428]);
    assert_eq!(
        gt.q_wxyz[0],
        [-0.002783797821, 0.989693116041, 0.114948319089, -0.085361996628]
    );
    assert_eq!(
        gt.v.as_ref().unwrap()[0],
        [-1.416452426075, 2.144184694651, -0.032295262630]
    );
}

#[test]
fn decimal_seconds_keep_every_ns() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(
        &dir,
        "a.tum",
        "# t x y z qx qy qz qw\n1403636580.000000001 0 0 0 0 0 0 1\n# mid-file comment\n\t1403636580.000000002  0 0 0 0 0 0 1 \n1403636581 0 0 0 0 0 0 1\n",
    );
    let gt = read_tum(&p, &strict()).unwrap();
    assert_eq!(
        gt.t_ns,
        vec![
            1_403_636_580_000_000_001,
            1_403_636_580_000_000_002,
            1_403_636_581_000_000_000
        ]
    );
}

#[test]
fn wrong_column_counts() {
    let dir = tempfile::tempdir().unwrap();
    // 9 columns fit neither layout.
    let p = write(&dir, "a.tum", "# c\n1.0 0 0 0 0 0 0 1 7\n");
    let err = read_tum(&p, &strict()).unwrap_err();
    match &err {
        ImuError::ColumnCount {
            line, expected, found, ..
        } => assert_eq!((*line, *expected, *found), (2, 8, 9)),
        e => panic!("{e:?}"),
    }
    assert_message(&err, &p, 2, None);
    // The first row picks the layout; a later row may not switch.
    let p = write(&dir, "b.tum", "1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 0 1 1 2 3\n");
    let err = read_tum(&p, &strict()).unwrap_err();
    match &err {
        ImuError::ColumnCount {
            line, expected, found, ..
        } => assert_eq!((*line, *expected, *found), (2, 8, 11)),
        e => panic!("{e:?}"),
    }
    assert_message(&err, &p, 2, None);
}

#[test]
fn bad_fields_use_fixed_names() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(&dir, "a.tum", "# c\n1.0 0 0 0 0 0 0 1\n2.0 0 0 0 q 0 0 1\n");
    let err = read_tum(&p, &strict()).unwrap_err();
    match &err {
        ImuError::NotNumeric {
            line,
            column,
            field,
            value,
            ..
        } => {
            assert_eq!((*line, *column, field.as_str(), value.as_str()), (3, 5, "qx", "q"));
        }
        e => panic!("{e:?}"),
    }
    assert_message(&err, &p, 3, Some("qx"));

    let p = write(&dir, "b.tum", "1.0 0 0 0 0 0 0 1 0 nan 0\n");
    let err = read_tum(&p, &strict()).unwrap_err();
    match &err {
        ImuError::NonFinite {
            line, column, field, ..
        } => assert_eq!((*line, *column, field.as_str()), (1, 10, "vy")),
        e => panic!("{e:?}"),
    }
    assert_message(&err, &p, 1, Some("vy"));

    let p = write(&dir, "c.tum", "1.0 0 0 0 0 0 0 1\n1,5 0 0 0 0 0 0 1\n");
    let err = read_tum(&p, &strict()).unwrap_err();
    match &err {
        ImuError::NotNumeric {
            line, column, field, ..
        } => assert_eq!((*line, *column, field.as_str()), (2, 1, "timestamp")),
        e => panic!("{e:?}"),
    }
    assert_message(&err, &p, 2, Some("timestamp"));
    assert!(!err.to_string().contains("2262"), "{err}");
}

#[test]
fn stamps_in_milliseconds_name_the_unit() {
    // A VO's stamps written in ms where TUM means seconds: past i64 ns, a number all the same.
    let dir = tempfile::tempdir().unwrap();
    let p = write(
        &dir,
        "ms.tum",
        "1403637130538.319092 0 0 0 0 0 0 1
",
    );
    let err = read_tum(&p, &strict()).unwrap_err();
    match &err {
        ImuError::NotNumeric { line, field, hint, .. } => {
            assert_eq!((*line, field.as_str()), (1, "timestamp"));
            assert!(hint.contains("milliseconds or microseconds read as seconds"), "{hint}");
        }
        e => panic!("{e:?}"),
    }
    assert!(
        err.to_string()
            .contains("not a number of the file's time unit before the year 2262"),
        "{err}"
    );
}

#[test]
fn duplicate_and_decreasing_stamps() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(&dir, "a.tum", "1.5 0 0 0 0 0 0 1\n1.500000000 0 0 0 0 0 0 1\n");
    let err = read_tum(&p, &strict()).unwrap_err();
    match &err {
        ImuError::Timestamp {
            line,
            column,
            field,
            value,
            previous,
            problem,
            ..
        } => {
            assert_eq!((*line, *column, field.as_str()), (2, 1, "timestamp"));
            assert_eq!(
                (*value, *previous, *problem),
                (1_500_000_000, 1_500_000_000, TimestampProblem::Duplicate)
            );
        }
        e => panic!("{e:?}"),
    }
    assert_message(&err, &p, 2, Some("timestamp"));
    let p = write(&dir, "b.tum", "1.5 0 0 0 0 0 0 1\n# x\n1.4 0 0 0 0 0 0 1\n");
    match read_tum(&p, &strict()).unwrap_err() {
        ImuError::Timestamp { line, problem, .. } => assert_eq!((line, problem), (3, TimestampProblem::NotIncreasing)),
        e => panic!("{e:?}"),
    }
}

#[test]
fn missing_file_is_not_found() {
    assert!(matches!(
        read_tum(data("nope.tum"), &strict()),
        Err(ImuError::NotFound { .. })
    ));
}

#[test]
fn write_tum_round_trips_bit_for_bit() {
    if !(have("euroc/MH_01_easy/groundtruth_pose.tum") && have("blackbird/clover_yawForward_maxSpeed5p0")) {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("gt.tum");
    for src in [
        "euroc/MH_01_easy/groundtruth_pose.tum",
        "blackbird/clover_yawForward_maxSpeed5p0/val/stamped_groundtruth_imu.txt",
    ] {
        let gt = read_tum(data(src), &strict()).unwrap();
        write_tum(&out, &gt).unwrap();
        let back = read_tum(&out, &strict()).unwrap();
        assert_eq!(back.t_ns, gt.t_ns);
        assert_eq!(back.v.is_some(), gt.v.is_some());
        assert_eq!(bits(&back), bits(&gt));
    }
    let text = std::fs::read_to_string(&out).unwrap();
    assert!(text.starts_with("# timestamp(s) tx ty tz qx qy qz qw"));

    let odd = GroundTruth {
        t_ns: vec![-1_500_000_000, -1, 0, 1_403_636_580_838_560_001],
        p: vec![
            [1.0 / 3.0, -0.0, 1e-300],
            [1e22, 5e-324, -1.0],
            [0.0; 3],
            [4.688319, -1.786938, 0.783338],
        ],
        q_wxyz: vec![
            [1.0, 0.0, 0.0, 0.0],
            [0.5, 0.5, -0.5, 0.5],
            [0.0, 0.0, 0.0, 1.0],
            [0.534108, -0.153029, -0.827383, -0.082152],
        ],
        ..GroundTruth::default()
    };
    write_tum(&out, &odd).unwrap();
    let back = read_tum(&out, &strict()).unwrap();
    assert_eq!(back.t_ns, odd.t_ns);
    assert_eq!(bits(&back), bits(&odd));
    assert!(std::fs::read_to_string(&out)
        .unwrap()
        .starts_with("# timestamp(s) tx ty tz qx qy qz qw\n"));

    let mut bad = odd.clone();
    bad.p[2][1] = f64::INFINITY;
    assert!(matches!(write_tum(&out, &bad), Err(ImuError::InvalidInput(_))));
    let mut bad = odd.clone();
    bad.q_wxyz.pop();
    assert!(matches!(write_tum(&out, &bad), Err(ImuError::InvalidInput(_))));
}

// ---------------------------------------------------------------------------------------------
// One reader for ground truth and aiding trajectories: comments, blank lines, positions only,
// stamps past nine decimals, the csv and asl layouts.

fn traj(layout: TrajectoryLayout, positions_only: bool) -> TrajectoryOptions {
    TrajectoryOptions {
        layout,
        positions_only,
        allow_float_timestamps: false,
    }
}

#[test]
fn comments_and_blank_lines_anywhere_are_skipped() {
    let dir = tempfile::tempdir().unwrap();
    let text = "# t tx ty tz qx qy qz qw\n\n1.0 0 0 0 0 0 0 1\n\n  \n# note\n  # indented note\n2.0 1 0 0 0 0 0 1\n\n";
    let p = write(&dir, "a.tum", text);
    let gt = read_tum(&p, &strict()).unwrap();
    assert_eq!(gt.t_ns, vec![1_000_000_000, 2_000_000_000]);
    let tr = read_trajectory(&p, &traj(TrajectoryLayout::Tum, false)).unwrap();
    assert_eq!(tr.t_ns, gt.t_ns);
    assert_eq!(tr.lines, vec![3, 8]);
    assert_eq!(tr.q_wxyz.as_deref(), Some(&gt.q_wxyz[..]));
    // A blank line does not hide the row after it from the checks.
    let p = write(&dir, "b.tum", "1.0 0 0 0 0 0 0 1\n\n1.1 0 0 nan 0 0 0 1\n");
    match read_tum(&p, &strict()).unwrap_err() {
        ImuError::NonFinite {
            line, column, field, ..
        } => assert_eq!((line, column, field.as_str()), (3, 4, "tz")),
        e => panic!("{e:?}"),
    }
}

#[test]
fn trajectories_allow_a_comment_after_a_row_ground_truth_does_not() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(
        &dir,
        "a.tum",
        "1.0 0 0 0 0 0 0 1\n1.05 0.1 0 0 0 0 0 1  # a comment\n1.10 0.2 0 0 0 0 0 1#x\n",
    );
    let tr = read_trajectory(&p, &traj(TrajectoryLayout::Tum, false)).unwrap();
    assert_eq!(tr.t_ns, vec![1_000_000_000, 1_050_000_000, 1_100_000_000]);
    assert_eq!(tr.p[2], [0.2, 0.0, 0.0]);
    // The ground-truth reader takes a '#' inside a row as a bad field.
    assert!(matches!(
        read_tum(&p, &strict()),
        Err(ImuError::ColumnCount { line: 2, .. })
    ));
}

#[test]
fn four_columns_are_positions_only_where_the_caller_allows_them() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(&dir, "p.tum", "# t x y z\n1.0 0 0 0\n2.0 1 2 3\n");
    let tr = read_trajectory(&p, &traj(TrajectoryLayout::Tum, true)).unwrap();
    assert_eq!(tr.t_ns, vec![1_000_000_000, 2_000_000_000]);
    assert_eq!(tr.p, vec![[0.0; 3], [1.0, 2.0, 3.0]]);
    assert!(tr.q_wxyz.is_none());
    // Poses are still poses with the allowance.
    let poses = write(&dir, "q.tum", "1.0 0 0 0 0 0 0 1\n2.0 1 2 3 0 0 0 1\n");
    let tr = read_trajectory(&poses, &traj(TrajectoryLayout::Tum, true)).unwrap();
    assert_eq!(tr.q_wxyz, Some(vec![[1.0, 0.0, 0.0, 0.0]; 2]));
    // Without it (and for ground truth), 4 columns are a column-count error on the first row.
    for err in [
        read_trajectory(&p, &traj(TrajectoryLayout::Tum, false)).unwrap_err(),
        read_tum(&p, &strict()).unwrap_err(),
    ] {
        match &err {
            ImuError::ColumnCount {
                line, expected, found, ..
            } => assert_eq!((*line, *expected, *found), (2, 8, 4)),
            e => panic!("{e:?}"),
        }
        assert_message(&err, &p, 2, None);
    }
    // One file, one width: a pose row after position rows is an error.
    let p = write(&dir, "m.tum", "1.0 0 0 0\n2.0 1 2 3 0 0 0 1\n");
    assert!(matches!(
        read_trajectory(&p, &traj(TrajectoryLayout::Tum, true)),
        Err(ImuError::ColumnCount {
            line: 2,
            expected: 4,
            found: 8,
            ..
        })
    ));
}

#[test]
fn stamps_are_exact_and_digits_past_the_ns_round_half_to_even() {
    let dir = tempfile::tempdir().unwrap();
    const S: i64 = 1_403_636_579_000_000_000;
    let rows = [
        ("1403636579.763556", S + 763_556_000),     // exact: no float rounding
        ("1403636579.7635560015", S + 763_556_002), // an exact half: to the even ns (up)
        ("1403636579.7635560035", S + 763_556_004),
        ("1403636579.76355600650000000001", S + 763_556_007), // past the half: up
        ("1403636579.7635560085", S + 763_556_008),           // an exact half: to the even ns (down)
        ("1403636579.7635560094999", S + 763_556_009),        // below the half: down
        ("1403636580", S + 1_000_000_000),
        ("14036365.8000000001e2", S + 1_000_000_010), // exponent notation: exact too
    ];
    let text: String = rows.iter().map(|(t, _)| format!("{t} 0 0 0 0 0 0 1\n")).collect();
    let want: Vec<i64> = rows.iter().map(|r| r.1).collect();
    let p = write(&dir, "s.tum", &text);
    assert_eq!(read_tum(&p, &strict()).unwrap().t_ns, want);
    assert_eq!(
        read_trajectory(&p, &traj(TrajectoryLayout::Tum, false)).unwrap().t_ns,
        want
    );
    // Ties below the ns on either side of an even ns: 1.0000000005 s is 1 s, not 1 s + 1 ns, so
    // it duplicates the stamp above it.
    let p = write(&dir, "d.tum", "1.0 0 0 0 0 0 0 1\n1.0000000005 0 0 0 0 0 0 1\n");
    match read_tum(&p, &strict()).unwrap_err() {
        ImuError::Timestamp {
            line, value, problem, ..
        } => assert_eq!((line, value, problem), (2, 1_000_000_000, TimestampProblem::Duplicate)),
        e => panic!("{e:?}"),
    }
}

#[test]
fn csv_and_asl_layouts_read_the_same_poses() {
    let dir = tempfile::tempdir().unwrap();
    let csv = write(
        &dir,
        "a.csv",
        "t,x,y,z,qx,qy,qz,qw\n1.0,0,0,0,0,0,0,1\n\n2.0, 1, 0, 0, 1, 0, 0, 0 # note\n",
    );
    let asl = write(
        &dir,
        "b.csv",
        "#timestamp,p,p,p,qw,qx,qy,qz\n1000000000,0,0,0,1,0,0,0\n2000000000,1,0,0,0,1,0,0\n",
    );
    let a = read_trajectory(&csv, &traj(TrajectoryLayout::Csv, false)).unwrap();
    let b = read_trajectory(&asl, &traj(TrajectoryLayout::Asl, false)).unwrap();
    assert_eq!(a.t_ns, vec![1_000_000_000, 2_000_000_000]);
    assert_eq!((&a.t_ns, &a.p, &a.q_wxyz), (&b.t_ns, &b.p, &b.q_wxyz));
    assert_eq!(a.q_wxyz.unwrap()[1], [0.0, 1.0, 0.0, 0.0]);
    assert_eq!((a.lines, b.lines), (vec![2, 4], vec![2, 3]));
    // asl stamps are integer ns; errors use the layout's names.
    let bad = write(&dir, "c.csv", "1000000000,0,0,0,1,0,0,0\n2.0e9,1,0,0,0,1,0,0\n");
    let err = read_trajectory(&bad, &traj(TrajectoryLayout::Asl, false)).unwrap_err();
    assert!(
        matches!(err, ImuError::FloatTimestamp { line: 2, column: 1, .. }),
        "{err:?}"
    );
    let bad = write(&dir, "d.csv", "1000000000,0,0,0,1,0,0,0\n2000000000,1,0,0,x,1,0,0\n");
    let err = read_trajectory(&bad, &traj(TrajectoryLayout::Asl, false)).unwrap_err();
    assert_message(&err, &bad, 2, Some("qw"));
    assert!(TrajectoryLayout::parse("kitti").is_err());
    assert_eq!(TrajectoryLayout::parse("asl").unwrap(), TrajectoryLayout::Asl);
}

#[test]
fn one_trajectory_row_is_too_few() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(&dir, "one.tum", "# only a comment\n1.0 0 0 0 0 0 0 1\n");
    match read_trajectory(&p, &traj(TrajectoryLayout::Tum, false)).unwrap_err() {
        ImuError::TooFewRows { line, found, .. } => assert_eq!((line, found), (2, 1)),
        e => panic!("{e:?}"),
    }
}
