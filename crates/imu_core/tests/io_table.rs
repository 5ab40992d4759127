//! The shared table rules, exercised through the ASL IMU reader (the most used path) and the
//! table API directly.

mod io_common;
use io_common as common;

use common::*;
use imu_core::error::TimestampProblem;
use imu_core::io::asl::read_imu;
use imu_core::io::table::{read_table, Separator, TableSpec, TimeUnit};
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
