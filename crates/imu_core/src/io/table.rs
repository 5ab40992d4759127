//! The one numeric table reader behind every format: a timestamp column followed by float
//! columns, one row per line.
//!
//! Rules, the same for every format:
//! - The file is read whole; a UTF-8 BOM and CRLF line endings are accepted.
//! - Fields are separated by ',' (surrounding spaces/tabs trimmed) or by runs of whitespace.
//! - Every data row has the same number of columns (`ColumnCount` otherwise); the first data row
//!   picks it among the counts the format allows.
//! - A field that is not a number, an empty field included, is `NotNumeric`; NaN/inf is
//!   `NonFinite`.
//! - Nanosecond timestamps must be integers; float notation is `FloatTimestamp` unless
//!   `ReadOptions::allow_float_timestamps` (see there, also for the junk lines it drops).
//! - Second timestamps (`1403636580.83856`) are converted to ns from their decimal text, never
//!   through f64 (an f64 near 1.4e9 s only resolves ~0.2 µs), rounding half away from zero past
//!   the 9th fractional digit.
//! - Timestamps must be strictly increasing (`Timestamp` with `Duplicate`/`NotIncreasing`).
//! - Blank lines are allowed only at the end of the file.
//! - When several rows are bad, the first one in file order is reported, a stamp out of order
//!   included (it is not left for a check after every row has parsed).
//!
//! Rows are parsed in parallel over line-aligned chunks of the buffer; each chunk reports its
//! first problem with a chunk-local line number and the merge, walking chunks in order, keeps the
//! first one, so the parallelism never changes which error a user sees.

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::error::{ImuError, Result, RowsNeeded, TimestampProblem};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Separator {
    Comma,
    Whitespace,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TimeUnit {
    /// Integer nanoseconds (ASL, KAIST).
    Nanoseconds,
    /// Decimal seconds (TUM, Blackbird).
    Seconds,
}

#[derive(Clone, Debug)]
pub struct TableSpec {
    pub separator: Separator,
    /// Column counts (timestamp included) a row may have.
    pub columns: Vec<usize>,
    pub time_unit: TimeUnit,
    /// The first line is a header: skipped, and its comma-separated names (leading '#' removed)
    /// name the fields in errors.
    pub header_line: bool,
    /// Lines starting with '#' are comments wherever they are (TUM).
    pub hash_comments: bool,
    /// Field names for errors when there is no header line (at least as many as columns).
    pub names: Vec<String>,
    pub allow_float_timestamps: bool,
}

/// A parsed table: timestamps plus the other columns row-major.
#[derive(Clone, Debug, Default)]
pub struct Table {
    pub path: PathBuf,
    /// The header line as found (without line ending), when the spec has one.
    pub header: Option<String>,
    pub names: Vec<String>,
    pub n_columns: usize,
    pub t_ns: Vec<i64>,
    /// `n_columns - 1` values per row.
    pub values: Vec<f64>,
    /// 1-based file line of each row.
    pub lines: Vec<usize>,
}

impl Table {
    pub fn len(&self) -> usize {
        self.t_ns.len()
    }
    pub fn is_empty(&self) -> bool {
        self.t_ns.is_empty()
    }
    /// The non-timestamp values of row `i`; empty if `i` is out of range.
    pub fn row(&self, i: usize) -> &[f64] {
        let w = self.n_columns.saturating_sub(1);
        self.values.get(i * w..(i + 1) * w).unwrap_or(&[])
    }
}

/// Reads a whole file, mapping a missing file to `NotFound`.
pub fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|e| ImuError::io(path, e))
}

const BOM: &[u8] = b"\xEF\xBB\xBF";

pub(crate) fn strip_bom(bytes: &[u8]) -> &[u8] {
    bytes.strip_prefix(BOM).unwrap_or(bytes)
}

pub(crate) fn strip_cr(line: &[u8]) -> &[u8] {
    line.strip_suffix(b"\r").unwrap_or(line)
}

/// The first line of a file's bytes (BOM and line ending removed), lossily decoded.
pub fn first_line(bytes: &[u8]) -> String {
    line_text(strip_bom(bytes))
}

/// The first line of `bytes` as they are (line ending removed), lossily decoded.
fn line_text(bytes: &[u8]) -> String {
    let end = memchr::memchr(b'\n', bytes).unwrap_or(bytes.len());
    String::from_utf8_lossy(strip_cr(&bytes[..end])).into_owned()
}

/// `TooFewRows` unless `table` (parsed from `bytes`) holds at least `rows.needed` rows. Checked
/// by each reader rather than in `parse_table`, since only the reader knows what a row is for.
pub fn require_rows(table: &Table, bytes: &[u8], rows: &RowsNeeded) -> Result<()> {
    if table.len() >= rows.needed {
        return Ok(());
    }
    let line = match table.lines.last() {
        Some(&l) => l,
        None => count_lines(strip_bom(bytes)),
    };
    Err(ImuError::TooFewRows {
        path: table.path.clone(),
        line,
        rows: *rows,
        found: table.len(),
    })
}

/// Lines up to the last one holding anything but whitespace (0 for a blank file).
fn count_lines(bytes: &[u8]) -> usize {
    match bytes.iter().rposition(|b| !b.is_ascii_whitespace()) {
        Some(last) => memchr::memchr_iter(b'\n', &bytes[..last]).count() + 1,
        None => 0,
    }
}

/// Reads and parses `path` according to `spec`.
pub fn read_table(path: &Path, spec: &TableSpec) -> Result<Table> {
    let bytes = read_bytes(path)?;
    parse_table(path, &bytes, spec)
}

/// What went wrong on one line, before the file name and field names are attached.
#[derive(Debug, Clone)]
enum BadKind {
    ColumnCount { found: usize },
    NotNumeric { col: usize, value: String },
    NonFinite { col: usize, value: String },
    FloatTimestamp { col: usize, value: String },
}

#[derive(Debug, Clone)]
struct Bad {
    /// 0-based line index within the chunk (made file-global during the merge).
    line: usize,
    kind: BadKind,
}

#[derive(Default)]
struct ChunkOut {
    t: Vec<i64>,
    v: Vec<f64>,
    lines: Vec<usize>,
    n_lines: usize,
    /// A line that is fine only if nothing but blank/junk lines follows it in the file.
    pending: Option<Bad>,
    error: Option<Bad>,
}

struct Ctx<'a> {
    spec: &'a TableSpec,
    n_columns: usize,
}

/// Parses already-read bytes; `path` is only used in errors.
pub fn parse_table(path: &Path, bytes: &[u8], spec: &TableSpec) -> Result<Table> {
    let bytes = strip_bom(bytes);
    let mut body_start = 0;
    let mut first_body_line = 0; // 0-based line index of body_start
    let mut header = None;
    if spec.header_line {
        let end = memchr::memchr(b'\n', bytes).map_or(bytes.len(), |i| i + 1);
        // `bytes` has lost its BOM already; a second one is part of the header's text.
        header = Some(line_text(bytes));
        body_start = end;
        first_body_line = 1;
    }
    let body = &bytes[body_start..];

    let n_columns = pick_column_count(body, spec);
    let names = field_names(header.as_deref(), spec, n_columns);
    let ctx = Ctx { spec, n_columns };

    let chunks = split_chunks(body);
    let outs: Vec<ChunkOut> = if chunks.len() == 1 {
        vec![parse_chunk(body, &ctx)]
    } else {
        chunks
            .par_iter()
            .map(|&(a, b)| parse_chunk(&body[a..b], &ctx))
            .collect()
    };

    let mut table = Table {
        path: path.to_path_buf(),
        header,
        names,
        n_columns,
        ..Table::default()
    };
    let total: usize = outs.iter().map(|o| o.t.len()).sum();
    table.t_ns.reserve_exact(total);
    table.values.reserve_exact(total * n_columns.saturating_sub(1));
    table.lines.reserve_exact(total);

    let mut offset = first_body_line;
    let mut pending: Option<Bad> = None;
    for out in outs {
        let has_rows = !out.t.is_empty();
        if has_rows || out.error.is_some() {
            if let Some(p) = pending.take() {
                // Every row so far is above the pending line: a stamp out of order among them
                // comes first in the file.
                check_increasing(&table)?;
                return Err(to_error(path, &table.names, n_columns, p));
            }
        }
        // A chunk's rows all come before its bad line, if it has one.
        table.t_ns.extend_from_slice(&out.t);
        table.values.extend_from_slice(&out.v);
        table.lines.extend(out.lines.iter().map(|l| l + offset + 1));
        if let Some(mut e) = out.error {
            check_increasing(&table)?;
            e.line += offset;
            return Err(to_error(path, &table.names, n_columns, e));
        }
        if pending.is_none() {
            pending = out.pending.map(|mut p| {
                p.line += offset;
                p
            });
        }
        offset += out.n_lines;
    }

    check_increasing(&table)?;
    Ok(table)
}

/// The first data row picks the column count among the allowed ones; a row fitting none gets the
/// nearest allowed count so that the chunk parse reports it as `ColumnCount`.
fn pick_column_count(body: &[u8], spec: &TableSpec) -> usize {
    let fallback = spec.columns.first().copied().unwrap_or(0);
    let mut fields = Vec::new();
    for line in body.split(|&b| b == b'\n') {
        let line = strip_cr(line);
        if is_blank(line) || (spec.hash_comments && is_comment(line)) {
            continue;
        }
        split_fields(line, spec.separator, &mut fields);
        let n = fields.len();
        return spec
            .columns
            .iter()
            .copied()
            .min_by_key(|&c| c.abs_diff(n))
            .unwrap_or(fallback);
    }
    fallback
}

fn field_names(header: Option<&str>, spec: &TableSpec, n_columns: usize) -> Vec<String> {
    if let Some(h) = header {
        let names: Vec<String> = h
            .split(',')
            .enumerate()
            .map(|(i, s)| {
                let s = s.trim();
                let s = if i == 0 { s.trim_start_matches('#').trim() } else { s };
                s.to_string()
            })
            .collect();
        if names.len() >= n_columns {
            return names;
        }
    }
    (0..n_columns)
        .map(|i| {
            spec.names
                .get(i)
                .cloned()
                .unwrap_or_else(|| format!("column {}", i + 1))
        })
        .collect()
}

/// Line-aligned byte ranges of `body`; one range for small inputs, where threads cost more than
/// they save.
pub(crate) fn split_chunks(body: &[u8]) -> Vec<(usize, usize)> {
    const MIN_CHUNK: usize = 64 * 1024;
    let threads = rayon::current_num_threads().max(1);
    let n = (body.len() / MIN_CHUNK).clamp(1, threads * 4);
    let mut out = Vec::with_capacity(n);
    let mut start = 0;
    for k in 1..n {
        let guess = (body.len() * k / n).max(start);
        let end = match memchr::memchr(b'\n', &body[guess..]) {
            Some(i) => guess + i + 1,
            None => body.len(),
        };
        if end > start {
            out.push((start, end));
            start = end;
        }
    }
    if start < body.len() || out.is_empty() {
        out.push((start, body.len()));
    }
    out
}

pub(crate) fn is_blank(line: &[u8]) -> bool {
    line.iter().all(|b| b.is_ascii_whitespace())
}

pub(crate) fn is_comment(line: &[u8]) -> bool {
    line.iter().find(|b| !b.is_ascii_whitespace()) == Some(&b'#')
}

pub(crate) fn trim_field(f: &[u8]) -> &[u8] {
    let start = f.iter().position(|&b| b != b' ' && b != b'\t').unwrap_or(f.len());
    let end = f
        .iter()
        .rposition(|&b| b != b' ' && b != b'\t')
        .map_or(start, |i| i + 1);
    &f[start..end]
}

fn split_fields<'a>(line: &'a [u8], sep: Separator, out: &mut Vec<&'a [u8]>) {
    out.clear();
    match sep {
        Separator::Comma => {
            let mut start = 0;
            for i in memchr::memchr_iter(b',', line) {
                out.push(trim_field(&line[start..i]));
                start = i + 1;
            }
            out.push(trim_field(&line[start..]));
        }
        Separator::Whitespace => {
            out.extend(line.split(|b| b.is_ascii_whitespace()).filter(|f| !f.is_empty()));
        }
    }
}

/// Spreadsheet padding: separators with nothing after the first field (see `ReadOptions`).
fn is_junk(fields: &[&[u8]]) -> bool {
    fields.len() > 1 && fields.iter().skip(1).all(|f| f.is_empty())
}

fn parse_chunk(chunk: &[u8], ctx: &Ctx<'_>) -> ChunkOut {
    let spec = ctx.spec;
    let lenient = spec.allow_float_timestamps;
    let w = ctx.n_columns.saturating_sub(1);
    // ~60 bytes per row is a good guess for IMU CSVs; over-reserving a little is cheap.
    let est = chunk.len() / 48 + 1;
    let mut out = ChunkOut {
        t: Vec::with_capacity(est),
        v: Vec::with_capacity(est * w),
        lines: Vec::with_capacity(est),
        ..ChunkOut::default()
    };
    let mut fields: Vec<&[u8]> = Vec::with_capacity(ctx.n_columns + 1);
    let fast = spec.separator == Separator::Comma && spec.time_unit == TimeUnit::Nanoseconds && w > 0;

    let mut pos = 0;
    let mut line_idx = 0;
    while pos < chunk.len() {
        let end = memchr::memchr(b'\n', &chunk[pos..]).map_or(chunk.len(), |i| pos + i);
        let line = strip_cr(&chunk[pos..end]);
        pos = end + 1;
        let this = line_idx;
        line_idx += 1;

        if spec.hash_comments && is_comment(line) {
            continue;
        }
        if is_blank(line) {
            if out.pending.is_none() {
                out.pending = Some(Bad {
                    line: this,
                    kind: BadKind::ColumnCount { found: 0 },
                });
            }
            continue;
        }
        // Plain rows (no padding, integer ns, finite floats) in one pass; anything else, and any
        // line that would be an error, goes the general way below, which reports it.
        if fast && out.pending.is_none() && fast_row(line, w, &mut out.t, &mut out.v) {
            out.lines.push(this);
            continue;
        }
        split_fields(line, spec.separator, &mut fields);
        if lenient && is_junk(&fields) {
            if out.pending.is_none() {
                let kind = match parse_row(&fields, ctx, &mut out.t, &mut out.v) {
                    Err(kind) => kind,
                    // Only a one-column table can parse a junk line; undo the row it pushed.
                    Ok(()) => {
                        out.t.pop();
                        BadKind::ColumnCount { found: fields.len() }
                    }
                };
                out.pending = Some(Bad { line: this, kind });
            }
            continue;
        }
        if let Some(p) = out.pending.take() {
            out.error = Some(p);
            break;
        }
        match parse_row(&fields, ctx, &mut out.t, &mut out.v) {
            Ok(()) => out.lines.push(this),
            Err(kind) => {
                out.error = Some(Bad { line: this, kind });
                break;
            }
        }
    }
    out.n_lines = line_idx;
    // A row that failed half-way may have pushed some values; they are never used, but keep the
    // vectors consistent for whoever reads `out`.
    out.t.truncate(out.lines.len());
    out.v.truncate(out.lines.len() * w);
    out
}

/// One comma-separated row of an integer ns stamp and `w` finite floats, with no spaces, parsed
/// without splitting it first. Returns false, having pushed nothing, for anything else; the
/// general path then parses (or rejects) the line. Accepts only lines that the general path
/// parses to the same values: the stamp rule is `parse_time`'s digits-only one, and each float
/// is the same fast-float parse of the same bytes (a field must end exactly at the comma).
#[inline]
fn fast_row(line: &[u8], w: usize, t: &mut Vec<i64>, v: &mut Vec<f64>) -> bool {
    let digits = line.iter().take_while(|b| b.is_ascii_digit()).count();
    if digits == 0 || digits > 19 || line.get(digits) != Some(&b',') {
        return false;
    }
    let n = line[..digits]
        .iter()
        .fold(0u64, |acc, &d| acc * 10 + u64::from(d - b'0'));
    let Ok(stamp) = i64::try_from(n) else {
        return false;
    };
    let start = v.len();
    let mut pos = digits + 1;
    for i in 0..w {
        match fast_float2::parse_partial::<f64, _>(&line[pos..]) {
            Ok((x, used)) if used > 0 && x.is_finite() => {
                pos += used;
                let end_ok = if i + 1 == w {
                    pos == line.len()
                } else {
                    line.get(pos) == Some(&b',')
                };
                if !end_ok {
                    v.truncate(start);
                    return false;
                }
                pos += 1;
                v.push(x);
            }
            _ => {
                v.truncate(start);
                return false;
            }
        }
    }
    t.push(stamp);
    true
}

fn lossy(f: &[u8]) -> String {
    String::from_utf8_lossy(f).into_owned()
}

fn parse_row(fields: &[&[u8]], ctx: &Ctx<'_>, t: &mut Vec<i64>, v: &mut Vec<f64>) -> Result<(), BadKind> {
    if fields.len() != ctx.n_columns {
        return Err(BadKind::ColumnCount { found: fields.len() });
    }
    let stamp = parse_time(fields[0], ctx.spec)?;
    let start = v.len();
    for (i, f) in fields.iter().enumerate().skip(1) {
        match fast_float2::parse::<f64, _>(f) {
            Ok(x) if x.is_finite() => v.push(x),
            Ok(_) => {
                v.truncate(start);
                return Err(BadKind::NonFinite {
                    col: i + 1,
                    value: lossy(f),
                });
            }
            Err(_) => {
                v.truncate(start);
                return Err(BadKind::NotNumeric {
                    col: i + 1,
                    value: lossy(f),
                });
            }
        }
    }
    t.push(stamp);
    Ok(())
}

fn not_a_stamp(f: &[u8]) -> BadKind {
    match fast_float2::parse::<f64, _>(f) {
        Ok(x) if !x.is_finite() => BadKind::NonFinite {
            col: 1,
            value: lossy(f),
        },
        _ => BadKind::NotNumeric {
            col: 1,
            value: lossy(f),
        },
    }
}

fn parse_time(f: &[u8], spec: &TableSpec) -> Result<i64, BadKind> {
    match spec.time_unit {
        TimeUnit::Nanoseconds => {
            // 19 digits always fit in u64, and cover every ns stamp up to year 2262.
            if !f.is_empty() && f.len() <= 19 && f.iter().all(u8::is_ascii_digit) {
                let n = f.iter().fold(0u64, |acc, &d| acc * 10 + u64::from(d - b'0'));
                return i64::try_from(n).map_err(|_| BadKind::NotNumeric {
                    col: 1,
                    value: lossy(f),
                });
            }
            match parse_decimal(f, 0) {
                Decimal::Int(n) => Ok(n),
                Decimal::Frac(n) if spec.allow_float_timestamps => Ok(n),
                Decimal::Frac(_) => Err(BadKind::FloatTimestamp {
                    col: 1,
                    value: lossy(f),
                }),
                Decimal::Invalid | Decimal::OutOfRange => Err(not_a_stamp(f)),
            }
        }
        TimeUnit::Seconds => match parse_decimal(f, 9) {
            Decimal::Int(n) | Decimal::Frac(n) => Ok(n),
            Decimal::Invalid | Decimal::OutOfRange => Err(not_a_stamp(f)),
        },
    }
}

/// Result of reading a decimal number as an integer count of 10^-scale units.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Decimal {
    /// Written as a plain integer.
    Int(i64),
    /// Written with a decimal point or an exponent; rounded half away from zero.
    Frac(i64),
    Invalid,
    OutOfRange,
}

/// Exact decimal text → integer units of 10^-`scale` (scale 9: seconds → ns), so that stamps keep
/// every digit the file has.
pub(crate) fn parse_decimal(s: &[u8], scale: i64) -> Decimal {
    let mut i = 0;
    let neg = match s.first() {
        Some(b'-') => {
            i += 1;
            true
        }
        Some(b'+') => {
            i += 1;
            false
        }
        _ => false,
    };
    let int_start = i;
    while i < s.len() && s[i].is_ascii_digit() {
        i += 1;
    }
    let int_digits = &s[int_start..i];
    let mut frac_digits: &[u8] = &[];
    let mut fractional = false;
    if i < s.len() && s[i] == b'.' {
        fractional = true;
        i += 1;
        let fs = i;
        while i < s.len() && s[i].is_ascii_digit() {
            i += 1;
        }
        frac_digits = &s[fs..i];
    }
    if int_digits.is_empty() && frac_digits.is_empty() {
        return Decimal::Invalid;
    }
    let mut exp: i64 = 0;
    if i < s.len() && (s[i] == b'e' || s[i] == b'E') {
        fractional = true;
        i += 1;
        let eneg = match s.get(i) {
            Some(b'-') => {
                i += 1;
                true
            }
            Some(b'+') => {
                i += 1;
                false
            }
            _ => false,
        };
        let es = i;
        while i < s.len() && s[i].is_ascii_digit() {
            // Saturate: any exponent this large is out of range (or zero) anyway.
            exp = (exp * 10 + i64::from(s[i] - b'0')).min(1_000_000);
            i += 1;
        }
        if i == es {
            return Decimal::Invalid;
        }
        if eneg {
            exp = -exp;
        }
    }
    if i != s.len() {
        return Decimal::Invalid;
    }

    // value = D × 10^e10 with D the digit string int_digits ++ frac_digits.
    let n_int = int_digits.len() as i64;
    let n = n_int + frac_digits.len() as i64;
    let e10 = exp - frac_digits.len() as i64 + scale;
    let digit = |k: i64| -> u8 {
        let k = k as usize;
        if k < int_digits.len() {
            int_digits[k] - b'0'
        } else {
            frac_digits[k - int_digits.len()] - b'0'
        }
    };
    let keep = n + e10; // digits of D that form the integer part of the result
    const LIMIT: i128 = i64::MAX as i128 + 1;
    let mut acc: i128 = 0;
    for k in 0..keep.clamp(0, n) {
        acc = acc * 10 + i128::from(digit(k));
        if acc > LIMIT {
            return Decimal::OutOfRange;
        }
    }
    if keep > n {
        for _ in 0..(keep - n) {
            if acc == 0 {
                break;
            }
            acc *= 10;
            if acc > LIMIT {
                return Decimal::OutOfRange;
            }
        }
    } else if keep >= 0 && keep < n && digit(keep) >= 5 {
        acc += 1;
    }
    let signed = if neg { -acc } else { acc };
    match i64::try_from(signed) {
        Ok(v) if fractional => Decimal::Frac(v),
        Ok(v) => Decimal::Int(v),
        Err(_) => Decimal::OutOfRange,
    }
}

fn field_name(names: &[String], col: usize) -> String {
    names
        .get(col.wrapping_sub(1))
        .cloned()
        .unwrap_or_else(|| format!("column {col}"))
}

fn to_error(path: &Path, names: &[String], n_columns: usize, bad: Bad) -> ImuError {
    let path = path.to_path_buf();
    let line = bad.line + 1;
    match bad.kind {
        BadKind::ColumnCount { found } => ImuError::ColumnCount {
            path,
            line,
            expected: n_columns,
            found,
        },
        BadKind::NotNumeric { col, value } => ImuError::NotNumeric {
            path,
            line,
            column: col,
            field: field_name(names, col),
            value,
        },
        BadKind::NonFinite { col, value } => ImuError::NonFinite {
            path,
            line,
            column: col,
            field: field_name(names, col),
            value,
        },
        BadKind::FloatTimestamp { col, value } => ImuError::FloatTimestamp {
            path,
            line,
            column: col,
            field: field_name(names, col),
            value,
        },
    }
}

fn check_increasing(table: &Table) -> Result<()> {
    for i in 1..table.t_ns.len() {
        let (prev, cur) = (table.t_ns[i - 1], table.t_ns[i]);
        if cur <= prev {
            let problem = if cur == prev {
                TimestampProblem::Duplicate
            } else {
                TimestampProblem::NotIncreasing
            };
            return Err(ImuError::Timestamp {
                path: table.path.clone(),
                line: table.lines[i],
                column: 1,
                field: field_name(&table.names, 1),
                value: cur,
                previous: prev,
                problem,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimal_seconds_to_ns() {
        assert_eq!(
            parse_decimal(b"1403636580.83856", 9),
            Decimal::Frac(1_403_636_580_838_560_000)
        );
        assert_eq!(
            parse_decimal(b"1525745925.001598119736", 9),
            Decimal::Frac(1_525_745_925_001_598_120)
        );
        assert_eq!(
            parse_decimal(b"1525745925.0015981194", 9),
            Decimal::Frac(1_525_745_925_001_598_119)
        );
        assert_eq!(parse_decimal(b"12", 9), Decimal::Int(12_000_000_000));
        assert_eq!(parse_decimal(b"-0.5", 9), Decimal::Frac(-500_000_000));
        assert_eq!(parse_decimal(b"-0.0000000005", 9), Decimal::Frac(-1));
        assert_eq!(parse_decimal(b"0.0000000004", 9), Decimal::Frac(0));
        assert_eq!(parse_decimal(b".5", 9), Decimal::Frac(500_000_000));
        assert_eq!(parse_decimal(b"1.5e3", 0), Decimal::Frac(1500));
    }

    #[test]
    fn decimal_float_notation_ns_is_exact() {
        assert_eq!(
            parse_decimal(b"1.40363657975856E+018", 0),
            Decimal::Frac(1_403_636_579_758_560_000)
        );
        assert_eq!(
            parse_decimal(b"1403636579758560000", 0),
            Decimal::Int(1_403_636_579_758_560_000)
        );
    }

    #[test]
    fn decimal_rejects_garbage_and_overflow() {
        for s in [
            &b""[..],
            b"-",
            b".",
            b"1e",
            b"1.2.3",
            b"abc",
            b"1 2",
            b"nan",
            b"inf",
            b"0x10",
        ] {
            assert_eq!(
                parse_decimal(s, 9),
                Decimal::Invalid,
                "{:?}",
                String::from_utf8_lossy(s)
            );
        }
        assert_eq!(parse_decimal(b"1e30", 0), Decimal::OutOfRange);
        assert_eq!(parse_decimal(b"99999999999999999999", 0), Decimal::OutOfRange);
        assert_eq!(parse_decimal(b"0e999999999999", 0), Decimal::Frac(0));
        assert_eq!(parse_decimal(b"1e-999999999999", 0), Decimal::Frac(0));
    }

    #[test]
    fn chunks_are_line_aligned_and_cover_everything() {
        let text: Vec<u8> = (0..50_000).flat_map(|i| format!("{i},1.0\n").into_bytes()).collect();
        let chunks = split_chunks(&text);
        assert_eq!(chunks.first().map(|c| c.0), Some(0));
        assert_eq!(chunks.last().map(|c| c.1), Some(text.len()));
        for w in chunks.windows(2) {
            assert_eq!(w[0].1, w[1].0);
            assert_eq!(text[w[0].1 - 1], b'\n');
        }
    }

    #[test]
    fn fast_rows_parse_as_the_general_path_does() {
        let spec = TableSpec {
            separator: Separator::Comma,
            columns: vec![4],
            time_unit: TimeUnit::Nanoseconds,
            header_line: false,
            hash_comments: false,
            names: Vec::new(),
            allow_float_timestamps: false,
        };
        // Plain rows take the fast path; padded, signed and exponent forms mix in.
        let text = b"1,0.5,-2e-3,7\n2, 0.25 ,+1.5,1E2\n3,-0,.5,5.\n";
        let t = parse_table(Path::new("x"), text, &spec).unwrap();
        assert_eq!(t.t_ns, vec![1, 2, 3]);
        assert_eq!(t.values, vec![0.5, -2e-3, 7.0, 0.25, 1.5, 100.0, -0.0, 0.5, 5.0]);
        assert_eq!(t.lines, vec![1, 2, 3]);
        let (mut tv, mut v) = (Vec::new(), Vec::new());
        for bad in [
            &b"1,2,3"[..],
            b"1,2,3,4,",
            b"1,nan,2,3",
            b"1,2,3,4x",
            b"x,1,2,3",
            b"1,,2,3",
            b"1.0,1,2,3",
        ] {
            assert!(!fast_row(bad, 3, &mut tv, &mut v), "{:?}", String::from_utf8_lossy(bad));
            assert!(tv.is_empty() && v.is_empty());
        }
        for bad in [&b"1,2,3\n"[..], b"1,2,3,4,\n", b"1,nan,2,3\n", b"1,,2,3\n"] {
            assert!(parse_table(Path::new("x"), bad, &spec).is_err());
        }
    }
}
