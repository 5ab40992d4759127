//! A user's own IMU CSV: any column order and names, time in s/ms/µs/ns (integer or float), gyro
//! in rad/s or deg/s, accelerometer in m/s² or g; and the writer that puts refined samples back
//! into such a file, keeping everything else in it.
//!
//! The caller describes the file with a [`CsvFormat`]: a column map in the file's column order
//! (`t,gx,gy,gz,ax,ay,az`; `_` skips a column; columns after the last mapped one are ignored)
//! and the three units. The rest is found in the file:
//! - the delimiter, from the first line that is not blank or a comment: `;` if it has one, else
//!   `,`, else a tab, else runs of whitespace (fields are trimmed of spaces and tabs);
//! - a header: that first line when none of its mapped fields is a number. Its names (or, with
//!   no header, those of a `#` comment line just above the data that has enough fields) name the
//!   fields in errors, as `name (gx)`;
//! - comment lines start with `#` (after optional whitespace) and are skipped, as are blank lines.
//!
//! Time is read from its decimal text exactly (no detour through f64) and rounded to the nearest
//! ns (ties to even on the digits), so float seconds keep every digit the file has. Gyro and acc are converted to rad/s and
//! m/s² (deg → rad, g = 9.80665 m/s²). Errors are the core's: `MissingColumn` for a line shorter
//! than the map, `NotNumeric`/`NonFinite` for a bad value, `Timestamp` for time that does not
//! strictly increase, `TooFewRows` below two samples, each naming file:line:column and the field;
//! `UnknownUnit` and `InvalidInput` for a unit or a column map the core does not know.
//!
//! With [`CsvFormat::skip_bad_lines`] a line too short for the map or with a field that is not a
//! finite number (a logger's truncated first or last line) is skipped instead, and
//! [`read_imu_checked`] lists the lines skipped with what was wrong on each; the writer keeps such
//! lines as they are. Stamps out of order stay an error.
//!
//! This module finds the layout (delimiter, header, names) and the column map; the rows are read by
//! the one row parser of [`super::table`] with that map, so delimiters, comments, blank lines,
//! number rules, chunking and errors (the first problem in file order is the one reported) are
//! those of every reader.

use std::fmt::Write as _;
use std::path::Path;

use rayon::prelude::*;

pub use super::table::Delimiter;
use super::table::{
    self, classify, field_spans, field_texts, is_number, split_chunks, strip_bom, strip_cr, Bad, BadKind, BlankLines,
    Comments, LineKind, RowRules, Width,
};
use super::write_atomic;
use crate::error::{ImuError, Result, IMU_ROWS};
use crate::types::{ImuSamples, Vec3};

/// The quantities a column map must place, in the order [`ColumnMap::at`] keeps them.
pub const FIELDS: [&str; 7] = ["t", "gx", "gy", "gz", "ax", "ay", "az"];

/// Standard gravity [m/s²], the value of 1 g (not the core's default gravity magnitude).
pub const STANDARD_GRAVITY: f64 = 9.80665;

/// Where each quantity is in the file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ColumnMap {
    /// 0-based file column of t, gx, gy, gz, ax, ay, az.
    pub at: [usize; 7],
    /// The map as given, one entry per file column (`_` for skipped ones).
    pub entries: Vec<String>,
}

impl ColumnMap {
    /// Parses `t,gx,gy,gz,ax,ay,az` (any order; `_` skips a column; spaces and case ignored).
    pub fn parse(spec: &str) -> Result<Self> {
        let entries: Vec<String> = spec.split(',').map(|s| s.trim().to_ascii_lowercase()).collect();
        let mut at = [usize::MAX; 7];
        for (col, e) in entries.iter().enumerate() {
            if e == "_" {
                continue;
            }
            let Some(k) = FIELDS.iter().position(|f| f == e) else {
                return Err(ImuError::invalid(format!(
                    "column map {spec:?}: entry {} is {e:?}; each entry is one of t, gx, gy, gz, ax, ay, az, \
                     or _ to skip a column",
                    col + 1
                )));
            };
            if at[k] != usize::MAX {
                return Err(ImuError::invalid(format!(
                    "column map {spec:?}: {e} is given twice (columns {} and {})",
                    at[k] + 1,
                    col + 1
                )));
            }
            at[k] = col;
        }
        let missing: Vec<&str> = (0..7).filter(|&k| at[k] == usize::MAX).map(|k| FIELDS[k]).collect();
        if !missing.is_empty() {
            return Err(ImuError::invalid(format!(
                "column map {spec:?} has no {}; it must place all of t, gx, gy, gz, ax, ay, az \
                 (in the file's column order, _ for a column to skip)",
                missing.join(", ")
            )));
        }
        Ok(ColumnMap { at, entries })
    }

    /// Fields a line must have at least.
    pub fn width(&self) -> usize {
        self.at.iter().max().map_or(0, |m| m + 1)
    }
}

/// Unit of the time column.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TimeUnit {
    Seconds,
    Milliseconds,
    Microseconds,
    Nanoseconds,
}

impl TimeUnit {
    pub fn parse(s: &str) -> Result<Self> {
        match s.trim() {
            "s" => Ok(TimeUnit::Seconds),
            "ms" => Ok(TimeUnit::Milliseconds),
            "us" | "µs" => Ok(TimeUnit::Microseconds),
            "ns" => Ok(TimeUnit::Nanoseconds),
            _ => Err(ImuError::UnknownUnit {
                what: "time",
                value: s.to_string(),
                allowed: "s, ms, us, ns",
            }),
        }
    }

    /// Decimal digits from this unit down to ns.
    fn ns_digits(self) -> i64 {
        match self {
            TimeUnit::Seconds => 9,
            TimeUnit::Milliseconds => 6,
            TimeUnit::Microseconds => 3,
            TimeUnit::Nanoseconds => 0,
        }
    }
}

/// Unit of the gyroscope columns.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GyroUnit {
    RadPerSecond,
    DegPerSecond,
}

impl GyroUnit {
    pub fn parse(s: &str) -> Result<Self> {
        match s.trim() {
            "rad/s" => Ok(GyroUnit::RadPerSecond),
            "deg/s" => Ok(GyroUnit::DegPerSecond),
            _ => Err(ImuError::UnknownUnit {
                what: "gyro",
                value: s.to_string(),
                allowed: "rad/s, deg/s",
            }),
        }
    }

    fn to_si(self, x: f64) -> f64 {
        match self {
            GyroUnit::RadPerSecond => x,
            GyroUnit::DegPerSecond => x.to_radians(),
        }
    }

    fn in_unit(self, x: f64) -> f64 {
        match self {
            GyroUnit::RadPerSecond => x,
            GyroUnit::DegPerSecond => x.to_degrees(),
        }
    }
}

/// Unit of the accelerometer columns.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AccUnit {
    MetersPerSecond2,
    StandardGravity,
}

impl AccUnit {
    pub fn parse(s: &str) -> Result<Self> {
        match s.trim() {
            "m/s2" | "m/s^2" => Ok(AccUnit::MetersPerSecond2),
            "g" => Ok(AccUnit::StandardGravity),
            _ => Err(ImuError::UnknownUnit {
                what: "acc",
                value: s.to_string(),
                allowed: "m/s2, g",
            }),
        }
    }

    fn to_si(self, x: f64) -> f64 {
        match self {
            AccUnit::MetersPerSecond2 => x,
            AccUnit::StandardGravity => x * STANDARD_GRAVITY,
        }
    }

    fn in_unit(self, x: f64) -> f64 {
        match self {
            AccUnit::MetersPerSecond2 => x,
            AccUnit::StandardGravity => x / STANDARD_GRAVITY,
        }
    }
}

/// What a caller says about their file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CsvFormat {
    pub columns: ColumnMap,
    pub time: TimeUnit,
    pub gyro: GyroUnit,
    pub acc: AccUnit,
    /// Skip a line too short for the map or with a bad value instead of failing (module doc).
    pub skip_bad_lines: bool,
}

impl CsvFormat {
    /// From the user's strings (`"t,gx,gy,gz,ax,ay,az"`, `"s"`, `"deg/s"`, `"g"`).
    pub fn parse(columns: &str, time: &str, gyro: &str, acc: &str) -> Result<Self> {
        Ok(CsvFormat {
            columns: ColumnMap::parse(columns)?,
            time: TimeUnit::parse(time)?,
            gyro: GyroUnit::parse(gyro)?,
            acc: AccUnit::parse(acc)?,
            skip_bad_lines: false,
        })
    }

    /// The same format, skipping bad lines (or not).
    pub fn with_skip_bad_lines(mut self, skip: bool) -> Self {
        self.skip_bad_lines = skip;
        self
    }
}

/// The delimiter of a user's file, from its first row: `;` if it has one, else `,`, else a tab,
/// else runs of whitespace.
fn detect_delimiter(line: &[u8]) -> Delimiter {
    if line.contains(&b';') {
        Delimiter::Semicolon
    } else if line.contains(&b',') {
        Delimiter::Comma
    } else if line.contains(&b'\t') {
        Delimiter::Tab
    } else {
        Delimiter::Whitespace
    }
}

/// How a file is laid out: found once, before the rows are parsed.
#[derive(Clone, Debug)]
struct Layout {
    delimiter: Delimiter,
    /// Byte offset (in the BOM-less bytes) and 0-based line index where the rows start.
    body_start: usize,
    body_line: usize,
    /// 1-based line of the header, if there is one.
    header_line: Option<usize>,
    /// The header's (or a comment line's) names, one per file column.
    names: Vec<String>,
    /// skip_bad_lines: lines above the header too short for the map (0-based line, fields found).
    pre_skipped: Vec<(usize, usize)>,
}

/// Finds the delimiter and the header in the BOM-less `bytes`. With `skip` (skip_bad_lines), a
/// line too short for the map (a truncated first line) is passed over: the next one decides.
fn detect_layout(bytes: &[u8], map: &ColumnMap, skip: bool) -> Layout {
    let mut pos = 0;
    let mut line_idx = 0;
    let mut last_comment: Option<&[u8]> = None;
    // skip: the lines passed over, and where the first of them starts.
    let mut short: Vec<(usize, usize)> = Vec::new();
    let mut first_short: Option<(usize, usize)> = None;
    let mut spans = Vec::new();
    while pos < bytes.len() {
        let end = memchr::memchr(b'\n', &bytes[pos..]).map_or(bytes.len(), |i| pos + i);
        let line = strip_cr(&bytes[pos..end]);
        let next = (end + 1).min(bytes.len());
        match classify(line, COMMENTS) {
            LineKind::Blank => {}
            LineKind::Comment => last_comment = Some(line),
            LineKind::Row(line) => {
                let delimiter = detect_delimiter(line);
                field_spans(line, delimiter, &mut spans);
                if skip && spans.len() < map.width() {
                    short.push((line_idx, spans.len()));
                    first_short.get_or_insert((pos, line_idx));
                    pos = next;
                    line_idx += 1;
                    continue;
                }
                let header = !map
                    .at
                    .iter()
                    .any(|&c| spans.get(c).is_some_and(|&(a, b)| is_number(&line[a..b])));
                if header {
                    return Layout {
                        delimiter,
                        body_start: next,
                        body_line: line_idx + 1,
                        header_line: Some(line_idx + 1),
                        names: field_texts(line, delimiter),
                        pre_skipped: short,
                    };
                }
                let names = last_comment
                    .map(|c| {
                        let c = c.iter().position(|&b| b == b'#').map_or(c, |i| &c[i + 1..]);
                        field_texts(c, delimiter)
                    })
                    .filter(|n| n.len() >= map.width())
                    .unwrap_or_default();
                // The lines passed over are rows of the body (skipped there, with their error).
                let (body_start, body_line) = first_short.unwrap_or((pos, line_idx));
                return Layout {
                    delimiter,
                    body_start,
                    body_line,
                    header_line: None,
                    names,
                    pre_skipped: Vec::new(),
                };
            }
        }
        pos = next;
        line_idx += 1;
    }
    let (body_start, body_line) = first_short.unwrap_or((bytes.len(), line_idx));
    Layout {
        delimiter: Delimiter::Comma,
        body_start,
        body_line,
        header_line: None,
        names: Vec::new(),
        pre_skipped: Vec::new(),
    }
}

/// Comments in a user's file: whole lines starting with `#`.
const COMMENTS: Comments = Comments::Lines;

/// The name of file column `col` (0-based) that holds quantity `k`, for errors: the file's own
/// name with the map's in parentheses (`wx_dps (gx)`), or the map's alone.
fn field_name(layout: &Layout, k: usize, col: usize) -> String {
    match layout.names.get(col).map(|s| s.trim_start_matches('#').trim()) {
        Some(n) if !n.is_empty() && !n.eq_ignore_ascii_case(FIELDS[k]) => format!("{n} ({})", FIELDS[k]),
        _ => FIELDS[k].to_string(),
    }
}

/// The names errors give the file's columns: [`field_name`] for mapped ones.
fn column_names(layout: &Layout, map: &ColumnMap) -> Vec<String> {
    (0..map.width())
        .map(|c| match map.at.iter().position(|&a| a == c) {
            Some(k) => field_name(layout, k, c),
            None => format!("column {}", c + 1),
        })
        .collect()
}

/// The shared parser state for a file of this layout and format.
fn rules(layout: &Layout, fmt: &CsvFormat) -> RowRules {
    let at = &fmt.columns.at;
    RowRules {
        delimiter: layout.delimiter,
        comments: COMMENTS,
        blank_lines: BlankLines::Skip,
        width: Width::AtLeast(fmt.columns.width()),
        time_col: at[0],
        time_digits: fmt.time.ns_digits(),
        float_ns: true,
        values: at[1..].to_vec(),
        trailing_junk: false,
        skip_bad_lines: fmt.skip_bad_lines,
    }
}

/// Rows of a file with their 1-based lines.
struct Parsed {
    samples: ImuSamples,
    lines: Vec<usize>,
    layout: Layout,
    rules: RowRules,
    names: Vec<String>,
    /// Lines skipped (skip_bad_lines), file-wide 0-based, in file order.
    skipped: Vec<Bad>,
    /// Fields of the first row.
    fields: usize,
}

/// A line skipped with [`CsvFormat::skip_bad_lines`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SkippedLine {
    /// 1-based line in the file.
    pub line: usize,
    /// The error the line would have raised (`file:line:column: field ...`).
    pub problem: String,
}

/// A user's CSV as read, with what the plausibility checks of a caller need to know of the file.
#[derive(Clone, Debug)]
pub struct CsvRead {
    /// Stamps [ns], gyro [rad/s], acc [m/s²].
    pub samples: ImuSamples,
    /// Lines skipped (skip_bad_lines only), in file order.
    pub skipped: Vec<SkippedLine>,
    /// The header's (or a comment line's) names, one per file column; empty without.
    pub names: Vec<String>,
    /// Fields of the first row read, trailing empty ones (a delimiter at the line's end) left out.
    pub fields: usize,
}

/// Parses the BOM-less `bytes` of `path`.
fn parse(path: &Path, bytes: &[u8], fmt: &CsvFormat) -> Result<Parsed> {
    let layout = detect_layout(bytes, &fmt.columns, fmt.skip_bad_lines);
    let rules = rules(&layout, fmt);
    let names = column_names(&layout, &fmt.columns);
    if let Some(h) = layout.header_line {
        if layout.names.len() < fmt.columns.width() {
            let bad = Bad {
                line: h - 1,
                kind: BadKind::Count {
                    found: layout.names.len(),
                },
            };
            return Err(rules.error(path, &names, bad));
        }
    }
    let mut skipped: Vec<Bad> = layout
        .pre_skipped
        .iter()
        .map(|&(line, found)| Bad {
            line,
            kind: BadKind::Count { found },
        })
        .collect();
    let rows = table::parse_rows(path, &bytes[layout.body_start..], layout.body_line, &rules, &names)?;
    if rows.t_ns.len() < IMU_ROWS.needed {
        // skip_bad_lines passed over (nearly) every line: the first one's own error names the cause (a
        // time unit, a delimiter), where "too few rows" would not
        if let Some(first) = skipped.first().or(rows.skipped.first()) {
            return Err(rules.error(path, &names, first.clone()));
        }
        let t = table::Table {
            path: path.to_path_buf(),
            t_ns: rows.t_ns.clone(),
            lines: rows.lines.clone(),
            ..table::Table::default()
        };
        table::require_rows(&t, bytes, &IMU_ROWS)?;
    }
    skipped.extend(rows.skipped);
    let (gyro, acc) = rows
        .values
        .chunks_exact(6)
        .map(|v| {
            (
                [fmt.gyro.to_si(v[0]), fmt.gyro.to_si(v[1]), fmt.gyro.to_si(v[2])],
                [fmt.acc.to_si(v[3]), fmt.acc.to_si(v[4]), fmt.acc.to_si(v[5])],
            )
        })
        .unzip();
    Ok(Parsed {
        samples: ImuSamples {
            t_ns: rows.t_ns,
            gyro,
            acc,
        },
        lines: rows.lines,
        layout,
        rules,
        names,
        skipped,
        fields: rows.first_fields.unwrap_or(0),
    })
}

/// Reads a user's IMU CSV described by `fmt`: stamps [ns], gyro [rad/s], acc [m/s²].
pub fn read_imu(path: impl AsRef<Path>, fmt: &CsvFormat) -> Result<ImuSamples> {
    let path = path.as_ref();
    let bytes = table::read_bytes(path)?;
    Ok(parse(path, strip_bom(&bytes), fmt)?.samples)
}

/// Reads a user's IMU CSV as [`read_imu`] does, with the lines skipped (`fmt.skip_bad_lines`), the
/// file's column names and its number of fields: what a caller's plausibility checks look at.
pub fn read_imu_checked(path: impl AsRef<Path>, fmt: &CsvFormat) -> Result<CsvRead> {
    let path = path.as_ref();
    let bytes = table::read_bytes(path)?;
    let p = parse(path, strip_bom(&bytes), fmt)?;
    let skipped = p
        .skipped
        .into_iter()
        .map(|b| SkippedLine {
            line: b.line + 1,
            problem: p.rules.error(path, &p.names, b).to_string(),
        })
        .collect();
    Ok(CsvRead {
        samples: p.samples,
        skipped,
        names: p.layout.names,
        fields: p.fields,
    })
}

fn check_finite(what: &str, i: usize, xs: &Vec3) -> Result<()> {
    if xs.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(ImuError::invalid(format!("{what}[{i}] = {xs:?} is not finite")))
    }
}

/// The text for `y` (= `si` in the file's unit) in `best`: of `y` and its two f64 neighbours, the
/// shortest that the reader converts back to exactly `si` (so 3 deg/s read as rad/s is written
/// as `3`, not `3.0000000000000004`), else `y`; each in Rust's shortest round-trip form.
fn shortest_text(si: f64, y: f64, to_si: impl Fn(f64) -> f64, text: &mut String, best: &mut String) {
    best.clear();
    // Writing to a String cannot fail.
    let _ = write!(best, "{y}");
    if y == 0.0 || !y.is_finite() {
        return;
    }
    let exact = to_si(y) == si;
    for z in [f64::from_bits(y.to_bits() - 1), f64::from_bits(y.to_bits() + 1)] {
        if to_si(z) == si {
            text.clear();
            let _ = write!(text, "{z}");
            // One that reads back exactly beats one that does not; then the shorter one.
            if !exact || text.len() < best.len() {
                std::mem::swap(text, best);
            }
            if !exact {
                return;
            }
        }
    }
}

/// `line` with the six IMU fields replaced by `g`, `a` (SI) in the file's units, every other
/// byte as it was.
fn rewrite_line(line: &[u8], spans: &[(usize, usize)], fmt: &CsvFormat, g: &Vec3, a: &Vec3, out: &mut Vec<u8>) {
    let at = &fmt.columns.at;
    let mut cols: [(usize, f64); 6] = [
        (at[1], g[0]),
        (at[2], g[1]),
        (at[3], g[2]),
        (at[4], a[0]),
        (at[5], a[1]),
        (at[6], a[2]),
    ];
    cols.sort_unstable_by_key(|c| c.0);
    let (mut text, mut best) = (String::new(), String::new());
    let mut from = 0;
    for (col, si) in cols {
        let (s, e) = spans[col];
        out.extend_from_slice(&line[from..s]);
        let gyro = col != at[4] && col != at[5] && col != at[6];
        let y = if gyro {
            fmt.gyro.in_unit(si)
        } else {
            fmt.acc.in_unit(si)
        };
        let to_si = |y: f64| if gyro { fmt.gyro.to_si(y) } else { fmt.acc.to_si(y) };
        shortest_text(si, y, to_si, &mut text, &mut best);
        out.extend_from_slice(best.as_bytes());
        from = e;
    }
    out.extend_from_slice(&line[from..]);
}

/// Rewrites chunk `chunk` (whose first line is file line `first_line`, 0-based), replacing the
/// rows listed in `lines` (1-based file lines, from row index `row0` on).
#[allow(clippy::too_many_arguments)]
fn rewrite_chunk(
    chunk: &[u8],
    first_line: usize,
    lines: &[usize],
    row0: usize,
    fmt: &CsvFormat,
    delim: Delimiter,
    gyro: &[Vec3],
    acc: &[Vec3],
) -> Vec<u8> {
    let mut out = Vec::with_capacity(chunk.len() + chunk.len() / 4);
    let mut spans = Vec::new();
    let (mut pos, mut idx, mut row) = (0, first_line, row0);
    while pos < chunk.len() {
        let end = memchr::memchr(b'\n', &chunk[pos..]).map_or(chunk.len(), |i| pos + i);
        let raw = &chunk[pos..end];
        let line = strip_cr(raw);
        if row < lines.len() && lines[row] == idx + 1 {
            field_spans(line, delim, &mut spans);
            rewrite_line(line, &spans, fmt, &gyro[row], &acc[row], &mut out);
            out.extend_from_slice(&raw[line.len()..]);
            row += 1;
        } else {
            out.extend_from_slice(raw);
        }
        if end < chunk.len() {
            out.push(b'\n');
        }
        pos = end + 1;
        idx += 1;
    }
    out
}

/// Writes `out`: the user's file `original` (described by `fmt`) with its gyro and acc columns
/// replaced by `gyro`, `acc` [rad/s, m/s²], one row per sample the reader returns, in the file's
/// own units. Header, comments, time and every other column keep their text. Written atomically.
pub fn write_imu(
    original: impl AsRef<Path>,
    out: impl AsRef<Path>,
    fmt: &CsvFormat,
    gyro: &[Vec3],
    acc: &[Vec3],
) -> Result<()> {
    let original = original.as_ref();
    let all = table::read_bytes(original)?;
    let bytes = strip_bom(&all);
    let parsed = parse(original, bytes, fmt)?;
    let n = parsed.lines.len();
    if gyro.len() != n || acc.len() != n {
        return Err(ImuError::invalid(format!(
            "gyro has {} rows and acc {}, but {} holds {n} samples",
            gyro.len(),
            acc.len(),
            original.display()
        )));
    }
    for i in 0..n {
        check_finite("gyro", i, &gyro[i])?;
        check_finite("acc", i, &acc[i])?;
    }
    let chunks = split_chunks(bytes);
    // 0-based line index of each chunk's first line.
    let mut first_lines = Vec::with_capacity(chunks.len());
    let mut count = 0;
    for &(a, b) in &chunks {
        first_lines.push(count);
        count += memchr::memchr_iter(b'\n', &bytes[a..b]).count();
    }
    let delim = parsed.layout.delimiter;
    let lines = &parsed.lines;
    let parts: Vec<Vec<u8>> = chunks
        .par_iter()
        .zip(first_lines.par_iter())
        .map(|(&(a, b), &first)| {
            let row0 = lines.partition_point(|&l| l <= first);
            rewrite_chunk(&bytes[a..b], first, lines, row0, fmt, delim, gyro, acc)
        })
        .collect();
    let mut text = Vec::with_capacity(parts.iter().map(Vec::len).sum::<usize>() + 3);
    text.extend_from_slice(&all[..all.len() - bytes.len()]); // the BOM, if any
    for p in parts {
        text.extend_from_slice(&p);
    }
    write_atomic(out.as_ref(), &text)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fmt(cols: &str, t: &str, g: &str, a: &str) -> CsvFormat {
        CsvFormat::parse(cols, t, g, a).unwrap()
    }

    #[test]
    fn column_maps_place_every_quantity_once() {
        let m = ColumnMap::parse(" T, _ ,gx,gy,gz,_,ax,ay,az").unwrap();
        assert_eq!(m.at, [0, 2, 3, 4, 6, 7, 8]);
        assert_eq!(m.width(), 9);
        for bad in ["t,gx,gy,gz,ax,ay", "t,gx,gy,gz,ax,ay,az,gx", "t,wx,gy,gz,ax,ay,az", ""] {
            assert!(
                matches!(ColumnMap::parse(bad), Err(ImuError::InvalidInput(_))),
                "{bad:?}"
            );
        }
    }

    #[test]
    fn units_parse_and_unknown_ones_are_typed() {
        assert_eq!(TimeUnit::parse("us").unwrap(), TimeUnit::Microseconds);
        assert_eq!(AccUnit::parse("m/s^2").unwrap(), AccUnit::MetersPerSecond2);
        let e = GyroUnit::parse("rpm").unwrap_err();
        assert!(matches!(e, ImuError::UnknownUnit { what: "gyro", .. }));
        assert!(e.to_string().contains("rad/s, deg/s"), "{e}");
        assert!(CsvFormat::parse("t,gx,gy,gz,ax,ay,az", "min", "rad/s", "g").is_err());
    }

    #[test]
    fn delimiters_are_detected() {
        assert_eq!(detect_delimiter(b"1;2,5;3"), Delimiter::Semicolon);
        assert_eq!(detect_delimiter(b"a, b"), Delimiter::Comma);
        assert_eq!(detect_delimiter(b"a\tb c"), Delimiter::Tab);
        assert_eq!(detect_delimiter(b"a  b"), Delimiter::Whitespace);
        let mut s = Vec::new();
        field_spans(b" 1 , 2,3 ", Delimiter::Comma, &mut s);
        assert_eq!(s, vec![(1, 2), (5, 6), (7, 8)]);
        field_spans(b"  1  2\t3", Delimiter::Whitespace, &mut s);
        assert_eq!(s, vec![(2, 3), (5, 6), (7, 8)]);
    }

    #[test]
    fn reads_units_order_header_and_comments() {
        let f = fmt("gx,gy,gz,_,t,ax,ay,az", "ms", "deg/s", "g");
        let text = b"# exported by a logger\nwx;wy;wz;temp;time;x;y;z;extra\n\
180;0;-90;25.0;1000.5;1;0;-0.5;q\n# a note\n\n0;0;0;25.1;1001;0;0;1;r\n";
        let p = parse(Path::new("u.csv"), text, &f).unwrap();
        assert_eq!(p.layout.delimiter, Delimiter::Semicolon);
        assert_eq!(p.layout.header_line, Some(2));
        assert_eq!(p.samples.t_ns, vec![1_000_500_000, 1_001_000_000]);
        assert_eq!(
            p.samples.gyro[0],
            [std::f64::consts::PI, 0.0, -std::f64::consts::FRAC_PI_2]
        );
        assert_eq!(p.samples.acc[0], [STANDARD_GRAVITY, 0.0, -0.5 * STANDARD_GRAVITY]);
        assert_eq!(p.lines, vec![3, 6]);
    }

    #[test]
    fn errors_name_file_line_column_and_field() {
        let f = fmt("t,gx,gy,gz,ax,ay,az", "s", "rad/s", "m/s2");
        let head = "time,wx,wy,wz,ax,ay,az\n";
        let cases: [(&str, &str); 4] = [
            (
                "0.0,0,0,0,0,0,9\n0.01,0,0,0,0,0\n",
                "u.csv:3:7: field \"az\" is missing",
            ),
            (
                "0.0,0,0,0,0,0,9\n0.01,0,x,0,0,0,9\n",
                "u.csv:3:3: field \"wy (gy)\" = \"x\"",
            ),
            (
                "0.0,0,0,0,0,0,9\n0.01,0,0,inf,0,0,9\n",
                "u.csv:3:4: field \"wz (gz)\" = \"inf\" is not finite",
            ),
            (
                "0.02,0,0,0,0,0,9\n0.01,0,0,0,0,0,9\n",
                "u.csv:3:1: field \"time (t)\" = 10000000",
            ),
        ];
        for (body, want) in cases {
            let text = format!("{head}{body}");
            let msg = parse(Path::new("u.csv"), text.as_bytes(), &f)
                .err()
                .unwrap()
                .to_string();
            assert!(msg.starts_with(want), "{msg:?} does not start with {want:?}");
        }
        // A header too short for the map.
        let msg = parse(Path::new("u.csv"), b"a,b,c\n", &f).err().unwrap().to_string();
        assert!(msg.starts_with("u.csv:1:4: field \"gz\" is missing"), "{msg}");
        // The stamp out of order comes before a bad value further down.
        let text = format!("{head}0.02,0,0,0,0,0,9\n0.01,0,0,0,0,0,9\n0.03,0,x,0,0,0,9\n");
        assert!(matches!(
            parse(Path::new("u.csv"), text.as_bytes(), &f),
            Err(ImuError::Timestamp { line: 3, .. })
        ));
        assert!(matches!(
            parse(Path::new("u.csv"), b"0.0,0,0,0,0,0,9\n", &f),
            Err(ImuError::TooFewRows { found: 1, .. })
        ));
    }

    #[test]
    fn rewriting_keeps_everything_but_the_imu_fields() {
        let f = fmt("t,_,gx,gy,gz,ax,ay,az", "s", "deg/s", "g");
        let text = b"#c\r\nt ; label ; a ; b ; c ; d ; e ; f ; more\r\n0.5 ; x ; 1 ; 2 ; 3 ; 0 ; 0 ; 1 ; k\r\n1 ; y ; 4 ; 5 ; 6 ; 0 ; 0 ; 1 ; k";
        let p = parse(Path::new("u.csv"), text, &f).unwrap();
        let lines = p.lines.clone();
        let out = rewrite_chunk(
            text,
            0,
            &lines,
            0,
            &f,
            p.layout.delimiter,
            &p.samples.gyro,
            &p.samples.acc,
        );
        let again = parse(Path::new("u.csv"), &out, &f).unwrap();
        for i in 0..2 {
            for j in 0..3 {
                assert!((again.samples.gyro[i][j] - p.samples.gyro[i][j]).abs() < 1e-15);
                assert!((again.samples.acc[i][j] - p.samples.acc[i][j]).abs() < 1e-15);
            }
        }
        let s = String::from_utf8(out).unwrap();
        assert!(s.starts_with("#c\r\nt ; label ; a"), "{s}");
        assert!(s.contains("0.5 ; x ; 1 ; 2 ; 3 ; 0 ; 0 ; 1 ; k\r\n"), "{s}");
        assert!(s.ends_with("; k"), "{s}");
    }
}
