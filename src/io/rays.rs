//! The ray file: one [`Ray`] per 32-byte record, `ox oy oz tmin dx dy dz tmax` as little-endian
//! `f32`.

use std::path::Path;

use super::records::{read_records, write_records, Record, Words};
use crate::geom::Ray;

impl Record for Ray {
    const NAME: &'static str = "ray";

    fn from_words(w: Words) -> Self {
        let f = f32::from_bits;
        Ray {
            origin: [f(w[0]), f(w[1]), f(w[2])],
            tmin: f(w[3]),
            dir: [f(w[4]), f(w[5]), f(w[6])],
            tmax: f(w[7]),
        }
    }

    fn to_words(&self) -> Words {
        let [ox, oy, oz] = self.origin;
        let [dx, dy, dz] = self.dir;
        [ox, oy, oz, self.tmin, dx, dy, dz, self.tmax].map(f32::to_bits)
    }
}

/// Reads a ray file. Fails if the file cannot be read, is empty, or is not a whole number of
/// 32-byte records. Rays the tracers cannot answer (NaN, infinite, `tmin > tmax`, ...) are kept
/// as they are; the tracers report them as misses.
pub fn read_rays(path: &Path) -> crate::Result<Vec<Ray>> {
    read_records(path)
}

/// Writes a ray file, replacing `path` only once the whole file is written.
pub fn write_rays(path: &Path, rays: &[Ray]) -> crate::Result<()> {
    write_records(path, rays)
}
