//! Turning traced hits into pictures: preview shading, normal and heat-map visualisations, and
//! the PNG and EXR writers. Images are linear RGB in memory; only [`write_png`] applies the sRGB
//! transfer function, so that the EXR keeps the values the shading computed.
//!
//! Both writers go through [`crate::io::write_atomically`]: a failed write leaves no file behind.

#[cfg(feature = "exr")]
mod exr;
mod heatmap;
mod image;
mod png;
mod shade;

#[cfg(feature = "exr")]
pub use self::exr::write_exr;
pub use self::heatmap::{heatmap, with_colour_bar};
pub use self::image::{side_by_side, Image};
pub use self::png::write_png;
pub use self::shade::{shade, shade_normals, shade_with_albedo};
