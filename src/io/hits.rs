//! The hit file: one [`Hit`] per 32-byte record, `t nx ny nz` as little-endian `f32`, then `id`,
//! `instance` and two reserved words as little-endian `u32`.

use std::path::Path;

use super::records::{read_records, write_records, Record, Words};
use crate::geom::Hit;

impl Record for Hit {
    const NAME: &'static str = "hit";

    fn from_words(w: Words) -> Self {
        let f = f32::from_bits;
        Hit {
            t: f(w[0]),
            normal: [f(w[1]), f(w[2]), f(w[3])],
            id: w[4],
            instance: w[5],
            reserved: [w[6], w[7]],
        }
    }

    fn to_words(&self) -> Words {
        let [nx, ny, nz] = self.normal.map(f32::to_bits);
        let [r1, r2] = self.reserved;
        [self.t.to_bits(), nx, ny, nz, self.id, self.instance, r1, r2]
    }
}

/// Reads a hit file. Fails if the file cannot be read, is empty, or is not a whole number of
/// 32-byte records. The values are not checked.
pub fn read_hits(path: &Path) -> crate::Result<Vec<Hit>> {
    read_records(path)
}

/// Writes a hit file, replacing `path` only once the whole file is written.
pub fn write_hits(path: &Path, hits: &[Hit]) -> crate::Result<()> {
    write_records(path, hits)
}
