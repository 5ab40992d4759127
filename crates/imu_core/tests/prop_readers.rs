//! Property tests of every reader in `imu_core::io` (issue 13): arbitrary bytes and mutated real
//! files (truncated, a byte flipped, lines duplicated/deleted/swapped, CRLF/LF mixed, a BOM,
//! very long lines, huge or negative numbers, 2^63 stamps) never panic and never hang, and give
//! either data or a typed error whose line, column, field name and value are those of the
//! offending cell of the file; random valid data written by `write_imu`/`write_tum`, or printed
//! in each read-only format, reads back bit for bit.
//!
//! Case counts: each property has a small default so that this file stays fast in a debug build
//! (`cargo test` in CI); PROPTEST_CASES overrides them all (`just fuzz` runs many more in
//! release) and every property prints how many cases it ran (visible with `--nocapture`).
//! PROPTEST_RNG_SEED replays a run.

mod common;
mod io_common;

use std::collections::BTreeSet;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc;
use std::time::Duration;

use imu_core::io::table::{self, Separator, TableSpec, TimeUnit};
use imu_core::io::{asl, kaist, tum, ReadOptions};
use imu_core::{GroundTruth, ImuError, ImuSamples};
use proptest::prelude::*;
use proptest::sample::Index;
use proptest::test_runner::{Config, TestCaseError, TestRunner};

// ---------------------------------------------------------------------------------------------
// Running a property

/// How many cases a property runs: its own default, or, when PROPTEST_CASES is set, that many
/// divided by the property's relative `cost` (1 for a case of a few KB; the multi-MB-line
/// property costs about as much per case as a few hundred of those).
fn case_count(default: u32, cost: u32) -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|s| s.parse::<u32>().ok())
        .map_or(default, |n| (n / cost).max(1))
}

/// Runs `test` on `case_count(default, cost)` values of `strategy`, prints how many cases it actually
/// ran (counted here, not taken from the setting) and panics with proptest's minimal failing
/// case, if any. No failure file is written: a failure becomes a plain regression test.
fn check_property<S: Strategy>(
    name: &str,
    (default, cost): (u32, u32),
    strategy: S,
    test: impl Fn(S::Value) -> Result<(), TestCaseError>,
) {
    let tried = AtomicUsize::new(0);
    let config = Config {
        cases: case_count(default, cost),
        failure_persistence: None,
        ..Config::default()
    };
    let result = TestRunner::new(config).run(&strategy, |value| {
        tried.fetch_add(1, Ordering::Relaxed);
        test(value)
    });
    println!("property {name}: {} cases tried", tried.load(Ordering::Relaxed));
    if let Err(e) = result {
        panic!("property {name} failed: {e}");
    }
}

/// Far longer than any reader needs for the inputs made here (a few MB at most, linear work): a
/// call that has not returned by then is stuck, not slow. This is a hang detector, not a timing.
const HANG_LIMIT: Duration = Duration::from_secs(120);

/// Runs `f` on its own thread and turns a panic or a hang into a failed case (proptest would
/// catch a panic too, but this names what panicked and survives a hang).
fn guarded<T: Send + 'static>(what: &str, f: impl FnOnce() -> T + Send + 'static) -> Result<T, TestCaseError> {
    let (tx, rx) = mpsc::channel();
    let worker = std::thread::spawn(move || {
        let _ = tx.send(std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)));
    });
    match rx.recv_timeout(HANG_LIMIT) {
        Ok(Ok(value)) => {
            let _ = worker.join();
            Ok(value)
        }
        Ok(Err(panic)) => {
            let msg = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_default();
            Err(TestCaseError::fail(format!("{what} panicked: {msg}")))
        }
        Err(_) => Err(TestCaseError::fail(format!(
            "{what} did not return within {HANG_LIMIT:?}: it hangs"
        ))),
    }
}

fn ensure(ok: bool, msg: impl FnOnce() -> String) -> Result<(), TestCaseError> {
    if ok {
        Ok(())
    } else {
        Err(TestCaseError::fail(msg()))
    }
}

/// The input, shortened for failure messages.
fn show(bytes: &[u8]) -> String {
    const MAX: usize = 600;
    let text = String::from_utf8_lossy(&bytes[..bytes.len().min(MAX)]).into_owned();
    if bytes.len() > MAX {
        format!("{text:?}... ({} bytes)", bytes.len())
    } else {
        format!("{text:?}")
    }
}

// ---------------------------------------------------------------------------------------------
// The readers and what their files look like

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Reader {
    Imu,
    ImuHeader,
    State,
    Pose,
    Position,
    Tum,
    Xsens,
    GlobalPose,
}

const READERS: [Reader; 8] = [
    Reader::Imu,
    Reader::ImuHeader,
    Reader::State,
    Reader::Pose,
    Reader::Position,
    Reader::Tum,
    Reader::Xsens,
    Reader::GlobalPose,
];

/// What a reader returned, flattened: stamps and every float of each row, or a header line.
#[derive(Debug)]
enum Parsed {
    Rows { t_ns: Vec<i64>, rows: Vec<Vec<f64>> },
    Header(String),
}

fn imu_rows(s: ImuSamples) -> Parsed {
    let rows = s.gyro.iter().zip(&s.acc).map(|(g, a)| [*g, *a].concat()).collect();
    Parsed::Rows { t_ns: s.t_ns, rows }
}

fn ground_truth_rows(gt: GroundTruth) -> Parsed {
    let rows = (0..gt.len())
        .map(|i| {
            let mut row = [gt.p[i].as_slice(), gt.q_wxyz[i].as_slice()].concat();
            for extra in [&gt.v, &gt.bias_gyro, &gt.bias_acc].into_iter().flatten() {
                row.extend_from_slice(&extra[i]);
            }
            row
        })
        .collect();
    Parsed::Rows { t_ns: gt.t_ns, rows }
}

/// The layout facts the error oracle needs, as the module docs of each format state them.
struct Format {
    separator: Separator,
    header_line: bool,
    columns: Vec<usize>,
    /// Field names used when there is no header line.
    names: Vec<String>,
    seconds: bool,
}

impl Reader {
    fn read(self, path: &Path, opts: &ReadOptions) -> Result<Parsed, ImuError> {
        Ok(match self {
            Reader::Imu => imu_rows(asl::read_imu(path, opts)?),
            Reader::ImuHeader => Parsed::Header(asl::read_imu_header(path)?),
            Reader::State => ground_truth_rows(asl::read_state(path, opts)?),
            Reader::Pose => ground_truth_rows(asl::read_pose(path, opts)?),
            Reader::Position => {
                let (t_ns, p) = asl::read_position(path, opts)?;
                let rows = p.iter().map(|x| x.to_vec()).collect();
                Parsed::Rows { t_ns, rows }
            }
            Reader::Tum => ground_truth_rows(tum::read_tum(path, opts)?),
            Reader::Xsens => imu_rows(kaist::read_xsens_imu(path, opts)?),
            Reader::GlobalPose => ground_truth_rows(kaist::read_global_pose(path, opts)?),
        })
    }

    fn format(self) -> Format {
        let asl = |n| Format {
            separator: Separator::Comma,
            header_line: true,
            columns: vec![n],
            names: Vec::new(),
            seconds: false,
        };
        let headerless = |separator, columns, names: &[&str], seconds| Format {
            separator,
            header_line: false,
            columns,
            names: names.iter().map(|s| s.to_string()).collect(),
            seconds,
        };
        match self {
            Reader::Imu | Reader::ImuHeader => asl(7),
            Reader::State => asl(17),
            Reader::Pose => asl(8),
            Reader::Position => asl(4),
            Reader::Tum => headerless(Separator::Whitespace, vec![8, 11], &tum::FIELD_NAMES, true),
            Reader::Xsens => headerless(Separator::Comma, vec![17], &kaist::XSENS_FIELD_NAMES, false),
            Reader::GlobalPose => headerless(Separator::Comma, vec![13], &kaist::POSE_FIELD_NAMES, false),
        }
    }

    /// Real files of this format: the crops shipped in the repository, and, where the data root
    /// has them, recordings the repository does not ship (a Leica file, an 11-column TUM file).
    fn seed_files(self) -> Vec<PathBuf> {
        let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let shipped = |rel: &str| repo.join(rel);
        let imu = [
            "datasets/euroc/MH_01_easy/mav0/imu0/data.csv",
            "datasets/euroc/V1_01_easy/mav0/imu0/data.csv",
            "datasets/euroc/MH_04_difficult/mav0/imu0/data.csv",
            "datasets/tum-vi/dataset-room2_512_16/mav0/imu0/data.csv",
        ];
        let mut files: Vec<PathBuf> = match self {
            Reader::Imu | Reader::ImuHeader => imu.iter().map(|r| shipped(r)).collect(),
            Reader::State => vec![
                shipped("datasets/euroc/MH_04_difficult/mav0/state_groundtruth_estimate0/data.csv"),
                shipped("datasets/euroc/V1_01_easy/groundtruth_state_20hz.csv"),
            ],
            Reader::Pose => vec![shipped("datasets/tum-vi/dataset-room2_512_16/mav0/mocap0/data.csv")],
            Reader::Position => vec![common::data("euroc/MH_01_easy/mav0/leica0/data.csv")],
            Reader::Tum => vec![
                shipped("datasets/euroc/MH_01_easy/groundtruth_pose.tum"),
                shipped("datasets/euroc/V1_01_easy/groundtruth_pose.tum"),
                common::data("blackbird/clover_yawForward_maxSpeed5p0/val/stamped_groundtruth_imu.txt"),
            ],
            Reader::Xsens => vec![shipped(
                "crates/imu_core/tests/fixtures/kaist/sensor_data/xsens_imu.csv",
            )],
            Reader::GlobalPose => vec![shipped("crates/imu_core/tests/fixtures/kaist/global_pose.csv")],
        };
        files.retain(|p| p.exists());
        files
    }

    /// Seed contents, each cut to its first lines (mutating megabytes per case buys nothing).
    /// Without a Leica file in the data root, the position seed is the first four columns of
    /// the shipped EuRoC state file under the Leica header: real stamps and positions.
    fn seeds(self) -> Vec<Vec<u8>> {
        const MAX_LINES: usize = 4000;
        let mut seeds: Vec<Vec<u8>> = self
            .seed_files()
            .iter()
            .map(|p| first_lines(&std::fs::read(p).expect("seed file reads"), MAX_LINES))
            .collect();
        if seeds.is_empty() && self == Reader::Position {
            seeds.push(position_seed_from_state(MAX_LINES));
        }
        assert!(!seeds.is_empty(), "no seed file for {self:?}");
        seeds
    }

    /// The file name the reader's input is written to (only used in messages).
    fn file_name(self) -> &'static str {
        match self {
            Reader::Tum => "groundtruth.tum",
            Reader::Xsens => "xsens_imu.csv",
            Reader::GlobalPose => "global_pose.csv",
            _ => "data.csv",
        }
    }
}

fn first_lines(bytes: &[u8], n: usize) -> Vec<u8> {
    let spans = line_spans(bytes);
    let end = spans.get(n).map_or(bytes.len(), |r| r.start);
    bytes[..end].to_vec()
}

fn position_seed_from_state(max_lines: usize) -> Vec<u8> {
    let state = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../datasets/euroc/MH_04_difficult/mav0/state_groundtruth_estimate0/data.csv");
    let text = String::from_utf8(std::fs::read(state).expect("state crop reads")).expect("UTF-8");
    let mut out = format!("{}\r\n", asl::POSITION_HEADER);
    for line in text.lines().skip(1).take(max_lines) {
        let cells: Vec<&str> = line.split(',').take(4).collect();
        out.push_str(&cells.join(","));
        out.push_str("\r\n");
    }
    out.into_bytes()
}

// ---------------------------------------------------------------------------------------------
// The oracle: what a file's lines and fields are, by the rules in `io::table`'s docs

const BOM: &[u8] = b"\xEF\xBB\xBF";

/// Byte ranges of the lines of `bytes`, each with its '\n' if it has one. A final '\n' does not
/// start another line.
fn line_spans(bytes: &[u8]) -> Vec<Range<usize>> {
    let mut spans = Vec::new();
    let mut start = 0;
    for (i, &b) in bytes.iter().enumerate() {
        if b == b'\n' {
            spans.push(start..i + 1);
            start = i + 1;
        }
    }
    if start < bytes.len() {
        spans.push(start..bytes.len());
    }
    spans
}

/// The file's lines as the readers see them: BOM dropped, line endings (LF or CRLF) removed.
fn file_lines(bytes: &[u8]) -> Vec<&[u8]> {
    let bytes = bytes.strip_prefix(BOM).unwrap_or(bytes);
    line_spans(bytes)
        .into_iter()
        .map(|r| {
            let line = &bytes[r];
            let line = line.strip_suffix(b"\n").unwrap_or(line);
            line.strip_suffix(b"\r").unwrap_or(line)
        })
        .collect()
}

fn trim_spaces(f: &[u8]) -> &[u8] {
    let start = f.iter().position(|&b| b != b' ' && b != b'\t').unwrap_or(f.len());
    let end = f
        .iter()
        .rposition(|&b| b != b' ' && b != b'\t')
        .map_or(start, |i| i + 1);
    &f[start..end]
}

fn split_fields(line: &[u8], separator: Separator) -> Vec<&[u8]> {
    match separator {
        Separator::Comma => line.split(|&b| b == b',').map(trim_spaces).collect(),
        Separator::Whitespace => line
            .split(|b| b.is_ascii_whitespace())
            .filter(|f| !f.is_empty())
            .collect(),
    }
}

fn is_blank(line: &[u8]) -> bool {
    line.iter().all(u8::is_ascii_whitespace)
}

fn lossy(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// The names errors use for the columns of a row of `n_columns` fields: the header's when it
/// has enough, else the format's fixed ones, else "column k".
fn column_names(lines: &[&[u8]], format: &Format, n_columns: usize) -> Vec<String> {
    if format.header_line {
        let header = lossy(lines.first().copied().unwrap_or_default());
        let names: Vec<String> = header
            .split(',')
            .enumerate()
            .map(|(i, s)| {
                let s = s.trim();
                if i == 0 { s.trim_start_matches('#').trim() } else { s }.to_string()
            })
            .collect();
        if names.len() >= n_columns {
            return names;
        }
    }
    (1..=n_columns.max(1))
        .map(|col| {
            format
                .names
                .get(col - 1)
                .cloned()
                .unwrap_or_else(|| format!("column {col}"))
        })
        .collect()
}

/// The checks on a successful read: as many rows as stamps, rows of one width, every value
/// finite, stamps strictly increasing, no more rows than the file has lines.
fn check_rows(t_ns: &[i64], rows: &[Vec<f64>], n_lines: usize) -> Result<(), TestCaseError> {
    ensure(t_ns.len() == rows.len(), || {
        format!("{} stamps, {} rows", t_ns.len(), rows.len())
    })?;
    ensure(t_ns.len() <= n_lines, || {
        format!("{} rows from {n_lines} lines", t_ns.len())
    })?;
    let width = rows.first().map_or(0, Vec::len);
    ensure(rows.iter().all(|r| r.len() == width), || {
        "rows of different widths".into()
    })?;
    ensure(rows.iter().flatten().all(|x| x.is_finite()), || {
        "a non-finite value was returned".into()
    })?;
    ensure(t_ns.windows(2).all(|w| w[0] < w[1]), || {
        "stamps not strictly increasing".into()
    })
}

/// Checks one reader outcome on `bytes` (written at `path`): data that passes `check_rows`, or
/// a typed error naming `path`, a line of the file, and the column, field name and text of the
/// cell it blames, exactly as they are in the file.
fn check_outcome(
    path: &Path,
    bytes: &[u8],
    format: &Format,
    outcome: Result<Parsed, ImuError>,
) -> Result<(), TestCaseError> {
    let lines = file_lines(bytes);
    match outcome {
        Ok(Parsed::Rows { t_ns, rows }) => check_rows(&t_ns, &rows, lines.len()),
        Ok(Parsed::Header(h)) => {
            let first = lossy(lines.first().copied().unwrap_or_default());
            ensure(h == first, || format!("header {h:?}, first line {first:?}"))
        }
        Err(e) => check_error(path, &lines, format, &e)
            .map_err(|why| TestCaseError::fail(format!("{why}\n  error: {e}\n  variant: {e:?}"))),
    }
}

fn check_error(path: &Path, lines: &[&[u8]], format: &Format, e: &ImuError) -> Result<(), String> {
    let in_range = |line: usize| line >= 1 && line <= lines.len().max(1);
    let line_text = |line: usize| lines.get(line - 1).copied().unwrap_or_default();
    let same_path = |p: &Path| {
        if p == path {
            Ok(())
        } else {
            Err(format!("names {p:?}, not {path:?}"))
        }
    };
    let check = |ok: bool, what: &str| if ok { Ok(()) } else { Err(what.to_string()) };
    match e {
        ImuError::Header {
            path: p, line, found, ..
        } => {
            same_path(p)?;
            check(format.header_line && *line == 1, "header error off line 1")?;
            check(*found == lossy(line_text(1)), "header error quotes another line")
        }
        ImuError::ColumnCount {
            path: p,
            line,
            expected,
            found,
        } => {
            same_path(p)?;
            check(in_range(*line), "line out of range")?;
            check(
                format.columns.contains(expected),
                "expected count not one the format allows",
            )?;
            let text = line_text(*line);
            let actual = split_fields(text, format.separator).len();
            let counts = actual == *found || (*found == 0 && is_blank(text));
            check(counts && found != expected, "column count does not match the line")
        }
        ImuError::NotNumeric {
            path: p,
            line,
            column,
            field,
            value,
            ..
        }
        | ImuError::NonFinite {
            path: p,
            line,
            column,
            field,
            value,
        }
        | ImuError::FloatTimestamp {
            path: p,
            line,
            column,
            field,
            value,
        } => {
            same_path(p)?;
            check(in_range(*line), "line out of range")?;
            let is_stamp_error = matches!(e, ImuError::FloatTimestamp { .. });
            check(!is_stamp_error || *column == 1, "float timestamp off column 1")?;
            check_cell(lines, format, *line, *column, field, value)
        }
        ImuError::Timestamp {
            path: p,
            line,
            column,
            field,
            value,
            previous,
            problem,
        } => {
            same_path(p)?;
            check(in_range(*line) && *column == 1, "line out of range or column not 1")?;
            let duplicate = *problem == imu_core::error::TimestampProblem::Duplicate;
            check(
                duplicate == (value == previous) && value <= previous,
                "problem does not match stamps",
            )?;
            let cells = split_fields(line_text(*line), format.separator);
            let names = column_names(lines, format, cells.len());
            check(names.first() == Some(field), "timestamp field misnamed")?;
            let text = lossy(cells.first().copied().unwrap_or_default());
            let plain = format.seconds || text.parse::<i64>().is_err() || text.parse::<i64>() == Ok(*value);
            check(plain, "stamp differs from the line's text")
        }
        ImuError::InvalidInput(msg) => {
            // Only the KAIST pose reader reports a bad row this way (not a rotation): the message
            // starts with "<path>:<line>:".
            let prefix = format!("{}:", path.display());
            let rest = msg.strip_prefix(&prefix).ok_or("InvalidInput does not name the file")?;
            let line: usize = rest.split(':').next().and_then(|s| s.parse().ok()).ok_or("no line")?;
            check(in_range(line) && !is_blank(line_text(line)), "line out of range")
        }
        ImuError::NotFound { .. } | ImuError::Io { .. } | ImuError::Alignment(_) | ImuError::NoOverlap { .. } => {
            Err("unexpected error kind for an existing file".into())
        }
        ImuError::TooFewRows {
            path: p,
            line,
            rows,
            found,
        } => {
            // `line` is the last row's, or the last non-blank line's (0 when there is none).
            same_path(p)?;
            check(
                *line <= lines.len() && found < &rows.needed,
                "line out of range or enough rows",
            )
        }
        // A variant added after this test was written: it must at least name the file.
        #[allow(unreachable_patterns)]
        other => check(
            other.to_string().contains(&path.display().to_string()),
            "does not name the file",
        ),
    }
}

/// A cell error: `column` is a field of `line`, and `field`/`value` are its name and text.
fn check_cell(
    lines: &[&[u8]],
    format: &Format,
    line: usize,
    column: usize,
    field: &str,
    value: &str,
) -> Result<(), String> {
    let cells = split_fields(lines.get(line - 1).copied().unwrap_or_default(), format.separator);
    if column == 0 || column > cells.len() {
        return Err(format!("column {column} of a line with {} fields", cells.len()));
    }
    if lossy(cells[column - 1]) != value {
        return Err(format!(
            "value {value:?} is not the cell's text {:?}",
            lossy(cells[column - 1])
        ));
    }
    let names = column_names(lines, format, cells.len());
    if names.get(column - 1).map(String::as_str) != Some(field) {
        return Err(format!("field {field:?}, expected {:?}", names.get(column - 1)));
    }
    Ok(())
}

/// Writes `bytes` to `dir/<reader's file name>`, reads it with `reader` under the hang guard and
/// checks the outcome.
fn read_and_check(reader: Reader, dir: &Path, bytes: &[u8], opts: &ReadOptions) -> Result<(), TestCaseError> {
    let path = dir.join(reader.file_name());
    std::fs::write(&path, bytes).map_err(|e| TestCaseError::fail(format!("temp write: {e}")))?;
    let (p, o) = (path.clone(), opts.clone());
    let outcome = guarded(&format!("{reader:?}"), move || reader.read(&p, &o))?;
    check_outcome(&path, bytes, &reader.format(), outcome)
        .map_err(|e| TestCaseError::fail(format!("{reader:?} on {}: {e}", show(bytes))))
}

// ---------------------------------------------------------------------------------------------
// Mutations of real files

/// Field texts that readers must survive: 2^63 and neighbours, huge and tiny floats, float and
/// signed stamps, non-numbers, empty and padded cells.
const NASTY_FIELDS: &[&str] = &[
    "9223372036854775807",
    "9223372036854775808",
    "-9223372036854775808",
    "-9223372036854775809",
    "18446744073709551615",
    "18446744073709551616",
    "99999999999999999999999999999999",
    "0",
    "-0",
    "+7",
    "-1",
    "007",
    "1e308",
    "1e309",
    "-1e400",
    "1e-400",
    "4.9e-324",
    "1.7976931348623157e308",
    "1.40363657975856E+018",
    "9.3e18",
    "1e999999999999",
    "1e-999999999999",
    "9223372036.854775807",
    "9223372036.854775808",
    "-9223372036.854775808",
    "1.5",
    "1.",
    ".5",
    ".",
    "-",
    "e5",
    "1e",
    "1e+",
    "0x10",
    "nan",
    "NaN",
    "inf",
    "-inf",
    "infinity",
    "",
    " ",
    " 1 ",
    "\t2",
    "1 2",
    "1,2",
    "#",
    "\u{FEFF}1",
    "\u{00e9}",
    "\r",
];

fn nasty_field() -> impl Strategy<Value = Vec<u8>> {
    prop_oneof![
        4 => proptest::sample::select(NASTY_FIELDS).prop_map(|s| s.as_bytes().to_vec()),
        1 => any::<i64>().prop_map(|x| x.to_string().into_bytes()),
        1 => any::<f64>().prop_map(|x| x.to_string().into_bytes()),
        1 => any::<f64>().prop_map(|x| format!("{x:e}").into_bytes()),
        1 => (1usize..400, 0u8..10).prop_map(|(n, d)| vec![b'0' + d; n]),
        1 => proptest::collection::vec(any::<u8>(), 0..8),
    ]
}

/// Pieces that make near-valid rows: digits, signs, separators, exponents, line ends.
const TOKENS: &[&str] = &[
    "0",
    "1",
    "9",
    "12345",
    "1403636579758560000",
    "-",
    "+",
    ".",
    "e",
    "E",
    ",",
    ", ",
    " ",
    "\t",
    "\r",
    "\n",
    "\r\n",
    "#",
    "nan",
    "inf",
    "x",
    "\u{FEFF}",
    "\u{00e9}",
    "1e308",
    "1e309",
    "9223372036854775808",
    "0.5",
    "-2e-3",
];

fn token_soup(max_tokens: usize) -> impl Strategy<Value = Vec<u8>> {
    prop_oneof![
        8 => proptest::collection::vec(proptest::sample::select(TOKENS), 0..max_tokens)
            .prop_map(|t| t.concat().into_bytes()),
        1 => proptest::collection::vec(any::<u8>(), 0..max_tokens),
    ]
}

/// A line too long to be an accident, in shapes that could trip a parser into quadratic work
/// (scanning, digit accumulation, exponent handling, splitting, trimming).
fn long_line(max_len: usize) -> impl Strategy<Value = Vec<u8>> {
    (0u8..10, 1024..=max_len).prop_map(|(kind, n)| {
        let body = |b: u8| vec![b; n];
        match kind {
            0 => body(b'7'),
            1 => [body(b'0'), b"1".to_vec()].concat(),
            2 => [b"0.".to_vec(), body(b'0'), b"1".to_vec()].concat(),
            3 => [b"1".to_vec(), body(b'0'), format!("e-{n}").into_bytes()].concat(),
            4 => body(b','),
            5 => body(b' '),
            6 => body(b'#'),
            7 => b"1,".repeat(n / 2),
            8 => [b"1403636579758560000,".to_vec(), body(b'9')].concat(),
            _ => body(b'\r'),
        }
    })
}

#[derive(Clone, Debug)]
enum Mutation {
    Truncate(Index),
    FlipByte(Index, u8),
    InsertBytes(Index, Vec<u8>),
    DuplicateLine(Index),
    DeleteLine(Index),
    SwapLines(Index, Index),
    ToggleCrlf(Index),
    AddBom,
    InsertLine(Index, Vec<u8>),
    ReplaceField(Index, Index, Vec<u8>),
}

fn mutation(max_long_line: usize) -> impl Strategy<Value = Mutation> {
    let idx = any::<Index>;
    let inserted_line = prop_oneof![
        Just(Vec::new()),
        Just(b" \t ".to_vec()),
        Just(b"# a comment".to_vec()),
        Just(b",,,,,,".to_vec()),
        token_soup(40),
        long_line(max_long_line),
    ];
    prop_oneof![
        1 => idx().prop_map(Mutation::Truncate),
        1 => (idx(), 1u8..=255).prop_map(|(i, x)| Mutation::FlipByte(i, x)),
        1 => (idx(), token_soup(12)).prop_map(|(i, b)| Mutation::InsertBytes(i, b)),
        1 => idx().prop_map(Mutation::DuplicateLine),
        1 => idx().prop_map(Mutation::DeleteLine),
        1 => (idx(), idx()).prop_map(|(a, b)| Mutation::SwapLines(a, b)),
        1 => idx().prop_map(Mutation::ToggleCrlf),
        1 => Just(Mutation::AddBom),
        1 => (idx(), inserted_line).prop_map(|(i, l)| Mutation::InsertLine(i, l)),
        2 => (idx(), idx(), nasty_field()).prop_map(|(l, f, v)| Mutation::ReplaceField(l, f, v)),
    ]
}

impl Mutation {
    fn apply(&self, bytes: &mut Vec<u8>) {
        let spans = line_spans(bytes);
        let line = |i: &Index| spans.get(i.index(spans.len().max(1))).cloned();
        match self {
            Mutation::Truncate(i) => bytes.truncate(i.index(bytes.len() + 1)),
            Mutation::FlipByte(i, x) if !bytes.is_empty() => {
                let at = i.index(bytes.len());
                bytes[at] ^= x;
            }
            Mutation::FlipByte(..) => {}
            Mutation::InsertBytes(i, b) => {
                let at = i.index(bytes.len() + 1);
                bytes.splice(at..at, b.iter().copied());
            }
            Mutation::DuplicateLine(i) => {
                if let Some(r) = line(i) {
                    let copy = with_newline(&bytes[r.clone()]);
                    bytes.splice(r.start..r.start, copy);
                }
            }
            Mutation::DeleteLine(i) => {
                if let Some(r) = line(i) {
                    bytes.drain(r);
                }
            }
            Mutation::SwapLines(a, b) => swap_lines(bytes, line(a), line(b)),
            Mutation::ToggleCrlf(i) => {
                if let Some(r) = line(i) {
                    toggle_crlf(bytes, r);
                }
            }
            Mutation::AddBom => {
                bytes.splice(0..0, BOM.iter().copied());
            }
            Mutation::InsertLine(i, l) => {
                let at = line(i).map_or(bytes.len(), |r| r.start);
                bytes.splice(at..at, with_newline(l));
            }
            Mutation::ReplaceField(l, f, v) => {
                if let Some(r) = line(l) {
                    replace_field(bytes, r, f, v);
                }
            }
        }
    }
}

fn with_newline(line: &[u8]) -> Vec<u8> {
    let mut v = line.to_vec();
    if v.last() != Some(&b'\n') {
        v.push(b'\n');
    }
    v
}

fn swap_lines(bytes: &mut Vec<u8>, a: Option<Range<usize>>, b: Option<Range<usize>>) {
    let (Some(a), Some(b)) = (a, b) else { return };
    let (first, second) = if a.start <= b.start { (a, b) } else { (b, a) };
    if first == second {
        return;
    }
    let mut out = bytes[..first.start].to_vec();
    out.extend(with_newline(&bytes[second.clone()]));
    out.extend_from_slice(&bytes[first.end..second.start]);
    out.extend(with_newline(&bytes[first]));
    out.extend_from_slice(&bytes[second.end..]);
    *bytes = out;
}

/// LF → CRLF or CRLF → LF at the end of one line, so a file mixes both.
fn toggle_crlf(bytes: &mut Vec<u8>, r: Range<usize>) {
    let line = &bytes[r.clone()];
    if line.ends_with(b"\r\n") {
        bytes.remove(r.end - 2);
    } else if line.ends_with(b"\n") {
        bytes.insert(r.end - 1, b'\r');
    }
}

/// Replaces one comma- or whitespace-separated field of a line by `value`.
fn replace_field(bytes: &mut Vec<u8>, r: Range<usize>, f: &Index, value: &[u8]) {
    let line = &bytes[r.clone()];
    let sep = if line.contains(&b',') { b',' } else { b' ' };
    let mut starts = vec![r.start];
    starts.extend(
        line.iter()
            .enumerate()
            .filter(|(_, &b)| b == sep)
            .map(|(i, _)| r.start + i + 1),
    );
    let k = f.index(starts.len());
    let start = starts[k];
    let end = bytes[start..r.end]
        .iter()
        .position(|&b| b == sep || b == b'\r' || b == b'\n')
        .map_or(r.end, |i| start + i);
    bytes.splice(start..end, value.iter().copied());
}

#[derive(Clone, Debug)]
struct MutatedFile {
    seed: Index,
    start: Index,
    n_lines: usize,
    mutations: Vec<Mutation>,
    lenient: bool,
}

/// Mostly a few dozen lines; one case in ten takes thousands, so that the reader splits the body
/// into several chunks and parses them in parallel (the merge must keep line numbers right).
fn mutated_file(max_long_line: usize) -> impl Strategy<Value = MutatedFile> {
    let n_lines = prop_oneof![9 => 0usize..40, 1 => 1000usize..4000];
    (
        any::<Index>(),
        any::<Index>(),
        n_lines,
        proptest::collection::vec(mutation(max_long_line), 0..5),
        any::<bool>(),
    )
        .prop_map(|(seed, start, n_lines, mutations, lenient)| MutatedFile {
            seed,
            start,
            n_lines,
            mutations,
            lenient,
        })
}

impl MutatedFile {
    /// A run of `n_lines` lines of the seed (after its header, which is kept), then mutated.
    fn bytes(&self, seeds: &[Vec<u8>], header_line: bool) -> Vec<u8> {
        let seed = self.seed.get(seeds);
        let spans = line_spans(seed);
        let skip = usize::from(header_line).min(spans.len());
        let body = spans.len() - skip;
        let first = skip + self.start.index(body.max(1)).min(body);
        let last = (first + self.n_lines).min(spans.len());
        let mut bytes = Vec::new();
        if header_line {
            bytes.extend_from_slice(&seed[spans.first().map_or(0..0, Range::clone)]);
        }
        if first < last {
            bytes.extend_from_slice(&seed[spans[first].start..spans[last - 1].end]);
        }
        for m in &self.mutations {
            m.apply(&mut bytes);
        }
        bytes
    }
}

fn options(lenient: bool) -> ReadOptions {
    ReadOptions {
        allow_float_timestamps: lenient,
    }
}

fn check_mutated_files(reader: Reader, default_cases: u32) {
    let seeds = reader.seeds();
    let dir = tempfile::tempdir().unwrap();
    let header_line = reader.format().header_line;
    let name = format!("mutated_real_files_{reader:?}");
    check_property(&name, (default_cases, 1), mutated_file(100_000), |case| {
        let bytes = case.bytes(&seeds, header_line);
        read_and_check(reader, dir.path(), &bytes, &options(case.lenient))
    });
}

const MUTATED_CASES: u32 = 96;

#[test]
fn mutated_imu_files_give_data_or_a_located_error() {
    check_mutated_files(Reader::Imu, MUTATED_CASES);
}

#[test]
fn mutated_imu_headers_give_the_first_line_or_a_header_error() {
    check_mutated_files(Reader::ImuHeader, MUTATED_CASES);
}

#[test]
fn mutated_state_files_give_data_or_a_located_error() {
    check_mutated_files(Reader::State, MUTATED_CASES);
}

#[test]
fn mutated_pose_files_give_data_or_a_located_error() {
    check_mutated_files(Reader::Pose, MUTATED_CASES);
}

#[test]
fn mutated_position_files_give_data_or_a_located_error() {
    check_mutated_files(Reader::Position, MUTATED_CASES);
}

#[test]
fn mutated_tum_files_give_data_or_a_located_error() {
    check_mutated_files(Reader::Tum, MUTATED_CASES);
}

#[test]
fn mutated_xsens_files_give_data_or_a_located_error() {
    check_mutated_files(Reader::Xsens, MUTATED_CASES);
}

#[test]
fn mutated_global_pose_files_give_data_or_a_located_error() {
    check_mutated_files(Reader::GlobalPose, MUTATED_CASES);
}

// ---------------------------------------------------------------------------------------------
// Arbitrary bytes, alone or after a real header line

#[test]
fn arbitrary_bytes_give_data_or_a_located_error() {
    let seeds: Vec<Vec<Vec<u8>>> = READERS.iter().map(|r| r.seeds()).collect();
    let dir = tempfile::tempdir().unwrap();
    let strategy = (
        proptest::sample::select(READERS.to_vec()),
        any::<bool>(),
        token_soup(400),
        any::<bool>(),
    );
    check_property(
        "arbitrary_bytes",
        (256, 1),
        strategy,
        |(reader, keep_first_line, soup, lenient)| {
            let mut bytes = Vec::new();
            if keep_first_line {
                // The seed's first line: the header of ASL files, a data row otherwise.
                let seed = &seeds[READERS.iter().position(|&r| r == reader).unwrap()][0];
                bytes.extend_from_slice(&seed[line_spans(seed).first().map_or(0..0, Range::clone)]);
            }
            bytes.extend_from_slice(&soup);
            read_and_check(reader, dir.path(), &bytes, &options(lenient))
        },
    );
}

/// Any table spec on near-valid bytes, or a reader's spec on a mutated real file: `parse_table`
/// returns rows whose every value is the standard library's parse of the cell on the line the
/// table says, or a located error, and exactly what the documented rules give when applied one
/// line at a time in file order (`reference_parse`), whatever the chunking and fast path do.
#[test]
fn parse_table_with_any_spec_gives_the_cells_or_a_located_error() {
    let seeds: Vec<Vec<Vec<u8>>> = READERS.iter().map(|r| r.seeds()).collect();
    let any_spec = (
        any::<bool>(),
        proptest::collection::vec(1usize..20, 1..3),
        any::<bool>(),
        any::<bool>(),
        any::<bool>(),
        any::<bool>(),
        0usize..12,
    )
        .prop_map(
            |(comma, columns, seconds, header_line, hash_comments, lenient, n_names)| TableSpec {
                separator: if comma { Separator::Comma } else { Separator::Whitespace },
                columns,
                time_unit: if seconds {
                    TimeUnit::Seconds
                } else {
                    TimeUnit::Nanoseconds
                },
                header_line,
                hash_comments,
                names: (0..n_names).map(|i| format!("name{i}")).collect(),
                allow_float_timestamps: lenient,
            },
        );
    let soup = (any_spec, token_soup(300)).prop_map(|(spec, bytes)| (spec, bytes, None));
    let real = (proptest::sample::select(READERS.to_vec()), mutated_file(100_000))
        .prop_map(|(reader, case)| (reader_spec(reader, case.lenient), Vec::new(), Some((reader, case))));
    let strategy = prop_oneof![soup, real];
    check_property("parse_table_any_spec", (512, 1), strategy, |(spec, soup, real)| {
        let bytes = match real {
            Some((reader, case)) => case.bytes(
                &seeds[READERS.iter().position(|&r| r == reader).unwrap()],
                spec.header_line,
            ),
            None => soup,
        };
        let path = PathBuf::from("any/table.txt");
        let (p, s, b) = (path.clone(), spec.clone(), bytes.clone());
        let outcome = guarded("parse_table", move || table::parse_table(&p, &b, &s))?;
        let fail = |e: String| TestCaseError::fail(format!("{spec:?} on {}: {e}", show(&bytes)));
        let expected = reference_parse(&path, &bytes, &spec);
        let found = summary(&outcome);
        if found != expected {
            return Err(fail(format!("parse_table gave {found:?}, the rules give {expected:?}")));
        }
        check_table(&path, &bytes, &spec, outcome).map_err(|e| fail(e.to_string()))
    });
}

/// The spec a reader gives `parse_table` (as its module docs describe the format).
fn reader_spec(reader: Reader, lenient: bool) -> TableSpec {
    let f = reader.format();
    TableSpec {
        separator: f.separator,
        columns: f.columns,
        time_unit: if f.seconds {
            TimeUnit::Seconds
        } else {
            TimeUnit::Nanoseconds
        },
        header_line: f.header_line,
        hash_comments: reader == Reader::Tum,
        names: f.names,
        allow_float_timestamps: lenient,
    }
}

/// What a table parse came to, comparably: the rows (stamps, value bits, lines), or the error's
/// kind and location.
#[derive(Debug, PartialEq, Eq)]
enum Summary {
    Rows(Vec<i64>, Vec<u64>, Vec<usize>),
    Error(String, usize, usize),
}

fn summary(outcome: &imu_core::Result<table::Table>) -> Summary {
    match outcome {
        Ok(t) => Summary::Rows(
            t.t_ns.clone(),
            t.values.iter().map(|x| x.to_bits()).collect(),
            t.lines.clone(),
        ),
        Err(e) => {
            let (kind, line, column) = error_place(e);
            Summary::Error(kind, line, column)
        }
    }
}

/// Kind (the variant's name), line and column of an error.
fn error_place(e: &ImuError) -> (String, usize, usize) {
    let (line, column) = match e {
        ImuError::ColumnCount { line, .. } => (*line, 0),
        ImuError::NotNumeric { line, column, .. }
        | ImuError::NonFinite { line, column, .. }
        | ImuError::FloatTimestamp { line, column, .. }
        | ImuError::Timestamp { line, column, .. } => (*line, *column),
        _ => (0, 0),
    };
    let kind = format!("{e:?}")
        .split([' ', '('])
        .next()
        .unwrap_or_default()
        .to_string();
    (kind, line, column)
}

/// `parse_table` by its documented rules, one line at a time in file order: the first problem
/// in the file wins, whether a bad cell, a blank or junk line followed by a row, or a stamp not
/// after the previous row's. Whether one line on its own is a valid row (and what it holds) is
/// left to `parse_table` on that line alone, so that this checks how lines are put together
/// (chunks, line numbers, blank and junk lines, stamp order), not number parsing again.
fn reference_parse(path: &Path, bytes: &[u8], spec: &TableSpec) -> Summary {
    let body = bytes.strip_prefix(BOM).unwrap_or(bytes);
    let raw: Vec<&[u8]> = line_spans(body).into_iter().map(|r| &body[r]).collect();
    let lines = file_lines(bytes);
    let first = usize::from(spec.header_line).min(lines.len());
    let is_comment = |l: &[u8]| spec.hash_comments && l.iter().find(|b| !b.is_ascii_whitespace()) == Some(&b'#');
    let n_columns = lines[first..]
        .iter()
        .find(|l| !is_blank(l) && !is_comment(l))
        .map(|l| split_fields(l, spec.separator).len())
        .map_or(spec.columns[0], |n| {
            *spec.columns.iter().min_by_key(|c| c.abs_diff(n)).unwrap()
        });
    // One line alone, after a dummy header so that a BOM in it stays part of the line.
    let one_line = |lenient: bool| TableSpec {
        columns: vec![n_columns],
        header_line: true,
        hash_comments: false,
        allow_float_timestamps: lenient,
        ..spec.clone()
    };
    let (lenient_spec, strict_spec) = (one_line(spec.allow_float_timestamps), one_line(false));
    let parse_line = |i: usize, spec: &TableSpec| table::parse_table(path, &[b"h\n", raw[i]].concat(), spec);
    // The error on line 2 of that input, placed on file line i + 1.
    let placed = |e: &ImuError, i: usize| {
        let (kind, _, column) = error_place(e);
        Summary::Error(kind, i + 1, column)
    };
    let (mut t_ns, mut values, mut rows_at) = (Vec::new(), Vec::new(), Vec::new());
    // A blank or junk line: an error only if a row follows it.
    let mut pending: Option<Summary> = None;
    for (i, &line) in lines.iter().enumerate().skip(first) {
        if is_comment(line) {
            continue;
        }
        if is_blank(line) {
            pending.get_or_insert(Summary::Error("ColumnCount".into(), i + 1, 0));
            continue;
        }
        let row = match parse_line(i, &lenient_spec) {
            Ok(t) if t.is_empty() => {
                // A junk line the lenient option drops when nothing but junk follows.
                let kind = match parse_line(i, &strict_spec) {
                    Err(e) => placed(&e, i),
                    Ok(_) => Summary::Error("ColumnCount".into(), i + 1, 0),
                };
                pending.get_or_insert(kind);
                continue;
            }
            Ok(t) => t,
            Err(e) => return pending.unwrap_or_else(|| placed(&e, i)),
        };
        if let Some(p) = pending {
            return p;
        }
        if t_ns.last().is_some_and(|&prev| row.t_ns[0] <= prev) {
            return Summary::Error("Timestamp".into(), i + 1, 1);
        }
        t_ns.push(row.t_ns[0]);
        values.extend(row.values.iter().map(|x| x.to_bits()));
        rows_at.push(i + 1);
    }
    Summary::Rows(t_ns, values, rows_at)
}

fn check_table(
    path: &Path,
    bytes: &[u8],
    spec: &TableSpec,
    outcome: imu_core::Result<table::Table>,
) -> Result<(), TestCaseError> {
    let format = Format {
        separator: spec.separator,
        header_line: spec.header_line,
        columns: spec.columns.clone(),
        names: spec.names.clone(),
        seconds: spec.time_unit == TimeUnit::Seconds,
    };
    let t = match outcome {
        Err(e) => return check_outcome(path, bytes, &format, Err(e)),
        Ok(t) => t,
    };
    let lines = file_lines(bytes);
    let w = t.n_columns.saturating_sub(1);
    let rows: Vec<Vec<f64>> = (0..t.len()).map(|i| t.row(i).to_vec()).collect();
    check_rows(&t.t_ns, &rows, lines.len())?;
    ensure(t.lines.len() == t.len() && t.values.len() == t.len() * w, || {
        "table lengths differ".into()
    })?;
    ensure(t.lines.windows(2).all(|l| l[0] < l[1]), || {
        "row lines not increasing".into()
    })?;
    for (i, &line) in t.lines.iter().enumerate() {
        let text = lines.get(line.wrapping_sub(1)).copied().unwrap_or_default();
        check_row_matches_line(text, spec, t.n_columns, t.t_ns[i], t.row(i))
            .map_err(|e| TestCaseError::fail(format!("row {i} (line {line}): {e}")))?;
    }
    Ok(())
}

/// A returned row is the line it claims to come from: same field count, each value the standard
/// library's parse of the cell, and an integer stamp equal to the cell's integer.
fn check_row_matches_line(text: &[u8], spec: &TableSpec, n_columns: usize, t: i64, row: &[f64]) -> Result<(), String> {
    let cells = split_fields(text, spec.separator);
    if cells.len() != n_columns {
        return Err(format!("{} cells, table has {n_columns} columns", cells.len()));
    }
    for (cell, &x) in cells.iter().skip(1).zip(row) {
        let parsed: Option<f64> = std::str::from_utf8(cell).ok().and_then(|s| s.parse().ok());
        if parsed.map(f64::to_bits) != Some(x.to_bits()) {
            return Err(format!("cell {:?} read as {x:e}, std parses {parsed:?}", lossy(cell)));
        }
    }
    let stamp: Option<i64> = std::str::from_utf8(cells[0]).ok().and_then(|s| s.parse().ok());
    match (spec.time_unit, stamp) {
        (TimeUnit::Nanoseconds, Some(s)) if s != t => Err(format!("stamp {:?} read as {t}", lossy(cells[0]))),
        _ => Ok(()),
    }
}

// ---------------------------------------------------------------------------------------------
// Very long lines: several MB without a newline must parse or fail in linear time

#[test]
fn multi_megabyte_lines_give_data_or_a_located_error() {
    let seeds: Vec<Vec<Vec<u8>>> = READERS.iter().map(|r| r.seeds()).collect();
    let dir = tempfile::tempdir().unwrap();
    let strategy = (
        proptest::sample::select(READERS.to_vec()),
        long_line(4 << 20),
        0usize..3,
        any::<bool>(),
    );
    check_property(
        "multi_megabyte_lines",
        (8, 250),
        strategy,
        |(reader, long, place, newline)| {
            let seed = &seeds[READERS.iter().position(|&r| r == reader).unwrap()][0];
            let head = first_lines(seed, 3);
            // The long line first (as the header, or the first row), in the middle, or last.
            let mut bytes = match place {
                0 => [long.as_slice(), b"\n", head.as_slice()].concat(),
                1 => [head.as_slice(), long.as_slice(), b"\n", head.as_slice()].concat(),
                _ => [head.as_slice(), long.as_slice()].concat(),
            };
            if newline {
                bytes.push(b'\n');
            }
            read_and_check(reader, dir.path(), &bytes, &ReadOptions::default())
        },
    );
}

// ---------------------------------------------------------------------------------------------
// Round trips

/// Stamps as the formats allow them: anywhere in i64 (ASL and TUM readers accept negative
/// stamps), with the extremes and real-looking ones made likely.
fn stamps(max: usize) -> impl Strategy<Value = Vec<i64>> {
    let stamp = prop_oneof![
        3 => any::<i64>(),
        1 => proptest::sample::select(vec![i64::MIN, i64::MIN + 1, -1, 0, 1, i64::MAX - 1, i64::MAX]),
        2 => (0i64..1_000_000_000_000).prop_map(|d| 1_403_636_579_758_560_000 + d),
    ];
    proptest::collection::btree_set(stamp, 0..max).prop_map(|s: BTreeSet<i64>| s.into_iter().collect())
}

/// Any finite f64: normal, subnormal, zero of either sign, any exponent.
fn finite() -> impl Strategy<Value = f64> {
    use proptest::num::f64::{NEGATIVE, NORMAL, POSITIVE, SUBNORMAL, ZERO};
    prop_oneof![
        3 => POSITIVE | NEGATIVE | NORMAL | SUBNORMAL | ZERO,
        1 => -20.0..20.0f64,
    ]
}

fn vec3() -> impl Strategy<Value = [f64; 3]> {
    [finite(), finite(), finite()]
}

fn bits(rows: &[Vec<f64>]) -> Vec<u64> {
    rows.iter().flatten().map(|x| x.to_bits()).collect()
}

/// Spellings of the IMU header that `write_imu` accepts and `read_imu_header` must give back.
const IMU_HEADERS: &[&str] = &[
    asl::IMU_HEADER,
    "# timestamp,w_RS_S_x,w_RS_S_y,w_RS_S_z,a_RS_S_x,a_RS_S_y,a_RS_S_z",
    "#timestamp [ns], w_RS_S_x [rad s^-1], w_RS_S_y [rad s^-1], w_RS_S_z [rad s^-1], a_RS_S_x [m s^-2], a_RS_S_y [m s^-2], a_RS_S_z [m s^-2]",
];

#[test]
fn write_imu_then_read_imu_is_bit_exact() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("imu0.csv");
    let samples = stamps(40).prop_flat_map(|t| {
        let n = t.len();
        (
            Just(t),
            proptest::collection::vec(vec3(), n),
            proptest::collection::vec(vec3(), n),
        )
    });
    let strategy = (samples, proptest::sample::select(IMU_HEADERS), any::<bool>());
    check_property(
        "write_imu_read_imu",
        (128, 1),
        strategy,
        |((t_ns, gyro, acc), header, lenient)| {
            let written = ImuSamples { t_ns, gyro, acc };
            asl::write_imu(&path, &written, Some(header)).map_err(|e| TestCaseError::fail(e.to_string()))?;
            ensure(asl::read_imu_header(&path).ok().as_deref() == Some(header), || {
                "header changed".into()
            })?;
            match asl::read_imu(&path, &options(lenient)) {
                Ok(read) => {
                    let (Parsed::Rows { t_ns: t0, rows: r0 }, Parsed::Rows { t_ns: t1, rows: r1 }) =
                        (imu_rows(written.clone()), imu_rows(read))
                    else {
                        unreachable!()
                    };
                    ensure(t0 == t1 && bits(&r0) == bits(&r1), || {
                        format!("{written:?} read back differently")
                    })
                }
                // Fewer rows than a reader needs is its own typed error.
                Err(ImuError::TooFewRows { found, .. }) if found == written.len() && found < 2 => Ok(()),
                Err(e) => Err(TestCaseError::fail(format!("{e} on {written:?}"))),
            }
        },
    );
}

#[test]
fn write_tum_then_read_tum_is_bit_exact() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("groundtruth.tum");
    let gt = stamps(40).prop_flat_map(|t| {
        let n = t.len();
        (
            Just(t),
            proptest::collection::vec(vec3(), n),
            proptest::collection::vec([finite(), finite(), finite(), finite()], n),
            proptest::option::of(proptest::collection::vec(vec3(), n)),
        )
    });
    check_property(
        "write_tum_read_tum",
        (128, 1),
        (gt, any::<bool>()),
        |((t_ns, p, q_wxyz, v), lenient)| {
            let written = GroundTruth {
                t_ns,
                p,
                q_wxyz,
                v,
                ..GroundTruth::default()
            };
            tum::write_tum(&path, &written).map_err(|e| TestCaseError::fail(e.to_string()))?;
            match tum::read_tum(&path, &options(lenient)) {
                Ok(read) => {
                    let same_v = read.v.is_some() == written.v.is_some() || written.is_empty();
                    let (Parsed::Rows { t_ns: t0, rows: r0 }, Parsed::Rows { t_ns: t1, rows: r1 }) =
                        (ground_truth_rows(written.clone()), ground_truth_rows(read))
                    else {
                        unreachable!()
                    };
                    ensure(same_v && t0 == t1 && bits(&r0) == bits(&r1), || {
                        format!("{written:?} read back differently")
                    })
                }
                Err(ImuError::TooFewRows { found, .. }) if found == written.len() && found < 2 => Ok(()),
                Err(e) => Err(TestCaseError::fail(format!("{e} on {written:?}"))),
            }
        },
    );
}

/// The formats without a writer, printed the way their producers print them (integer ns and
/// shortest round-trip floats; a real header, or none), read back bit for bit.
#[test]
fn printed_tables_read_back_bit_exact() {
    let dir = tempfile::tempdir().unwrap();
    let readers = vec![Reader::State, Reader::Pose, Reader::Position, Reader::Xsens];
    let strategy = (proptest::sample::select(readers), stamps(30), any::<bool>()).prop_flat_map(|(reader, t, crlf)| {
        let width = reader.format().columns[0] - 1;
        let rows = proptest::collection::vec(proptest::collection::vec(finite(), width), t.len());
        (Just(reader), Just(t), rows, Just(crlf))
    });
    check_property("printed_tables", (128, 1), strategy, |(reader, t_ns, rows, crlf)| {
        let header = match reader {
            Reader::State => Some(asl::STATE_HEADER),
            Reader::Pose => Some(asl::POSE_HEADER),
            Reader::Position => Some(asl::POSITION_HEADER),
            _ => None,
        };
        let end = if crlf { "\r\n" } else { "\n" };
        let mut text: String = header.map(|h| format!("{h}{end}")).unwrap_or_default();
        for (t, row) in t_ns.iter().zip(&rows) {
            let cells: Vec<String> = row.iter().map(f64::to_string).collect();
            text.push_str(&format!("{t},{}{end}", cells.join(",")));
        }
        let path = dir.path().join(reader.file_name());
        std::fs::write(&path, &text).unwrap();
        // read_state and read_pose return p, q, v, biases in file order; read_xsens_imu only
        // gyro and acceleration (file columns 8..13).
        let expected: Vec<Vec<f64>> = match reader {
            Reader::Xsens => rows.iter().map(|r| r[7..13].to_vec()).collect(),
            _ => rows.clone(),
        };
        match reader.read(&path, &ReadOptions::default()) {
            Ok(Parsed::Rows { t_ns: t1, rows: r1 }) => ensure(t1 == t_ns && bits(&r1) == bits(&expected), || {
                format!("{reader:?}: {text:?} read back differently")
            }),
            Ok(Parsed::Header(_)) => unreachable!(),
            // read_position has no minimum; the others need two rows.
            Err(ImuError::TooFewRows { found, .. }) if found == t_ns.len() && found < 2 => Ok(()),
            Err(e) => Err(TestCaseError::fail(format!("{e} on {text:?}"))),
        }
    });
}

// ---------------------------------------------------------------------------------------------
// Regressions: the minimal inputs of what the properties found

/// A duplicated stamp above a truncated row: the module promises the first problem in file
/// order, but the stamp check ran only after every row had parsed, so the later bad row was
/// reported instead.
#[test]
fn a_stamp_out_of_order_above_a_bad_row_is_the_error_reported() {
    let dir = tempfile::tempdir().unwrap();
    let row = "1520530841267970010,-0.0692489679,-0.2241203441,0.9880698966,0.1865052944,0.9916792850,9.2028308622";
    let text = format!("{}\n{row}\n{row}\n1\n", asl::IMU_HEADER);
    let path = io_common::write(&dir, "data.csv", &text);
    match asl::read_imu(&path, &ReadOptions::default()) {
        Err(ImuError::Timestamp { line: 3, column: 1, .. }) => {}
        other => panic!("expected the duplicate stamp on line 3, got {other:?}"),
    }
}

/// Two BOMs: the reader drops the first (the file's), and the second is the header's own text;
/// the header used to lose it too, so errors named a field the file does not spell that way.
#[test]
fn a_second_bom_stays_in_the_header_text() {
    let spec = TableSpec {
        separator: Separator::Comma,
        columns: vec![2],
        time_unit: TimeUnit::Nanoseconds,
        header_line: true,
        hash_comments: false,
        names: Vec::new(),
        allow_float_timestamps: false,
    };
    let t = table::parse_table(Path::new("t.csv"), b"\xEF\xBB\xBF\xEF\xBB\xBF#t,a\n1,1\n", &spec).unwrap();
    assert_eq!(t.header.as_deref(), Some("\u{FEFF}#t,a"));
    assert_eq!(t.names, vec!["\u{FEFF}#t", "a"]);
}
