//! Experiment records on disk: one directory per experiment with `meta.json`,
//! `samples.csv` and `frames.csv` (streams appended and flushed as they arrive, so a crash
//! or kill loses at most what arrived since the last flush, well under a second),
//! `curve.csv` (the measured-curve format), `fit.json` and the plots.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// An I/O problem with a record, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: {reason}")]
    Encode { path: PathBuf, reason: String },
}

/// A CSV stream appended as data arrives and flushed at least every `FLUSH_MS`.
#[derive(Debug)]
pub struct StreamCsv {
    path: PathBuf,
    out: BufWriter<File>,
    last_flush: Instant,
    pub rows: u64,
}

const FLUSH_MS: u128 = 250;

impl StreamCsv {
    fn create(path: PathBuf, header: &str) -> Result<Self, RecordError> {
        let file = File::create(&path).map_err(|source| RecordError::Io {
            path: path.clone(),
            source,
        })?;
        let mut s = Self {
            path,
            out: BufWriter::new(file),
            last_flush: Instant::now(),
            rows: 0,
        };
        s.write_line(header)?;
        s.flush()?;
        Ok(s)
    }

    fn write_line(&mut self, line: &str) -> Result<(), RecordError> {
        writeln!(self.out, "{line}").map_err(|source| RecordError::Io {
            path: self.path.clone(),
            source,
        })
    }

    /// Appends one row (already formatted, no newline).
    pub fn append(&mut self, row: &str) -> Result<(), RecordError> {
        self.write_line(row)?;
        self.rows += 1;
        if self.last_flush.elapsed().as_millis() >= FLUSH_MS {
            self.flush()?;
        }
        Ok(())
    }

    /// Writes buffered rows to the file and asks the OS to keep them.
    pub fn flush(&mut self) -> Result<(), RecordError> {
        self.out.flush().map_err(|source| RecordError::Io {
            path: self.path.clone(),
            source,
        })?;
        self.last_flush = Instant::now();
        Ok(())
    }
}

impl Drop for StreamCsv {
    fn drop(&mut self) {
        let _ = self.out.flush();
    }
}

/// One experiment's directory.
#[derive(Debug)]
pub struct RecordDir {
    pub dir: PathBuf,
}

impl RecordDir {
    /// Creates `dir` (and parents); it must not already hold a record.
    pub fn create(dir: &Path) -> Result<Self, RecordError> {
        std::fs::create_dir_all(dir).map_err(|source| RecordError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
        if dir.join("meta.json").exists() {
            return Err(RecordError::Encode {
                path: dir.to_path_buf(),
                reason: "already holds a record (meta.json exists); choose another --out".into(),
            });
        }
        Ok(Self {
            dir: dir.to_path_buf(),
        })
    }

    pub fn path(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }

    /// Opens an appended CSV stream with `header`.
    pub fn stream(&self, name: &str, header: &str) -> Result<StreamCsv, RecordError> {
        StreamCsv::create(self.path(name), header)
    }

    /// Writes `value` as pretty JSON (to a temporary name, then renamed, so a crash never
    /// leaves half a file).
    pub fn write_json<T: serde::Serialize>(
        &self,
        name: &str,
        value: &T,
    ) -> Result<PathBuf, RecordError> {
        let path = self.path(name);
        let text = serde_json::to_string_pretty(value).map_err(|e| RecordError::Encode {
            path: path.clone(),
            reason: e.to_string(),
        })?;
        let tmp = self.path(&format!(".{name}.tmp"));
        std::fs::write(&tmp, text).map_err(|source| RecordError::Io {
            path: tmp.clone(),
            source,
        })?;
        std::fs::rename(&tmp, &path).map_err(|source| RecordError::Io {
            path: path.clone(),
            source,
        })?;
        Ok(path)
    }
}

/// Seconds since the Unix epoch (records are dated in UTC).
pub fn unix_now_s() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0)
}

/// `YYYY-MM-DDTHH-MM-SSZ` for a Unix time (proleptic Gregorian, UTC), for directory names.
pub fn utc_stamp(unix_s: u64) -> String {
    let days = (unix_s / 86_400) as i64;
    let secs = unix_s % 86_400;
    // civil-from-days (H. Hinnant's algorithm)
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let y = yoe + era * 400;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = if m <= 2 { y + 1 } else { y };
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}-{:02}-{:02}Z",
        secs / 3600,
        (secs / 60) % 60,
        secs % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_stamp_matches_known_dates() {
        assert_eq!(utc_stamp(0), "1970-01-01T00-00-00Z");
        // 2000-02-29 12:34:56 UTC = 951827696 (date -u -d @951827696)
        assert_eq!(utc_stamp(951_827_696), "2000-02-29T12-34-56Z");
    }

    #[test]
    fn streams_are_on_disk_after_flush_and_json_is_atomic() {
        let dir = std::env::temp_dir().join(format!("tactile-rec-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let rec = RecordDir::create(&dir).unwrap();
        let mut s = rec.stream("samples.csv", "a,b").unwrap();
        s.append("1,2").unwrap();
        s.flush().unwrap();
        let text = std::fs::read_to_string(dir.join("samples.csv")).unwrap();
        assert_eq!(text, "a,b\n1,2\n");
        rec.write_json("meta.json", &serde_json::json!({"x": 1}))
            .unwrap();
        assert!(
            RecordDir::create(&dir).is_err(),
            "a second record in the same directory"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
