//! The framing shared by the ray and hit files: headerless runs of 32-byte records, each eight
//! little-endian 4-byte words.

use std::io::Write;
use std::path::Path;

use super::write_atomically;
use crate::Error;

/// Bytes in one record of either file.
pub(super) const RECORD_BYTES: usize = 32;

/// A record's eight words, in file order, as raw bits. Floats travel as their bit patterns so
/// that NaN payloads, signed zeros and infinities survive a round trip exactly.
pub(super) type Words = [u32; 8];

/// A type stored as one record. Encoding goes through explicit little-endian words rather than
/// a cast of the in-memory struct, so the files mean the same on any host.
pub(super) trait Record: Sized {
    /// What one record is called in messages ("ray", "hit").
    const NAME: &'static str;
    fn from_words(words: Words) -> Self;
    fn to_words(&self) -> Words;
}

/// Reads a whole file of `R` records. Only the framing is checked; see the module docs.
pub(super) fn read_records<R: Record>(path: &Path) -> crate::Result<Vec<R>> {
    let bytes = super::input::read(path)?;
    if bytes.is_empty() {
        return Err(Error::parse(
            path,
            None,
            format!("the file is empty; it contains no {}s", R::NAME),
        ));
    }
    if bytes.len() % RECORD_BYTES != 0 {
        return Err(Error::parse(
            path,
            None,
            format!(
                "the file is {} bytes long, not a whole number of {RECORD_BYTES}-byte {} records; \
                 it looks truncated",
                bytes.len(),
                R::NAME,
            ),
        ));
    }
    Ok(bytes
        .chunks_exact(RECORD_BYTES)
        .map(|record| {
            let mut words = [0u32; 8];
            for (word, b) in words.iter_mut().zip(record.chunks_exact(4)) {
                *word = u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
            }
            R::from_words(words)
        })
        .collect())
}

/// Writes `records` to `path`, atomically.
pub(super) fn write_records<R: Record>(path: &Path, records: &[R]) -> crate::Result<()> {
    write_atomically(path, |w| {
        for record in records {
            let mut bytes = [0u8; RECORD_BYTES];
            for (b, word) in bytes.chunks_exact_mut(4).zip(record.to_words()) {
                b.copy_from_slice(&word.to_le_bytes());
            }
            w.write_all(&bytes)?;
        }
        Ok(())
    })
}
