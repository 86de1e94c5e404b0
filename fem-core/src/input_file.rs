//! Reading input files under a size limit. Every reader of a user-supplied file (tables,
//! scenarios, images, firmware, curves) goes through [`read_limited`], so a wrong path (a
//! disk image, `/dev/zero`, a multi-gigabyte log) is refused with a clear message instead of
//! exhausting memory.

use std::io::Read;
use std::path::Path;

/// Reads at most `max_bytes` of `path`; a longer file is an error of kind `InvalidData`
/// whose message names the limit and `what` the file should have been. The size is checked
/// on the metadata first and again while reading (special files report size 0).
pub fn read_limited(path: &Path, max_bytes: u64, what: &str) -> std::io::Result<Vec<u8>> {
    let too_large = |size: String| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("{size} is too large for {what} (the limit is {max_bytes} bytes)"),
        )
    };
    let file = std::fs::File::open(path)?;
    let declared = file.metadata()?.len();
    if declared > max_bytes {
        return Err(too_large(format!("{declared} bytes")));
    }
    let mut bytes = Vec::with_capacity(usize::try_from(declared).unwrap_or(0));
    file.take(max_bytes.saturating_add(1))
        .read_to_end(&mut bytes)?;
    if bytes.len() as u64 > max_bytes {
        return Err(too_large("more than the limit".to_string()));
    }
    Ok(bytes)
}

/// [`read_limited`] for text files: the bytes must be UTF-8.
pub fn read_limited_text(path: &Path, max_bytes: u64, what: &str) -> std::io::Result<String> {
    String::from_utf8(read_limited(path, max_bytes, what)?).map_err(|e| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("not UTF-8 text at byte {}", e.utf8_error().valid_up_to()),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_over_the_limit_is_refused_and_names_the_limit() {
        let dir = std::env::temp_dir().join(format!("fem-input-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("big.txt");
        std::fs::write(&path, vec![b'x'; 100]).unwrap();
        assert_eq!(read_limited(&path, 100, "a table").unwrap().len(), 100);
        let err = read_limited(&path, 99, "a table").unwrap_err();
        assert_eq!(err.kind(), std::io::ErrorKind::InvalidData);
        assert!(err.to_string().contains("the limit is 99 bytes"), "{err}");
        std::fs::write(&path, [0xff, 0xfe]).unwrap();
        assert!(read_limited_text(&path, 10, "a scenario").is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_special_file_without_a_size_is_cut_at_the_limit() {
        // /dev/zero reports size 0 and never ends: only the limit on reading stops it.
        let zero = Path::new("/dev/zero");
        if zero.exists() {
            let err = read_limited(zero, 1 << 16, "an image").unwrap_err();
            assert_eq!(err.kind(), std::io::ErrorKind::InvalidData);
        }
    }
}
