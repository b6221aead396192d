//! The ray and hit files, and the one way every output file of the crate is written.
//!
//! Both file formats are headerless sequences of fixed 32-byte little-endian records, so that a
//! file is its own index (record `i` starts at byte `32 i`), can be produced by any tool that can
//! write floats, and is byte for byte what the GPU buffers hold:
//!
//! - a **ray** is 8 × `f32`: `ox oy oz tmin dx dy dz tmax` ([`crate::geom::Ray`]);
//! - a **hit** is 8 × 4 bytes: `t` (`f32`, +inf on a miss), `nx ny nz` (`f32`, the unit geometric
//!   normal as wound, zero on a miss), `id` (`u32`, `0xFFFFFFFF` on a miss), and three reserved
//!   `u32` words ([`crate::geom::Hit`]).
//!
//! The readers check only the framing: a missing, empty, or truncated file (a length that is not a
//! multiple of 32) is an error. The *values* are not judged: a ray with a NaN or infinite origin or
//! direction, a zero direction, a negative `tmin`, or `tmin > tmax` is read as is, and the tracers
//! answer it with a miss (see [`crate::geom::Ray::is_valid`]). Rejecting such rays here would make
//! one bad ray cost a whole batch, and would shift the ray-to-hit correspondence by index.
//!
//! Every writer goes through [`write_atomically`], so an interrupted or failed write never leaves
//! a file that looks complete; every reader of a named file through [`input`], which refuses
//! anything but a regular file before opening it.

mod atomic;
mod hits;
pub mod input;
mod rays;
mod records;

pub use atomic::{rename_target, write_atomically};

/// A FIFO made at `dir/name` by coreutils' `mkfifo` (std has no call for it), for the tests of
/// what readers and writers do with a pipe; a test fails, rather than passes unchecked, where it
/// cannot be made.
#[cfg(all(test, unix))]
fn fifo_in(dir: &std::path::Path, name: &str) -> std::path::PathBuf {
    let fifo = dir.join(name);
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    assert!(made.is_ok_and(|s| s.success()), "mkfifo {}", fifo.display());
    fifo
}
pub use hits::{read_hits, write_hits};
pub use rays::{read_rays, write_rays};
