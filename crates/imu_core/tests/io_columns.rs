//! A user's own IMU CSV (`imu_core::io::columns`): random column orders, skipped and extra
//! columns, units, delimiters, headers and comments read back to the samples they were printed
//! from; the writer puts new samples into such a file, keeping every other byte; arbitrary bytes
//! give data or a typed error, never a panic.

use std::fmt::Write as _;

use imu_core::io::columns::{self, CsvFormat, STANDARD_GRAVITY};
use imu_core::ImuError;
use proptest::prelude::*;

const DELIMS: [&str; 4] = [",", ";", "\t", " "];
const TIME_UNITS: [(&str, u32); 4] = [("s", 9), ("ms", 6), ("us", 3), ("ns", 0)];

/// A file layout: the map (quantity or skip per column), units, delimiter, header, comments.
#[derive(Clone, Debug)]
struct Layout {
    /// File columns: Some(k) holds quantity k of t,gx,gy,gz,ax,ay,az; None a skipped text column.
    cols: Vec<Option<usize>>,
    extra: usize,
    time: usize,
    deg: bool,
    in_g: bool,
    delim: usize,
    header: bool,
    comment_every: usize,
    float_ns: bool,
}

fn layout() -> impl Strategy<Value = Layout> {
    (
        Just((0..7).collect::<Vec<usize>>()).prop_shuffle(),
        proptest::collection::vec(0usize..8, 0..3),
        (0usize..3, 0usize..4, any::<bool>(), any::<bool>()),
        (0usize..4, any::<bool>(), 0usize..5, any::<bool>()),
    )
        .prop_map(
            |(order, skips, (extra, time, deg, in_g), (delim, header, comment_every, float_ns))| {
                let mut cols: Vec<Option<usize>> = order.into_iter().map(Some).collect();
                for s in skips {
                    cols.insert(s.min(cols.len()), None);
                }
                Layout {
                    cols,
                    extra,
                    time,
                    deg,
                    in_g,
                    delim,
                    header,
                    comment_every,
                    float_ns,
                }
            },
        )
}

impl Layout {
    fn format(&self) -> CsvFormat {
        let names = ["t", "gx", "gy", "gz", "ax", "ay", "az"];
        let map: Vec<&str> = self.cols.iter().map(|c| c.map_or("_", |k| names[k])).collect();
        CsvFormat::parse(
            &map.join(","),
            TIME_UNITS[self.time].0,
            if self.deg { "deg/s" } else { "rad/s" },
            if self.in_g { "g" } else { "m/s2" },
        )
        .unwrap()
    }
}

/// `t_ns` as exact decimal text in units of 10^digits ns (`1.000000250` s).
fn time_text(t_ns: i64, digits: u32, float_ns: bool) -> String {
    if digits == 0 {
        return if float_ns {
            format!("{t_ns}.0")
        } else {
            t_ns.to_string()
        };
    }
    let d = 10i64.pow(digits);
    let sign = if t_ns < 0 { "-" } else { "" };
    let a = t_ns.unsigned_abs();
    format!("{sign}{}.{:0w$}", a / d as u64, a % d as u64, w = digits as usize)
}

#[derive(Clone, Debug)]
struct Samples {
    t: Vec<i64>,
    g: Vec<[f64; 3]>,
    a: Vec<[f64; 3]>,
}

fn samples() -> impl Strategy<Value = Samples> {
    proptest::collection::vec(
        (
            1i64..5_000_000_000,
            proptest::array::uniform3(-30.0f64..30.0),
            proptest::array::uniform3(-100.0f64..100.0),
        ),
        2..40,
    )
    .prop_flat_map(|rows| {
        (Just(rows), 0i64..2_000_000_000_000_000_000).prop_map(|(rows, t0)| {
            let mut t = t0;
            let mut s = Samples {
                t: Vec::new(),
                g: Vec::new(),
                a: Vec::new(),
            };
            for (dt, g, a) in rows {
                t += dt;
                s.t.push(t);
                s.g.push(g);
                s.a.push(a);
            }
            s
        })
    })
}

/// The file's text, each value printed in the layout's units.
fn print(l: &Layout, s: &Samples) -> String {
    let d = DELIMS[l.delim];
    let mut out = String::from("# written by a test\n");
    if l.header {
        let mut names: Vec<String> = (0..l.cols.len()).map(|i| format!("c{i}")).collect();
        names.extend((0..l.extra).map(|i| format!("x{i}")));
        let _ = writeln!(out, "{}", names.join(d));
    }
    for i in 0..s.t.len() {
        if l.comment_every > 0 && i % l.comment_every == 1 {
            out.push_str("# a note\n\n");
        }
        let mut f: Vec<String> = l
            .cols
            .iter()
            .map(|c| match *c {
                None => format!("n{i}"),
                Some(0) => time_text(s.t[i], TIME_UNITS[l.time].1, l.float_ns),
                Some(k) if k < 4 => {
                    let x = s.g[i][k - 1];
                    format!("{}", if l.deg { x.to_degrees() } else { x })
                }
                Some(k) => {
                    let x = s.a[i][k - 4];
                    format!("{}", if l.in_g { x / STANDARD_GRAVITY } else { x })
                }
            })
            .collect();
        f.extend((0..l.extra).map(|j| format!("e{j}")));
        let _ = writeln!(out, "{}", f.join(d));
    }
    out
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-13 * b.abs().max(1e-300)
}

proptest! {
    // 64 cases by default (a debug `cargo test`); PROPTEST_CASES runs more (`just fuzz`).
    #![proptest_config(ProptestConfig {
        cases: std::env::var("PROPTEST_CASES").ok().and_then(|s| s.parse().ok()).unwrap_or(64),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    #[test]
    fn printed_samples_read_back(l in layout(), s in samples()) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("imu.csv");
        std::fs::write(&path, print(&l, &s)).unwrap();
        let fmt = l.format();
        let got = columns::read_imu(&path, &fmt).unwrap();
        prop_assert_eq!(&got.t_ns, &s.t);
        for i in 0..s.t.len() {
            for j in 0..3 {
                prop_assert!(close(got.gyro[i][j], s.g[i][j]), "{} vs {}", got.gyro[i][j], s.g[i][j]);
                prop_assert!(close(got.acc[i][j], s.a[i][j]), "{} vs {}", got.acc[i][j], s.a[i][j]);
            }
        }
        // The writer: new samples go in, everything else stays, and they read back.
        let new_g: Vec<[f64; 3]> = s.g.iter().map(|g| [g[1] * 0.5, -g[2], g[0] + 1e-3]).collect();
        let new_a: Vec<[f64; 3]> = s.a.iter().map(|a| [a[2], a[0] * 1.01, -a[1]]).collect();
        let out = dir.path().join("refined.csv");
        columns::write_imu(&path, &out, &fmt, &new_g, &new_a).unwrap();
        let back = columns::read_imu(&out, &fmt).unwrap();
        prop_assert_eq!(&back.t_ns, &s.t);
        for i in 0..s.t.len() {
            for j in 0..3 {
                prop_assert!(close(back.gyro[i][j], new_g[i][j]));
                prop_assert!(close(back.acc[i][j], new_a[i][j]));
            }
        }
        let (before, after) = (std::fs::read_to_string(&path).unwrap(), std::fs::read_to_string(&out).unwrap());
        prop_assert_eq!(before.lines().count(), after.lines().count());
        let imu_cols: Vec<usize> = l.cols.iter().enumerate().filter(|(_, c)| matches!(c, Some(k) if *k > 0)).map(|(i, _)| i).collect();
        for (x, y) in before.lines().zip(after.lines()) {
            if x.starts_with('#') || x.trim().is_empty() || (l.header && x.starts_with("c0")) {
                prop_assert_eq!(x, y);
                continue;
            }
            let split = |s: &str| -> Vec<String> {
                if DELIMS[l.delim] == " " { s.split_whitespace().map(String::from).collect() }
                else { s.split(DELIMS[l.delim]).map(String::from).collect() }
            };
            let (fx, fy) = (split(x), split(y));
            prop_assert_eq!(fx.len(), fy.len());
            for (i, (p, q)) in fx.iter().zip(&fy).enumerate() {
                if !imu_cols.contains(&i) {
                    prop_assert_eq!(p, q);
                }
            }
        }
        // Writing back the samples as read reproduces the file byte for byte where the printed
        // text was already the shortest (SI units always are).
        if !l.deg && !l.in_g {
            columns::write_imu(&path, &out, &fmt, &got.gyro, &got.acc).unwrap();
            prop_assert_eq!(std::fs::read_to_string(&out).unwrap(), before);
        }
    }

    #[test]
    fn arbitrary_bytes_give_data_or_a_typed_error(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.csv");
        std::fs::write(&path, &bytes).unwrap();
        let fmt = CsvFormat::parse("t,gx,gy,gz,ax,ay,az", "s", "rad/s", "m/s2").unwrap();
        match columns::read_imu(&path, &fmt) {
            Ok(s) => prop_assert!(s.t_ns.len() >= 2 && s.t_ns.windows(2).all(|w| w[1] > w[0])),
            Err(e) => prop_assert!(matches!(
                e,
                ImuError::MissingColumn { .. }
                    | ImuError::NotNumeric { .. }
                    | ImuError::NonFinite { .. }
                    | ImuError::Timestamp { .. }
                    | ImuError::TooFewRows { .. }
            ), "{e:?}"),
        }
    }
}

#[test]
fn a_long_file_reads_in_parallel_chunks_with_the_right_lines() {
    // Enough rows for several chunks; one bad value far down is reported at its own line.
    let mut text = String::from("time,wx,wy,wz,ax,ay,az\n");
    for i in 0..60_000 {
        let _ = writeln!(text, "{}.{:03},0.1,0.2,0.3,0,0,1", i / 1000, i % 1000);
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("long.csv");
    std::fs::write(&path, &text).unwrap();
    let fmt = CsvFormat::parse("t,gx,gy,gz,ax,ay,az", "s", "deg/s", "g").unwrap();
    let s = columns::read_imu(&path, &fmt).unwrap();
    assert_eq!(s.t_ns.len(), 60_000);
    assert_eq!(s.t_ns[59_999], 59_999_000_000);
    assert_eq!(s.acc[7][2], STANDARD_GRAVITY);
    let bad = text.replacen("54.321,0.1,0.2", "54.321,0.1,zz", 1);
    std::fs::write(&path, bad).unwrap();
    let e = columns::read_imu(&path, &fmt).unwrap_err();
    assert!(
        matches!(&e, ImuError::NotNumeric { line: 54_323, column: 3, field, .. } if field == "wy (gy)"),
        "{e}"
    );
}

#[test]
fn skip_bad_lines_passes_over_truncated_lines_and_lists_them() {
    // A logger's log: the first line cut at its start (a single field: no delimiter to go by), a
    // bad value in the middle, the last line cut short; many rows, so the parallel chunks meet.
    let mut text = String::from("0.0041\n");
    for i in 0..30_000 {
        let _ = writeln!(text, "{}.{:03};0.1;0.2;0.3;0;0;1;ok", i / 1000, i % 1000);
    }
    text = text.replacen("12.345;0.1;0.2", "12.345;0.1;nan", 1);
    text.push_str("30.000;0.1;0.");
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("log.csv");
    std::fs::write(&path, &text).unwrap();
    let strict = CsvFormat::parse("t,gx,gy,gz,ax,ay,az", "s", "rad/s", "m/s2").unwrap();
    // Without the flag: the first bad line, as before.
    let e = columns::read_imu(&path, &strict).unwrap_err();
    assert!(matches!(&e, ImuError::MissingColumn { line: 1, .. }), "{e}");
    let fmt = strict.clone().with_skip_bad_lines(true);
    let r = columns::read_imu_checked(&path, &fmt).unwrap();
    assert_eq!(r.samples.t_ns.len(), 30_000 - 1);
    let lines: Vec<usize> = r.skipped.iter().map(|s| s.line).collect();
    assert_eq!(lines, vec![1, 12_347, 30_002]);
    assert!(
        r.skipped[0].problem.contains("log.csv:1:2: field \"gx\" is missing"),
        "{:?}",
        r.skipped[0]
    );
    assert!(
        r.skipped[1].problem.contains("\"nan\" is not finite"),
        "{:?}",
        r.skipped[1]
    );
    assert!(
        r.skipped[2]
            .problem
            .contains("log.csv:30002:4: field \"gz\" is missing"),
        "{:?}",
        r.skipped[2]
    );
    assert_eq!(r.fields, 8);
    assert!(r.names.is_empty());
    // The writer keeps the skipped lines as they were, and rewrites the rest.
    let n = r.samples.t_ns.len();
    let out = dir.path().join("out.csv");
    columns::write_imu(&path, &out, &fmt, &vec![[1.0, 2.0, 3.0]; n], &r.samples.acc).unwrap();
    let back = std::fs::read_to_string(&out).unwrap();
    let (a, b): (Vec<&str>, Vec<&str>) = (text.lines().collect(), back.lines().collect());
    assert_eq!(a.len(), b.len());
    for l in [0, 12_346, 30_001] {
        assert_eq!(a[l], b[l]);
    }
    assert_eq!(b[1], "0.000;1;2;3;0;0;1;ok");
    assert!(columns::write_imu(&path, &out, &strict, &vec![[1.0, 2.0, 3.0]; n], &r.samples.acc).is_err());
}

#[test]
fn skip_bad_lines_passes_over_a_truncated_line_above_the_header() {
    let text = "t_s,wx\ntime,wx,wy,wz,ax,ay,az,temp\n0.0,0,0,0,0,0,9.8,20,\n0.01,0,0,0,0,0,9.8,20\n";
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("h.csv");
    std::fs::write(&path, text).unwrap();
    let fmt = CsvFormat::parse("t,gx,gy,gz,ax,ay,az", "s", "rad/s", "m/s2")
        .unwrap()
        .with_skip_bad_lines(true);
    let r = columns::read_imu_checked(&path, &fmt).unwrap();
    assert_eq!(r.samples.t_ns, vec![0, 10_000_000]);
    assert_eq!(r.skipped.iter().map(|s| s.line).collect::<Vec<_>>(), vec![1]);
    assert_eq!(r.names[7], "temp");
    assert_eq!(r.fields, 8);
    // Stamps out of order stay an error.
    std::fs::write(&path, format!("{text}0.005,0,0,0,0,0,9.8,20\n")).unwrap();
    assert!(matches!(
        columns::read_imu_checked(&path, &fmt),
        Err(ImuError::Timestamp { line: 5, .. })
    ));
}

#[test]
fn skip_bad_lines_that_skips_every_line_names_the_first_lines_error() {
    // nanosecond stamps read as seconds: every stamp overflows; skipping them all must not turn the
    // precise error (the unit) into "no samples"
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ns.csv");
    let mut text = String::from("t,gx,gy,gz,ax,ay,az\n");
    for i in 0..50u64 {
        writeln!(text, "{},0,0,0,0,0,9.8", 1_403_636_579_758_555_392u64 + i * 5_000_000).unwrap();
    }
    std::fs::write(&path, &text).unwrap();
    let fmt = CsvFormat::parse("t,gx,gy,gz,ax,ay,az", "s", "rad/s", "m/s2").unwrap();
    let strict = columns::read_imu(&path, &fmt).unwrap_err().to_string();
    let skipping = columns::read_imu_checked(&path, &fmt.with_skip_bad_lines(true))
        .unwrap_err()
        .to_string();
    assert!(strict.contains("ns.csv:2:1"), "{strict}");
    assert_eq!(skipping, strict);
}

proptest! {
    #[test]
    fn arbitrary_bytes_skipping_bad_lines_give_data_or_a_typed_error(
        bytes in proptest::collection::vec(any::<u8>(), 0..400)
    ) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.csv");
        std::fs::write(&path, &bytes).unwrap();
        let fmt = CsvFormat::parse("t,gx,gy,gz,ax,ay,az", "s", "rad/s", "m/s2").unwrap().with_skip_bad_lines(true);
        match columns::read_imu_checked(&path, &fmt) {
            Ok(r) => {
                prop_assert!(r.samples.t_ns.len() >= 2 && r.samples.t_ns.windows(2).all(|w| w[1] > w[0]));
                prop_assert!(r.skipped.windows(2).all(|w| w[1].line > w[0].line));
            }
            // stamps out of order stay an error; a file with too few good lines gets the first skipped
            // line's own error (what was wrong with it), or too few rows where none was skipped
            Err(e) => prop_assert!(
                matches!(
                    e,
                    ImuError::Timestamp { .. }
                        | ImuError::TooFewRows { .. }
                        | ImuError::MissingColumn { .. }
                        | ImuError::NotNumeric { .. }
                        | ImuError::NonFinite { .. }
                        | ImuError::FloatTimestamp { .. }
                ),
                "{e:?}"
            ),
        }
    }
}
