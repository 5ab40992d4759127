//! The one row parser behind every reader: the dataset tables (ASL, TUM, KAIST, through
//! [`TableSpec`]), a user's own CSV ([`super::columns`]) and aiding trajectories
//! ([`super::tum::read_trajectory`]). Each reader finds its file's layout (delimiter, header,
//! column count) and describes it as `RowRules`: a column map (which file column holds the
//! time, which ones the values, in the order they are returned) with the rules below; the chunk
//! loop, the number rules and the errors live here once.
//!
//! Rules, the same for every reader:
//! - The file is read whole; a UTF-8 BOM and CRLF line endings are accepted.
//! - Fields are separated by one delimiter character (`,`, `;` or a tab; surrounding spaces and
//!   tabs trimmed) or by runs of whitespace.
//! - Comment lines start with `#` (after optional whitespace), where the reader allows comments;
//!   trajectories also allow a `# ...` comment after a row's fields.
//! - Blank lines are skipped. Dataset tables read through [`TableSpec`] (ASL, KAIST) are
//!   stricter: there a blank line is allowed only at the end of the file, since one inside the
//!   data is a sign of a damaged or concatenated recording.
//! - A row has exactly the column count the layout picked (`ColumnCount` otherwise), or, for a
//!   column map that ignores later columns, at least enough fields for every mapped column
//!   (`MissingColumn` naming the first mapped column past the line's end).
//! - A value field that is not a number, an empty field included, is `NotNumeric`; NaN/inf is
//!   `NonFinite`. Unmapped columns are never parsed.
//! - Time is converted to integer ns from its decimal text, never through f64 (an f64 near 1.4e9 s
//!   only resolves ~0.2 µs): `1403636579.763556` s is `1403636579763556000` ns exactly. Digits
//!   past the ns are rounded half to even on the digits themselves (`0.0000000005` s is 0 ns,
//!   `0.0000000015` s is 2 ns, `0.00000000050001` s is 1 ns).
//! - Integer-ns time columns of dataset tables must be integers; float notation is
//!   `FloatTimestamp` unless `ReadOptions::allow_float_timestamps` (see there, also for the
//!   trailing junk lines it drops).
//! - Timestamps must be strictly increasing (`Timestamp` with `Duplicate`/`NotIncreasing`).
//! - When several rows are bad, the first one in file order is reported, a stamp out of order
//!   included (it is not left for a check after every row has parsed). With `skip_bad_lines` a
//!   row with a bad field is skipped and listed instead; stamps out of order stay an error.
//! - Errors name the file, the 1-based line and column and the field.
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

/// A dataset table: a timestamp column followed by float columns, every column read.
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

// ---------------------------------------------------------------------------------------------
// The parser state

/// The field delimiter of a file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Delimiter {
    Comma,
    Semicolon,
    Tab,
    Whitespace,
}

impl From<Separator> for Delimiter {
    fn from(s: Separator) -> Self {
        match s {
            Separator::Comma => Delimiter::Comma,
            Separator::Whitespace => Delimiter::Whitespace,
        }
    }
}

/// Which lines (or line ends) are comments.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Comments {
    /// None: a line starting with '#' is a row like any other (and a bad one).
    None,
    /// Lines whose first non-blank character is '#'.
    Lines,
    /// Those, and everything from a '#' to the end of a row's line.
    LinesAndTrailing,
}

/// What a blank line inside the data is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum BlankLines {
    /// Skipped wherever it is.
    Skip,
    /// Allowed only when no row follows it (`ColumnCount` with 0 fields otherwise).
    OnlyAtEnd,
}

/// How many fields a row has.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Width {
    /// Exactly this many (`ColumnCount` otherwise).
    Exact(usize),
    /// At least this many; later fields are ignored (`MissingColumn` for fewer).
    AtLeast(usize),
}

/// The one parser state: how a file's rows are laid out and read (module doc).
#[derive(Clone, Debug)]
pub(crate) struct RowRules {
    pub delimiter: Delimiter,
    pub comments: Comments,
    pub blank_lines: BlankLines,
    pub width: Width,
    /// 0-based file column of the time.
    pub time_col: usize,
    /// Decimal digits from the time's unit down to ns (9 for seconds, 0 for ns).
    pub time_digits: i64,
    /// With `time_digits` 0: accept float notation (else `FloatTimestamp`).
    pub float_ns: bool,
    /// 0-based file columns of the values, in the order a row returns them.
    pub values: Vec<usize>,
    /// Drop spreadsheet padding lines after the last row (see `ReadOptions`).
    pub trailing_junk: bool,
    /// Skip (and list) a row with a bad or missing field instead of failing.
    pub skip_bad_lines: bool,
}

/// A line as the rules see it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum LineKind<'a> {
    Comment,
    Blank,
    /// A row's text, a trailing comment removed.
    Row(&'a [u8]),
}

/// What `line` (line ending removed) is under `comments`.
pub(crate) fn classify(line: &[u8], comments: Comments) -> LineKind<'_> {
    let line = match comments {
        Comments::None => line,
        Comments::Lines if is_comment(line) => return LineKind::Comment,
        Comments::Lines => line,
        Comments::LinesAndTrailing => match memchr::memchr(b'#', line) {
            Some(i) if is_blank(&line[..i]) => return LineKind::Comment,
            Some(i) => &line[..i],
            None => line,
        },
    };
    if is_blank(line) {
        LineKind::Blank
    } else {
        LineKind::Row(line)
    }
}

/// The first row of `body` that is neither blank nor a comment: (byte offset of its line,
/// 0-based line index, its text).
pub(crate) fn first_row(body: &[u8], comments: Comments) -> Option<(usize, usize, &[u8])> {
    let mut pos = 0;
    let mut idx = 0;
    while pos < body.len() {
        let end = memchr::memchr(b'\n', &body[pos..]).map_or(body.len(), |i| pos + i);
        if let LineKind::Row(text) = classify(strip_cr(&body[pos..end]), comments) {
            return Some((pos, idx, text));
        }
        pos = end + 1;
        idx += 1;
    }
    None
}

/// Byte ranges of the fields of `line` (trimmed of spaces and tabs for a delimiter character).
pub(crate) fn field_spans(line: &[u8], delim: Delimiter, out: &mut Vec<(usize, usize)>) {
    out.clear();
    let by = |sep: u8, out: &mut Vec<(usize, usize)>| {
        let mut start = 0;
        for end in memchr::memchr_iter(sep, line).chain(std::iter::once(line.len())) {
            let f = trim_field(&line[start..end]);
            // `trim_field` returns a subslice: its offset within `line` locates it.
            let a = f.as_ptr() as usize - line.as_ptr() as usize;
            out.push((a, a + f.len()));
            start = end + 1;
        }
    };
    match delim {
        Delimiter::Comma => by(b',', out),
        Delimiter::Semicolon => by(b';', out),
        Delimiter::Tab => by(b'\t', out),
        Delimiter::Whitespace => {
            let mut i = 0;
            while i < line.len() {
                if line[i].is_ascii_whitespace() {
                    i += 1;
                    continue;
                }
                let a = i;
                while i < line.len() && !line[i].is_ascii_whitespace() {
                    i += 1;
                }
                out.push((a, i));
            }
        }
    }
}

/// The fields of `line`, lossily decoded.
pub(crate) fn field_texts(line: &[u8], delim: Delimiter) -> Vec<String> {
    let mut spans = Vec::new();
    field_spans(line, delim, &mut spans);
    spans.iter().map(|&(a, b)| lossy(&line[a..b])).collect()
}

/// Whether `f` reads as a number (NaN and infinities included).
pub(crate) fn is_number(f: &[u8]) -> bool {
    fast_float2::parse::<f64, _>(f).is_ok()
}

/// What went wrong on one line, before the file name and field names are attached. Columns are
/// 0-based file columns.
#[derive(Debug, Clone)]
pub(crate) enum BadKind {
    /// The line has `found` fields, not what the width asks for.
    Count {
        found: usize,
    },
    NotNumeric {
        col: usize,
        value: String,
        hint: &'static str,
    },
    NonFinite {
        col: usize,
        value: String,
    },
    FloatTimestamp {
        col: usize,
        value: String,
    },
}

/// A bad line: what is wrong and where.
#[derive(Debug, Clone)]
pub(crate) struct Bad {
    /// 0-based line index: within the chunk while parsing, in the file after the merge.
    pub line: usize,
    pub kind: BadKind,
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
    skipped: Vec<Bad>,
    first_fields: Option<usize>,
}

/// Rows read by [`parse_rows`].
#[derive(Debug, Default)]
pub(crate) struct Rows {
    pub t_ns: Vec<i64>,
    /// `rules.values.len()` values per row.
    pub values: Vec<f64>,
    /// 1-based file line of each row.
    pub lines: Vec<usize>,
    /// Lines skipped (`skip_bad_lines`), 0-based file lines, in file order.
    pub skipped: Vec<Bad>,
    /// Fields of the first row, trailing empty ones (a delimiter at the line's end) left out.
    pub first_fields: Option<usize>,
}

impl RowRules {
    /// The time and value columns, in no particular order.
    fn mapped(&self) -> impl Iterator<Item = usize> + '_ {
        std::iter::once(self.time_col).chain(self.values.iter().copied())
    }

    /// Plain rows (comma, integer ns time first, then every value in file order) may take the
    /// one-pass path.
    fn fast(&self) -> bool {
        self.delimiter == Delimiter::Comma
            && self.time_col == 0
            && self.time_digits == 0
            && !self.values.is_empty()
            && self.values.iter().enumerate().all(|(i, &c)| c == i + 1)
            && match self.width {
                Width::Exact(n) => n == self.values.len() + 1,
                Width::AtLeast(n) => n <= self.values.len() + 1,
            }
    }

    /// The typed error for `bad`; `names` name the file's columns (0-based), `column N` past
    /// their end.
    pub fn error(&self, path: &Path, names: &[String], bad: Bad) -> ImuError {
        let path = path.to_path_buf();
        let line = bad.line + 1;
        let name = |c: usize| column_name(names, c);
        match bad.kind {
            BadKind::Count { found } => match self.width {
                Width::Exact(expected) => ImuError::ColumnCount {
                    path,
                    line,
                    expected,
                    found,
                },
                Width::AtLeast(_) => {
                    // The first mapped column (in file order) past the end of the line.
                    let c = self.mapped().filter(|&c| c >= found).min().unwrap_or(found);
                    ImuError::MissingColumn {
                        path,
                        line,
                        column: c + 1,
                        field: name(c),
                        found,
                    }
                }
            },
            BadKind::NotNumeric { col, value, hint } => ImuError::NotNumeric {
                path,
                line,
                column: col + 1,
                field: name(col),
                value,
                hint,
            },
            BadKind::NonFinite { col, value } => ImuError::NonFinite {
                path,
                line,
                column: col + 1,
                field: name(col),
                value,
            },
            BadKind::FloatTimestamp { col, value } => ImuError::FloatTimestamp {
                path,
                line,
                column: col + 1,
                field: name(col),
                value,
            },
        }
    }

    /// One row's time and values, pushed onto `t` and `v` (nothing pushed on error).
    fn parse_row(
        &self,
        line: &[u8],
        spans: &[(usize, usize)],
        t: &mut Vec<i64>,
        v: &mut Vec<f64>,
    ) -> std::result::Result<(), BadKind> {
        let found = spans.len();
        match self.width {
            Width::Exact(n) if found != n => return Err(BadKind::Count { found }),
            Width::AtLeast(n) if found < n => return Err(BadKind::Count { found }),
            _ => {}
        }
        let field = |c: usize| {
            let (a, b) = spans[c];
            &line[a..b]
        };
        let stamp = self.parse_time(field(self.time_col))?;
        let start = v.len();
        for &c in &self.values {
            let f = field(c);
            match fast_float2::parse::<f64, _>(f) {
                Ok(x) if x.is_finite() => v.push(x),
                _ => {
                    v.truncate(start);
                    return Err(bad_number(c, f));
                }
            }
        }
        t.push(stamp);
        Ok(())
    }

    fn parse_time(&self, f: &[u8]) -> std::result::Result<i64, BadKind> {
        let col = self.time_col;
        if self.time_digits == 0 {
            // 19 digits always fit in u64, and cover every ns stamp up to year 2262.
            if !f.is_empty() && f.len() <= 19 && f.iter().all(u8::is_ascii_digit) {
                let n = f.iter().fold(0u64, |acc, &d| acc * 10 + u64::from(d - b'0'));
                return i64::try_from(n).map_err(|_| BadKind::NotNumeric {
                    col,
                    value: lossy(f),
                    hint: TIME_RANGE_HINT,
                });
            }
        }
        match parse_decimal(f, self.time_digits) {
            Decimal::Int(n) => Ok(n),
            Decimal::Frac(n) if self.time_digits > 0 || self.float_ns => Ok(n),
            Decimal::Frac(_) => Err(BadKind::FloatTimestamp { col, value: lossy(f) }),
            Decimal::OutOfRange if fast_float2::parse::<f64, _>(f).is_ok_and(f64::is_finite) => {
                Err(BadKind::NotNumeric {
                    col,
                    value: lossy(f),
                    hint: TIME_RANGE_HINT,
                })
            }
            Decimal::Invalid | Decimal::OutOfRange => Err(bad_number(col, f)),
        }
    }

    fn parse_chunk(&self, chunk: &[u8]) -> ChunkOut {
        let w = self.values.len();
        // ~60 bytes per row is a good guess for IMU CSVs; over-reserving a little is cheap.
        let est = chunk.len() / 48 + 1;
        let mut out = ChunkOut {
            t: Vec::with_capacity(est),
            v: Vec::with_capacity(est * w),
            lines: Vec::with_capacity(est),
            ..ChunkOut::default()
        };
        let mut spans: Vec<(usize, usize)> = Vec::with_capacity(w + 4);
        let fast = self.fast();
        let (mut pos, mut line_idx) = (0, 0);
        while pos < chunk.len() {
            let end = memchr::memchr(b'\n', &chunk[pos..]).map_or(chunk.len(), |i| pos + i);
            let raw = strip_cr(&chunk[pos..end]);
            pos = end + 1;
            let this = line_idx;
            line_idx += 1;

            let line = match classify(raw, self.comments) {
                LineKind::Comment => continue,
                LineKind::Blank => {
                    if self.blank_lines == BlankLines::OnlyAtEnd && out.pending.is_none() {
                        out.pending = Some(Bad {
                            line: this,
                            kind: BadKind::Count { found: 0 },
                        });
                    }
                    continue;
                }
                LineKind::Row(line) => line,
            };
            // Plain rows (no padding, integer ns, finite floats) in one pass; anything else, and
            // any line that would be an error, goes the general way below, which reports it.
            if fast && out.pending.is_none() && fast_row(line, w, &mut out.t, &mut out.v) {
                out.lines.push(this);
                out.first_fields.get_or_insert(w + 1);
                continue;
            }
            field_spans(line, self.delimiter, &mut spans);
            if self.trailing_junk && is_junk(&spans) {
                if out.pending.is_none() {
                    let kind = match self.parse_row(line, &spans, &mut out.t, &mut out.v) {
                        Err(kind) => kind,
                        // Only a table whose values all lie in its first column can parse a junk
                        // line; undo the row it pushed.
                        Ok(()) => {
                            out.t.pop();
                            out.v.truncate(out.v.len() - w);
                            BadKind::Count { found: spans.len() }
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
            match self.parse_row(line, &spans, &mut out.t, &mut out.v) {
                Ok(()) => {
                    out.lines.push(this);
                    // Trailing empty fields (a delimiter at the end of the line) are no columns.
                    out.first_fields
                        .get_or_insert_with(|| spans.iter().rposition(|&(a, b)| b > a).map_or(0, |i| i + 1));
                }
                Err(kind) if self.skip_bad_lines => out.skipped.push(Bad { line: this, kind }),
                Err(kind) => {
                    out.error = Some(Bad { line: this, kind });
                    break;
                }
            }
        }
        out.n_lines = line_idx;
        out
    }
}

/// Parses the rows of `body`, whose first line is file line `first_line` (0-based), by `rules`;
/// `path` and `names` (one per file column) are only used in errors.
pub(crate) fn parse_rows(
    path: &Path,
    body: &[u8],
    first_line: usize,
    rules: &RowRules,
    names: &[String],
) -> Result<Rows> {
    let chunks = split_chunks(body);
    let outs: Vec<ChunkOut> = if chunks.len() == 1 {
        vec![rules.parse_chunk(body)]
    } else {
        chunks
            .par_iter()
            .map(|&(a, b)| rules.parse_chunk(&body[a..b]))
            .collect()
    };
    let total: usize = outs.iter().map(|o| o.t.len()).sum();
    let mut rows = Rows {
        t_ns: Vec::with_capacity(total),
        values: Vec::with_capacity(total * rules.values.len()),
        lines: Vec::with_capacity(total),
        ..Rows::default()
    };
    let check = |rows: &Rows| check_increasing(path, names, rules.time_col, &rows.t_ns, &rows.lines);
    let mut offset = first_line;
    let mut pending: Option<Bad> = None;
    for out in outs {
        if !out.t.is_empty() || out.error.is_some() || !out.skipped.is_empty() {
            if let Some(p) = pending.take() {
                // Every row so far is above the pending line: a stamp out of order among them
                // comes first in the file.
                check(&rows)?;
                return Err(rules.error(path, names, p));
            }
        }
        rows.first_fields = rows.first_fields.or(out.first_fields);
        rows.skipped.extend(out.skipped.into_iter().map(|mut b| {
            b.line += offset;
            b
        }));
        // A chunk's rows all come before its bad line, if it has one.
        rows.t_ns.extend_from_slice(&out.t);
        rows.values.extend_from_slice(&out.v);
        rows.lines.extend(out.lines.iter().map(|l| l + offset + 1));
        if let Some(mut e) = out.error {
            check(&rows)?;
            e.line += offset;
            return Err(rules.error(path, names, e));
        }
        if pending.is_none() {
            pending = out.pending.map(|mut p| {
                p.line += offset;
                p
            });
        }
        offset += out.n_lines;
    }
    check(&rows)?;
    Ok(rows)
}

fn column_name(names: &[String], col: usize) -> String {
    names.get(col).cloned().unwrap_or_else(|| format!("column {}", col + 1))
}

fn check_increasing(path: &Path, names: &[String], time_col: usize, t: &[i64], lines: &[usize]) -> Result<()> {
    for i in 1..t.len() {
        let (prev, cur) = (t[i - 1], t[i]);
        if cur <= prev {
            return Err(ImuError::Timestamp {
                path: path.to_path_buf(),
                line: lines[i],
                column: time_col + 1,
                field: column_name(names, time_col),
                value: cur,
                previous: prev,
                problem: if cur == prev {
                    TimestampProblem::Duplicate
                } else {
                    TimestampProblem::NotIncreasing
                },
            });
        }
    }
    Ok(())
}

/// Spreadsheet padding: separators with nothing after the first field (see `ReadOptions`).
fn is_junk(spans: &[(usize, usize)]) -> bool {
    spans.len() > 1 && spans.iter().skip(1).all(|&(a, b)| a == b)
}

fn lossy(f: &[u8]) -> String {
    String::from_utf8_lossy(f).into_owned()
}

/// A time that parses as a number but lies past i64 nanoseconds (the year 2262) in the file's unit.
const TIME_RANGE_HINT: &str = " of the file's time unit before the year 2262 \
                               (milliseconds or microseconds read as seconds?)";

fn bad_number(col: usize, f: &[u8]) -> BadKind {
    match fast_float2::parse::<f64, _>(f) {
        Ok(x) if !x.is_finite() => BadKind::NonFinite { col, value: lossy(f) },
        _ => BadKind::NotNumeric {
            col,
            value: lossy(f),
            hint: "",
        },
    }
}

// ---------------------------------------------------------------------------------------------
// Dataset tables

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
    let comments = if spec.hash_comments {
        Comments::Lines
    } else {
        Comments::None
    };
    let delimiter = Delimiter::from(spec.separator);
    let n_columns = pick_column_count(body, delimiter, comments, &spec.columns);
    let names = field_names(header.as_deref(), spec, n_columns);
    let rules = RowRules {
        delimiter,
        comments,
        blank_lines: BlankLines::OnlyAtEnd,
        width: Width::Exact(n_columns),
        time_col: 0,
        time_digits: match spec.time_unit {
            TimeUnit::Nanoseconds => 0,
            TimeUnit::Seconds => 9,
        },
        float_ns: spec.allow_float_timestamps,
        values: (1..n_columns).collect(),
        trailing_junk: spec.allow_float_timestamps,
        skip_bad_lines: false,
    };
    let rows = parse_rows(path, body, first_body_line, &rules, &names)?;
    Ok(Table {
        path: path.to_path_buf(),
        header,
        names,
        n_columns,
        t_ns: rows.t_ns,
        values: rows.values,
        lines: rows.lines,
    })
}

/// The first row picks the column count among the allowed ones; a row fitting none gets the
/// nearest allowed count so that the parse reports it as `ColumnCount`.
pub(crate) fn pick_column_count(body: &[u8], delimiter: Delimiter, comments: Comments, allowed: &[usize]) -> usize {
    let fallback = allowed.first().copied().unwrap_or(0);
    let Some((_, _, line)) = first_row(body, comments) else {
        return fallback;
    };
    let mut spans = Vec::new();
    field_spans(line, delimiter, &mut spans);
    let n = spans.len();
    allowed
        .iter()
        .copied()
        .min_by_key(|&c| c.abs_diff(n))
        .unwrap_or(fallback)
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

// ---------------------------------------------------------------------------------------------
// Bytes and lines

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

/// Result of reading a decimal number as an integer count of 10^-scale units.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Decimal {
    /// Written as a plain integer.
    Int(i64),
    /// Written with a decimal point or an exponent; rounded half to even past the last unit.
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
    } else if keep >= 0 && keep < n {
        // Round half to even on the digits dropped: up past a half, to the even neighbour on an
        // exact half (`…5` followed by zeros only).
        let first = digit(keep);
        let past_half = || (keep + 1..n).any(|k| digit(k) != 0);
        if first > 5 || (first == 5 && (acc % 2 == 1 || past_half())) {
            acc += 1;
        }
    }
    let signed = if neg { -acc } else { acc };
    match i64::try_from(signed) {
        Ok(v) if fractional => Decimal::Frac(v),
        Ok(v) => Decimal::Int(v),
        Err(_) => Decimal::OutOfRange,
    }
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
        assert_eq!(parse_decimal(b"0.0000000004", 9), Decimal::Frac(0));
        assert_eq!(parse_decimal(b".5", 9), Decimal::Frac(500_000_000));
        assert_eq!(parse_decimal(b"1.5e3", 0), Decimal::Frac(1500));
    }

    #[test]
    fn digits_past_the_unit_round_half_to_even() {
        // Exact halves go to the even neighbour, on either side of zero.
        assert_eq!(parse_decimal(b"0.0000000005", 9), Decimal::Frac(0));
        assert_eq!(parse_decimal(b"0.0000000015", 9), Decimal::Frac(2));
        assert_eq!(parse_decimal(b"0.0000000025", 9), Decimal::Frac(2));
        assert_eq!(parse_decimal(b"-0.0000000005", 9), Decimal::Frac(0));
        assert_eq!(parse_decimal(b"-0.0000000015", 9), Decimal::Frac(-2));
        assert_eq!(
            parse_decimal(b"1403636579.7635560005", 9),
            Decimal::Frac(1_403_636_579_763_556_000)
        );
        assert_eq!(
            parse_decimal(b"1403636579.7635560015", 9),
            Decimal::Frac(1_403_636_579_763_556_002)
        );
        // Anything past the half, however far down, rounds up; below it, down.
        assert_eq!(parse_decimal(b"0.00000000050000000001", 9), Decimal::Frac(1));
        assert_eq!(parse_decimal(b"0.00000000049999999999", 9), Decimal::Frac(0));
        assert_eq!(parse_decimal(b"2.5", 0), Decimal::Frac(2));
        assert_eq!(parse_decimal(b"3.5", 0), Decimal::Frac(4));
        assert_eq!(parse_decimal(b"25e-1", 0), Decimal::Frac(2));
        assert_eq!(parse_decimal(b"5e-10", 9), Decimal::Frac(0));
        assert_eq!(
            parse_decimal(b"1403636579.763556", 9),
            Decimal::Frac(1_403_636_579_763_556_000)
        );
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
