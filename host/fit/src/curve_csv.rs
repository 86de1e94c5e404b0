//! The measured-curve CSV, the interchange format every command reads
//! and writes: the single reader and writer of it.
//!
//! ```text
//! # source: tactile fem curve          <- `# key: value` lines are metadata
//! # p_air_kpa: 6                       <- other `#` lines are plain comments
//! u_s_mm,a_mm,load_n,p_air_kpa,phase   <- header row: u_s_mm and a_mm required
//! 0,0,0,6,load
//! 0.05,1.2,0.01,6,load
//! ```
//!
//! Columns: `u_s_mm`, `a_mm` (required, numbers); `load_n`, `p_air_kpa`, `t_s`, `h_mm`
//! (the tube's travel from first contact), `stage_mm` (the stage's position, zero wherever
//! the bench's is), `volume_mm3` (optional numbers), `phase` (optional, `load` or `unload`), `test`
//! (optional, replicate index, a non-negative integer). Optional columns may be left empty
//! in a row. Blank lines are ignored; comment lines may appear anywhere. Unknown or
//! duplicated columns are errors, so a misspelt column name is never silently dropped.

use std::fmt::Write as _;
use std::path::Path;

/// One row of a measured (or simulated) curve.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct CurveRow {
    pub u_s_mm: f64,
    pub a_mm: f64,
    pub load_n: Option<f64>,
    pub p_air_kpa: Option<f64>,
    pub t_s: Option<f64>,
    pub phase: Option<Phase>,
    pub test: Option<u32>,
    pub h_mm: Option<f64>,
    /// The stage's position (mm, towards the sample), its zero the bench's own: the tube
    /// travel up to the unknown position of first contact.
    pub stage_mm: Option<f64>,
    pub volume_mm3: Option<f64>,
}

/// Loading or unloading part of an indentation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    Load,
    Unload,
}

impl Phase {
    pub fn as_str(self) -> &'static str {
        match self {
            Phase::Load => "load",
            Phase::Unload => "unload",
        }
    }
}

/// A curve file: metadata (in file order) and rows.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CurveCsv {
    /// `# key: value` lines, in file order.
    pub metadata: Vec<(String, String)>,
    pub rows: Vec<CurveRow>,
}

impl CurveCsv {
    /// Value of metadata `key`, if present.
    pub fn meta(&self, key: &str) -> Option<&str> {
        self.metadata
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }
}

/// A problem with a curve file, naming the file and (where it applies) the line.
#[derive(Debug, thiserror::Error)]
pub enum CurveCsvError {
    #[error("{file}: {source}")]
    Io {
        file: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{file}:{line}: {reason}")]
    Parse {
        file: String,
        line: usize,
        reason: String,
    },
    #[error("{file}: {reason}")]
    Invalid { file: String, reason: String },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Column {
    USMm,
    AMm,
    LoadN,
    PAirKpa,
    TS,
    Phase,
    Test,
    HMm,
    StageMm,
    VolumeMm3,
}

/// Column order used by the writer.
const COLUMNS: [(Column, &str); 10] = [
    (Column::USMm, "u_s_mm"),
    (Column::AMm, "a_mm"),
    (Column::LoadN, "load_n"),
    (Column::PAirKpa, "p_air_kpa"),
    (Column::TS, "t_s"),
    (Column::Phase, "phase"),
    (Column::Test, "test"),
    (Column::HMm, "h_mm"),
    (Column::StageMm, "stage_mm"),
    (Column::VolumeMm3, "volume_mm3"),
];

fn column_named(name: &str) -> Option<Column> {
    COLUMNS.iter().find(|(_, n)| *n == name).map(|(c, _)| *c)
}

/// Largest curve file read (a 6-repeat record at 60 frames/s is well under 1 MB).
pub const MAX_CURVE_BYTES: u64 = 64 << 20;
/// Most data rows in one curve file.
pub const MAX_CURVE_ROWS: usize = 1_000_000;

/// Read a curve file.
pub fn read_curve_csv(path: &Path) -> Result<CurveCsv, CurveCsvError> {
    let file = path.display().to_string();
    let io = |source| CurveCsvError::Io {
        file: file.clone(),
        source,
    };
    let size = std::fs::metadata(path).map_err(io)?.len();
    if size > MAX_CURVE_BYTES {
        return Err(CurveCsvError::Invalid {
            file: file.clone(),
            reason: format!(
                "{size} bytes; a curve file is at most {MAX_CURVE_BYTES} bytes (is this a curve CSV?)"
            ),
        });
    }
    let text = fem_core::input_file::read_limited_text(path, MAX_CURVE_BYTES, "a curve file")
        .map_err(io)?;
    parse_curve_csv(&text, &file)
}

/// Parse curve-file text; `file` names it in errors.
pub fn parse_curve_csv(text: &str, file: &str) -> Result<CurveCsv, CurveCsvError> {
    let err = |line: usize, reason: String| CurveCsvError::Parse {
        file: file.to_string(),
        line,
        reason,
    };
    let mut out = CurveCsv::default();
    let mut columns: Option<Vec<Column>> = None;
    for (i, raw) in text.lines().enumerate() {
        let line_no = i + 1;
        let line = raw.trim();
        if line.is_empty() {
            continue;
        }
        if let Some(comment) = line.strip_prefix('#') {
            if let Some((key, value)) = comment.split_once(':') {
                let key = key.trim();
                if !key.is_empty() && !key.contains(char::is_whitespace) {
                    if out.metadata.iter().any(|(k, _)| k == key) {
                        return Err(err(line_no, format!("metadata key {key:?} given twice")));
                    }
                    out.metadata
                        .push((key.to_string(), value.trim().to_string()));
                }
            }
            continue;
        }
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        let Some(cols) = &columns else {
            let mut cols = Vec::with_capacity(cells.len());
            for name in &cells {
                let c = column_named(name).ok_or_else(|| {
                    err(
                        line_no,
                        format!(
                            "unknown column {name:?} in the header row (known: {})",
                            COLUMNS.map(|(_, n)| n).join(", ")
                        ),
                    )
                })?;
                if cols.contains(&c) {
                    return Err(err(line_no, format!("column {name:?} appears twice")));
                }
                cols.push(c);
            }
            for (req, name) in [(Column::USMm, "u_s_mm"), (Column::AMm, "a_mm")] {
                if !cols.contains(&req) {
                    return Err(err(
                        line_no,
                        format!("the header row lacks the required column {name:?}"),
                    ));
                }
            }
            columns = Some(cols);
            continue;
        };
        if out.rows.len() >= MAX_CURVE_ROWS {
            return Err(err(
                line_no,
                format!("more than {MAX_CURVE_ROWS} data rows; split the curve"),
            ));
        }
        if cells.len() != cols.len() {
            return Err(err(
                line_no,
                format!("{} fields, the header row has {}", cells.len(), cols.len()),
            ));
        }
        let mut row = CurveRow::default();
        for (&c, &cell) in cols.iter().zip(&cells) {
            let name = COLUMNS
                .iter()
                .find(|(k, _)| *k == c)
                .map(|(_, n)| *n)
                .unwrap_or("?");
            let number = |required: bool| -> Result<Option<f64>, CurveCsvError> {
                if cell.is_empty() {
                    return if required {
                        Err(err(line_no, format!("{name} is empty (it is required)")))
                    } else {
                        Ok(None)
                    };
                }
                match cell.parse::<f64>() {
                    Ok(v) if v.is_finite() => Ok(Some(v)),
                    _ => Err(err(
                        line_no,
                        format!("{name} = {cell:?} is not a finite number"),
                    )),
                }
            };
            match c {
                Column::USMm => row.u_s_mm = number(true)?.unwrap_or(f64::NAN),
                Column::AMm => {
                    row.a_mm = number(true)?.unwrap_or(f64::NAN);
                    if row.a_mm < 0.0 {
                        return Err(err(
                            line_no,
                            format!("a_mm = {cell} is negative (a contact radius is >= 0)"),
                        ));
                    }
                }
                Column::LoadN => row.load_n = number(false)?,
                Column::PAirKpa => row.p_air_kpa = number(false)?,
                Column::TS => row.t_s = number(false)?,
                Column::HMm => row.h_mm = number(false)?,
                Column::StageMm => row.stage_mm = number(false)?,
                Column::VolumeMm3 => row.volume_mm3 = number(false)?,
                Column::Phase => {
                    row.phase = match cell {
                        "" => None,
                        "load" => Some(Phase::Load),
                        "unload" => Some(Phase::Unload),
                        other => {
                            return Err(err(
                                line_no,
                                format!("phase = {other:?} is not \"load\" or \"unload\""),
                            ));
                        }
                    }
                }
                Column::Test => {
                    row.test = if cell.is_empty() {
                        None
                    } else {
                        Some(cell.parse::<u32>().map_err(|_| {
                            err(
                                line_no,
                                format!("test = {cell:?} is not a non-negative integer"),
                            )
                        })?)
                    }
                }
            }
        }
        out.rows.push(row);
    }
    if columns.is_none() {
        return Err(CurveCsvError::Invalid {
            file: file.to_string(),
            reason: "no header row (expected e.g. \"u_s_mm,a_mm\")".into(),
        });
    }
    Ok(out)
}

/// Render a curve file. Optional columns are written when any row has a value; metadata
/// keys must be non-empty words without ':' and values single lines.
pub fn format_curve_csv(curve: &CurveCsv) -> Result<String, CurveCsvError> {
    let bad = |reason: String| CurveCsvError::Invalid {
        file: "(curve being written)".into(),
        reason,
    };
    let mut s = String::new();
    for (k, v) in &curve.metadata {
        if k.is_empty() || k.contains([':', '\n', '\r']) || k.contains(char::is_whitespace) {
            return Err(bad(format!(
                "metadata key {k:?} must be a word without ':'"
            )));
        }
        if v.contains(['\n', '\r']) {
            return Err(bad(format!(
                "metadata value of {k:?} must be a single line"
            )));
        }
        let _ = writeln!(s, "# {k}: {v}");
    }
    let r = &curve.rows;
    let present = |c: Column| -> bool {
        match c {
            Column::USMm | Column::AMm => true,
            Column::LoadN => r.iter().any(|x| x.load_n.is_some()),
            Column::PAirKpa => r.iter().any(|x| x.p_air_kpa.is_some()),
            Column::TS => r.iter().any(|x| x.t_s.is_some()),
            Column::Phase => r.iter().any(|x| x.phase.is_some()),
            Column::Test => r.iter().any(|x| x.test.is_some()),
            Column::HMm => r.iter().any(|x| x.h_mm.is_some()),
            Column::StageMm => r.iter().any(|x| x.stage_mm.is_some()),
            Column::VolumeMm3 => r.iter().any(|x| x.volume_mm3.is_some()),
        }
    };
    let cols: Vec<(Column, &str)> = COLUMNS.into_iter().filter(|(c, _)| present(*c)).collect();
    s += &cols.iter().map(|(_, n)| *n).collect::<Vec<_>>().join(",");
    s.push('\n');
    // `{}` on f64 prints the shortest text that parses back to the same value.
    let num = |v: Option<f64>| v.map(|x| format!("{x}")).unwrap_or_default();
    for row in r {
        if !row.u_s_mm.is_finite() || !row.a_mm.is_finite() {
            return Err(bad(format!(
                "u_s_mm and a_mm must be finite (row with u_s_mm = {}, a_mm = {})",
                row.u_s_mm, row.a_mm
            )));
        }
        let cells: Vec<String> = cols
            .iter()
            .map(|(c, _)| match c {
                Column::USMm => num(Some(row.u_s_mm)),
                Column::AMm => num(Some(row.a_mm)),
                Column::LoadN => num(row.load_n),
                Column::PAirKpa => num(row.p_air_kpa),
                Column::TS => num(row.t_s),
                Column::Phase => row
                    .phase
                    .map(|p| p.as_str().to_string())
                    .unwrap_or_default(),
                Column::Test => row.test.map(|t| t.to_string()).unwrap_or_default(),
                Column::HMm => num(row.h_mm),
                Column::StageMm => num(row.stage_mm),
                Column::VolumeMm3 => num(row.volume_mm3),
            })
            .collect();
        s += &cells.join(",");
        s.push('\n');
    }
    Ok(s)
}

/// Write a curve file.
pub fn write_curve_csv(path: &Path, curve: &CurveCsv) -> Result<(), CurveCsvError> {
    let text = format_curve_csv(curve).map_err(|e| match e {
        CurveCsvError::Invalid { reason, .. } => CurveCsvError::Invalid {
            file: path.display().to_string(),
            reason,
        },
        other => other,
    })?;
    std::fs::write(path, text).map_err(|source| CurveCsvError::Io {
        file: path.display().to_string(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_documented_example_with_optional_columns_and_comments() {
        let text = "# source: bench 3\n# p_air_kpa: 6\n# a free comment without a key\n\
                    u_s_mm,a_mm,load_n,p_air_kpa,t_s,phase,test\n\
                    0,0,0,6,0.0,load,1\n\
                    \n\
                    # mid-file comment\n\
                    0.05, 1.2 ,0.01,6,0.5,load,1\n\
                    0.04,1.1,,6,1.0,unload,1\n";
        let c = parse_curve_csv(text, "x.csv").unwrap();
        assert_eq!(c.meta("p_air_kpa"), Some("6"));
        assert_eq!(c.meta("source"), Some("bench 3"));
        assert_eq!(c.metadata.len(), 2);
        assert_eq!(c.rows.len(), 3);
        assert_eq!(c.rows[1].a_mm, 1.2);
        assert_eq!(c.rows[2].load_n, None);
        assert_eq!(c.rows[2].phase, Some(Phase::Unload));
        assert_eq!(c.rows[0].test, Some(1));
        assert_eq!(c.rows[0].h_mm, None);
    }

    #[test]
    fn minimal_file_has_only_the_required_columns() {
        let c = parse_curve_csv("a_mm,u_s_mm\n1.5,0.25\n", "m.csv").unwrap();
        assert_eq!((c.rows[0].u_s_mm, c.rows[0].a_mm), (0.25, 1.5));
    }

    #[test]
    fn round_trip_is_exact() {
        let c = CurveCsv {
            metadata: vec![
                ("modulus_kpa".into(), "146.8".into()),
                ("steps".into(), "3".into()),
            ],
            rows: (0..4)
                .map(|k| CurveRow {
                    u_s_mm: 0.1 * k as f64 / 3.0,
                    a_mm: (k as f64).sqrt() * 1.234_567_890_123,
                    load_n: Some(1e-7 * k as f64),
                    p_air_kpa: Some(6.0),
                    phase: Some(Phase::Load),
                    h_mm: Some(0.05 * k as f64),
                    volume_mm3: Some(98.76543210987 - k as f64),
                    ..Default::default()
                })
                .collect(),
        };
        let text = format_curve_csv(&c).unwrap();
        assert!(
            text.contains("\nu_s_mm,a_mm,load_n,p_air_kpa,phase,h_mm,volume_mm3\n"),
            "{text}"
        );
        assert_eq!(parse_curve_csv(&text, "rt.csv").unwrap(), c);
    }

    #[test]
    fn errors_name_file_line_and_field() {
        let cases = [
            (
                "u_s_mm,a_mm\n0,abc\n",
                "bad.csv:2: a_mm = \"abc\" is not a finite number",
            ),
            (
                "u_s_mm,a_mm\n0,1,2\n",
                "bad.csv:2: 3 fields, the header row has 2",
            ),
            (
                "# c\nu_s_mm,load_n\n",
                "bad.csv:2: the header row lacks the required column \"a_mm\"",
            ),
            ("u_s_mm,a_mm,a_m\n", "bad.csv:1: unknown column \"a_m\""),
            (
                "u_s_mm,a_mm,a_mm\n",
                "bad.csv:1: column \"a_mm\" appears twice",
            ),
            (
                "u_s_mm,a_mm,phase\n0,0,push\n",
                "bad.csv:2: phase = \"push\" is not",
            ),
            (
                "u_s_mm,a_mm,test\n0,0,-1\n",
                "bad.csv:2: test = \"-1\" is not a non-negative",
            ),
            (
                "u_s_mm,a_mm\n,1\n",
                "bad.csv:2: u_s_mm is empty (it is required)",
            ),
            (
                "u_s_mm,a_mm\nNaN,1\n",
                "bad.csv:2: u_s_mm = \"NaN\" is not a finite number",
            ),
            (
                "# k: 1\n# k: 2\nu_s_mm,a_mm\n",
                "bad.csv:2: metadata key \"k\" given twice",
            ),
            ("# only comments\n", "bad.csv: no header row"),
        ];
        for (text, want) in cases {
            let got = parse_curve_csv(text, "bad.csv").unwrap_err().to_string();
            assert!(
                got.starts_with(want),
                "{text:?}: got {got:?}, want {want:?}"
            );
        }
        let missing = read_curve_csv(Path::new("/nonexistent/c.csv"))
            .unwrap_err()
            .to_string();
        assert!(missing.starts_with("/nonexistent/c.csv: "), "{missing}");
    }

    #[test]
    fn writer_rejects_metadata_that_would_not_read_back() {
        let mut c = CurveCsv::default();
        c.metadata.push(("a key".into(), "v".into()));
        assert!(format_curve_csv(&c).is_err());
        c.metadata[0] = ("k".into(), "two\nlines".into());
        assert!(format_curve_csv(&c).is_err());
    }
}
