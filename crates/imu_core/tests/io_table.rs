//! The shared table rules, exercised through the ASL IMU reader (the most used path) and the
//! table API directly.

mod io_common;
use io_common as common;

use common::*;
use imu_core::error::TimestampProblem;
use imu_core::io::asl::read_imu;
use imu_core::io::columns::{self, CsvFormat};
use imu_core::io::table::{read_table, Separator, TableSpec, TimeUnit};
use imu_core::io::tum::{read_trajectory, read_tum, TrajectoryLayout, TrajectoryOptions};
use imu_core::io::ReadOptions;
use imu_core::ImuError;

const T0: i64 = 1_403_636_579_758_560_000;

fn strict() -> ReadOptions {
    ReadOptions::default()
}

fn lenient() -> ReadOptions {
    ReadOptions {
        allow_float_timestamps: true,
    }
}

#[test]
fn missing_file_is_not_found() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("nope.csv");
    let err = read_imu(&p, &strict()).unwrap_err();
    match &err {
        ImuError::NotFound { path } => assert_eq!(path, &p),
        e => panic!("{e:?}"),
    }
    assert!(err.to_string().contains(&p.display().to_string()));
}

#[test]
fn wrong_column_count() {
    let dir = tempfile::tempdir().unwrap();
    let mut l = imu_lines(5);
    l[3] = format!("{},0.1,0.2,0.3,9.8,0.1", T0 + 10_000_000);
    let p = write(&dir, "a.csv", &join(&l));
    let err = read_imu(&p, &strict()).unwrap_err();
    match &err {
        ImuError::ColumnCount {
            path,
            line,
            expected,
            found,
        } => {
            assert_eq!((path, *line, *expected, *found), (&p, 4, 7, 6));
        }
        e => panic!("{e:?}"),
    }
    assert_message(&err, &p, 4, None);
}

#[test]
fn non_numeric_field() {
    let dir = tempfile::tempdir().unwrap();
    let mut l = imu_lines(5);
    l[2] = format!("{},0.1,0.2,abc,9.8,0.1,0.2", T0 + 5_000_000);
    let p = write(&dir, "a.csv", &join(&l));
    let err = read_imu(&p, &strict()).unwrap_err();
    match &err {
        ImuError::NotNumeric {
            path,
            line,
            column,
            field,
            value,
            ..
        } => {
            assert_eq!((path, *line, *column), (&p, 3, 4));
            assert_eq!(field, "w_RS_S_z [rad s^-1]");
            assert_eq!(value, "abc");
        }
        e => panic!("{e:?}"),
    }
    assert_message(&err, &p, 3, Some("w_RS_S_z [rad s^-1]"));
}

#[test]
fn empty_field_is_not_numeric() {
    let dir = tempfile::tempdir().unwrap();
    let mut l = imu_lines(5);
    l[5] = format!("{},0.1,0.2,0.3,9.8,,0.2", T0 + 20_000_000);
    let p = write(&dir, "a.csv", &join(&l));
    let err = read_imu(&p, &strict()).unwrap_err();
    match &err {
        ImuError::NotNumeric {
            line,
            column,
            field,
            value,
            ..
        } => {
            assert_eq!(
                (*line, *column, field.as_str(), value.as_str()),
                (6, 6, "a_RS_S_y [m s^-2]", "")
            );
        }
        e => panic!("{e:?}"),
    }
    assert_message(&err, &p, 6, Some("a_RS_S_y [m s^-2]"));
}

#[test]
fn non_numeric_timestamp() {
    let dir = tempfile::tempdir().unwrap();
    let mut l = imu_lines(3);
    l[2] = "12:00:01,0.1,0.2,0.3,9.8,0.1,0.2".into();
    let p = write(&dir, "a.csv", &join(&l));
    let err = read_imu(&p, &strict()).unwrap_err();
    match &err {
        ImuError::NotNumeric {
            line,
            column,
            field,
            value,
            ..
        } => {
            assert_eq!(
                (*line, *column, field.as_str(), value.as_str()),
                (3, 1, "timestamp [ns]", "12:00:01")
            );
        }
        e => panic!("{e:?}"),
    }
    assert_message(&err, &p, 3, Some("timestamp [ns]"));
}

#[test]
fn nan_and_inf_are_non_finite() {
    let dir = tempfile::tempdir().unwrap();
    for (bad, col, field) in [
        ("NaN", 2, "w_RS_S_x [rad s^-1]"),
        ("-inf", 7, "a_RS_S_z [m s^-2]"),
        ("nan", 1, "timestamp [ns]"),
    ] {
        let mut l = imu_lines(4);
        let mut fields: Vec<String> = l[3].split(',').map(String::from).collect();
        fields[col - 1] = bad.into();
        l[3] = fields.join(",");
        let p = write(&dir, "a.csv", &join(&l));
        let err = read_imu(&p, &strict()).unwrap_err();
        match &err {
            ImuError::NonFinite {
                path,
                line,
                column,
                field: f,
                value,
            } => {
                assert_eq!(
                    (path, *line, *column, f.as_str(), value.as_str()),
                    (&p, 4, col, field, bad)
                );
            }
            e => panic!("{e:?}"),
        }
        assert_message(&err, &p, 4, Some(field));
    }
}

#[test]
fn float_notation_timestamp_rejected_by_default_and_exact_with_option() {
    let dir = tempfile::tempdir().unwrap();
    let mut l = imu_lines(2);
    l[2] = "1.40363657976356E+018,0.1,0.2,0.3,9.8,0.1,0.2".into();
    let p = write(&dir, "a.csv", &join(&l));
    let err = read_imu(&p, &strict()).unwrap_err();
    match &err {
        ImuError::FloatTimestamp {
            path,
            line,
            column,
            field,
            value,
        } => {
            assert_eq!((path, *line, *column), (&p, 3, 1));
            assert_eq!(
                (field.as_str(), value.as_str()),
                ("timestamp [ns]", "1.40363657976356E+018")
            );
        }
        e => panic!("{e:?}"),
    }
    assert_message(&err, &p, 3, Some("timestamp [ns]"));
    let imu = read_imu(&p, &lenient()).unwrap();
    assert_eq!(imu.t_ns, vec![T0, 1_403_636_579_763_560_000]);
}

#[test]
fn duplicate_and_decreasing_timestamps() {
    let dir = tempfile::tempdir().unwrap();
    for (t, problem) in [
        (T0 + 5_000_000, TimestampProblem::Duplicate),
        (T0 + 1, TimestampProblem::NotIncreasing),
    ] {
        let mut l = imu_lines(4);
        l[3] = imu_row(t);
        let p = write(&dir, "a.csv", &join(&l));
        let err = read_imu(&p, &strict()).unwrap_err();
        match &err {
            ImuError::Timestamp {
                path,
                line,
                column,
                field,
                value,
                previous,
                problem: pr,
            } => {
                assert_eq!((path, *line, *column, field.as_str()), (&p, 4, 1, "timestamp [ns]"));
                assert_eq!((*value, *previous, *pr), (t, T0 + 5_000_000, problem));
            }
            e => panic!("{e:?}"),
        }
        assert_message(&err, &p, 4, Some("timestamp [ns]"));
    }
}

#[test]
fn crlf_bom_and_trailing_blank_lines_are_fine() {
    let dir = tempfile::tempdir().unwrap();
    let text = format!("\u{feff}{}\r\n\r\n\n  \n", imu_lines(3).join("\r\n"));
    let p = write(&dir, "a.csv", &text);
    let imu = read_imu(&p, &strict()).unwrap();
    assert_eq!(imu.len(), 3);
    assert_eq!(imu.acc[2], [9.81, 0.01, -0.02]);
}

/// Dataset tables (ASL, KAIST) keep the strict rule: a blank line inside the data is a sign of a
/// damaged or concatenated recording (the property tests of `parse_table` pin it too).
#[test]
fn blank_line_between_rows_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let mut l = imu_lines(4);
    l.insert(3, String::new());
    let p = write(&dir, "a.csv", &join(&l));
    let err = read_imu(&p, &strict()).unwrap_err();
    match &err {
        ImuError::ColumnCount {
            line, expected, found, ..
        } => assert_eq!((*line, *expected, *found), (4, 7, 0)),
        e => panic!("{e:?}"),
    }
    assert_message(&err, &p, 4, None);
}

#[test]
fn trailing_junk_dropped_only_with_option() {
    let dir = tempfile::tempdir().unwrap();
    let mut l = imu_lines(3);
    l.extend([",,,,,,", "1403636763.853,,,,,,", "Step: 0.005 = 1/200,,,,,,"].map(String::from));
    let p = write(&dir, "a.csv", &join(&l));
    let err = read_imu(&p, &strict()).unwrap_err();
    match &err {
        ImuError::NotNumeric {
            line,
            column,
            field,
            value,
            ..
        } => {
            assert_eq!(
                (*line, *column, field.as_str(), value.as_str()),
                (5, 1, "timestamp [ns]", "")
            );
        }
        e => panic!("{e:?}"),
    }
    assert_message(&err, &p, 5, Some("timestamp [ns]"));
    assert_eq!(read_imu(&p, &lenient()).unwrap().len(), 3);

    // Junk followed by data is not trailing: the junk line is the error, even with the option.
    l.push(imu_row(T0 + 1_000_000_000));
    let p = write(&dir, "b.csv", &join(&l));
    let err = read_imu(&p, &lenient()).unwrap_err();
    match &err {
        ImuError::NotNumeric { line, column, .. } => assert_eq!((*line, *column), (5, 1)),
        e => panic!("{e:?}"),
    }
}

/// Big enough for several parallel chunks: errors must still be the first in file order and
/// carry the right line numbers from later chunks.
#[test]
fn first_bad_row_in_file_order_across_chunks() {
    let dir = tempfile::tempdir().unwrap();
    let n = 40_000;
    let base = imu_lines(n);

    let mut l = base.clone();
    l[30_000] = l[30_000].replace(",0.3,", ",inf,");
    l[12_000] = l[12_000].replace(",0.3,", ",x,");
    let p = write(&dir, "a.csv", &join(&l));
    let err = read_imu(&p, &strict()).unwrap_err();
    match &err {
        ImuError::NotNumeric { line, column, .. } => assert_eq!((*line, *column), (12_001, 4)),
        e => panic!("{e:?}"),
    }

    let mut l = base.clone();
    l[35_000] = l[35_000].replace(",0.3,", ",inf,");
    let p = write(&dir, "b.csv", &join(&l));
    match read_imu(&p, &strict()).unwrap_err() {
        ImuError::NonFinite { line, column, .. } => assert_eq!((line, column), (35_001, 4)),
        e => panic!("{e:?}"),
    }

    let mut l = base.clone();
    l[38_000] = l[37_999].clone();
    let p = write(&dir, "c.csv", &join(&l));
    match read_imu(&p, &strict()).unwrap_err() {
        ImuError::Timestamp { line, problem, .. } => assert_eq!((line, problem), (38_001, TimestampProblem::Duplicate)),
        e => panic!("{e:?}"),
    }

    let p = write(&dir, "d.csv", &join(&base));
    let imu = read_imu(&p, &strict()).unwrap();
    assert_eq!(imu.len(), n);
    assert!(imu.t_ns.windows(2).all(|w| w[1] - w[0] == 5_000_000));
}

#[test]
fn table_api_headerless_whitespace_with_fixed_names() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(&dir, "t.txt", "# c\n1.5 2 3\n2.000000001   4 x\n");
    let spec = TableSpec {
        separator: Separator::Whitespace,
        columns: vec![3],
        time_unit: TimeUnit::Seconds,
        header_line: false,
        hash_comments: true,
        names: vec!["t".into(), "a".into(), "b".into()],
        allow_float_timestamps: false,
    };
    let err = read_table(&p, &spec).unwrap_err();
    match &err {
        ImuError::NotNumeric {
            line, column, field, ..
        } => assert_eq!((*line, *column, field.as_str()), (3, 3, "b")),
        e => panic!("{e:?}"),
    }
    assert_message(&err, &p, 3, Some("b"));
    let p = write(&dir, "u.txt", "# c\n1.5 2 3\n2.000000001   4 5\n");
    let t = read_table(&p, &spec).unwrap();
    assert_eq!(t.t_ns, vec![1_500_000_000, 2_000_000_001]);
    assert_eq!(t.row(1), &[4.0, 5.0]);
    assert_eq!(t.lines, vec![2, 3]);
}

// ---------------------------------------------------------------------------------------------
// One parser for every reader: the same rules give the same rows and the same errors whether a
// file is read as a dataset table, as a user's CSV (column map) or as a trajectory.

fn user_csv() -> CsvFormat {
    CsvFormat::parse("t,gx,gy,gz,ax,ay,az", "ns", "rad/s", "m/s2").unwrap()
}

/// Blank lines are skipped by the user-CSV reader and the trajectory readers, wherever they are;
/// only dataset tables reject one followed by a row (`blank_line_between_rows_is_an_error`).
#[test]
fn blank_lines_are_skipped_by_the_user_csv_and_trajectory_readers() {
    let dir = tempfile::tempdir().unwrap();
    let mut l = imu_lines(4);
    l.insert(3, String::new());
    l.insert(4, " \t ".into());
    l.insert(1, String::new());
    l.push(String::new());
    let p = write(&dir, "a.csv", &join(&l));
    let r = columns::read_imu_checked(&p, &user_csv()).unwrap();
    assert_eq!(r.samples.len(), 4);
    assert_eq!(r.samples.t_ns[3] - r.samples.t_ns[0], 15_000_000);
    assert!(r.skipped.is_empty());
    // The same file as a dataset table: the blank line after the header is followed by a row.
    match read_imu(&p, &strict()).unwrap_err() {
        ImuError::ColumnCount { line, found, .. } => assert_eq!((line, found), (2, 0)),
        e => panic!("{e:?}"),
    }

    let text = "\n1.0 0 0 0 0 0 0 1\n\n\n2.0 1 0 0 0 0 0 1\n \n3.0 2 0 0 0 0 0 1\n\n";
    let p = write(&dir, "t.tum", text);
    assert_eq!(
        read_tum(&p, &strict()).unwrap().t_ns,
        vec![1_000_000_000, 2_000_000_000, 3_000_000_000]
    );
    let opts = TrajectoryOptions {
        layout: TrajectoryLayout::Tum,
        positions_only: false,
        allow_float_timestamps: false,
    };
    assert_eq!(read_trajectory(&p, &opts).unwrap().lines, vec![2, 5, 7]);
}

/// A bad field is the same error, at the same place, through either entry to the parser.
#[test]
fn bad_fields_are_the_same_error_in_the_table_and_the_user_csv_reader() {
    let dir = tempfile::tempdir().unwrap();
    for (bad, col) in [("abc", 4), ("", 6), ("nan", 2), ("-inf", 7), ("x1", 1)] {
        let mut l = imu_lines(4);
        let mut fields: Vec<String> = l[3].split(',').map(String::from).collect();
        fields[col - 1] = bad.into();
        l[3] = fields.join(",");
        let p = write(&dir, "a.csv", &join(&l));
        let table = read_imu(&p, &strict()).unwrap_err();
        let user = columns::read_imu(&p, &user_csv()).unwrap_err();
        let place = |e: &ImuError| match e {
            ImuError::NotNumeric {
                line, column, value, ..
            } => ("NotNumeric", *line, *column, value.clone()),
            ImuError::NonFinite {
                line, column, value, ..
            } => ("NonFinite", *line, *column, value.clone()),
            e => panic!("{e:?}"),
        };
        assert_eq!(place(&table), place(&user), "{bad:?}");
        assert_eq!(place(&table).1, 4);
        assert_eq!(place(&table).2, col);
        // Both name the field from the header; the user's reader adds the map's name.
        let name = IMU_HEADER
            .split(',')
            .nth(col - 1)
            .unwrap()
            .trim_start_matches('#')
            .to_string();
        assert_message(&table, &p, 4, Some(&name));
        assert!(user.to_string().contains(&name), "{user}");
    }
}

/// Time past the ns rounds half to even in every reader (the one decimal rule).
#[test]
fn time_past_the_ns_rounds_half_to_even_in_every_reader() {
    let dir = tempfile::tempdir().unwrap();
    // An exact half to the even ns below, one to the even ns above, just past a half up.
    let stamps = ["1.0000000005", "1.0000000015", "1.00000000250001"];
    let want = vec![1_000_000_000, 1_000_000_002, 1_000_000_003];
    let user: String = stamps.iter().map(|t| format!("{t},0,0,0,0,0,9.8\n")).collect();
    let p = write(&dir, "u.csv", &user);
    let fmt = CsvFormat::parse("t,gx,gy,gz,ax,ay,az", "s", "rad/s", "m/s2").unwrap();
    assert_eq!(columns::read_imu(&p, &fmt).unwrap().t_ns, want);
    let tum: String = stamps.iter().map(|t| format!("{t} 0 0 0 0 0 0 1\n")).collect();
    let p = write(&dir, "t.tum", &tum);
    assert_eq!(read_tum(&p, &strict()).unwrap().t_ns, want);
    let spec = TableSpec {
        separator: Separator::Comma,
        columns: vec![2],
        time_unit: TimeUnit::Seconds,
        header_line: false,
        hash_comments: false,
        names: Vec::new(),
        allow_float_timestamps: false,
    };
    let p = write(
        &dir,
        "t.csv",
        &stamps.iter().map(|t| format!("{t},1\n")).collect::<String>(),
    );
    assert_eq!(read_table(&p, &spec).unwrap().t_ns, want);
    // Float-notation ns (allowed by the option) round the same way: 2.5 ns is 2 ns, 3.5 ns is 4.
    let mut l = imu_lines(0);
    l.push("25e-1,0.1,-0.2,0.3,9.81,0.01,-0.02".into());
    l.push("3.5,0.1,-0.2,0.3,9.81,0.01,-0.02".into());
    let p = write(&dir, "f.csv", &join(&l));
    assert_eq!(read_imu(&p, &lenient()).unwrap().t_ns, vec![2, 4]);
}
