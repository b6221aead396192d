//! The EXR writer, for pictures meant to be measured: shaded colour together with the raw depth
//! and normal of every pixel, all as 32-bit floats.

use std::io;
use std::path::Path;

use ::exr::prelude::{
    AnyChannel, AnyChannels, Encoding, FlatSamples, Layer, LayerAttributes, SmallVec, WritableImage,
};

use super::image::{check_per_pixel, check_writable, Image};
use crate::geom::Hit;
use crate::io::write_atomically;

/// Writes `image` and the `hits` it was shaded from as a single-layer EXR with seven `f32`
/// channels, pixel for pixel:
///
/// - `R`, `G`, `B`: the image's linear colour, unclamped;
/// - `Z`: the hit's `t`, in units of the ray direction's length (the distance for unit
///   directions), and **+inf on a miss**, so that misses are unambiguous rather than a large
///   finite depth;
/// - `N.X`, `N.Y`, `N.Z`: the world-space unit geometric normal as wound (not flipped towards the
///   ray), and 0 on a miss.
///
/// `hits` must have one entry per pixel. Compressed losslessly; written atomically.
pub fn write_exr(path: &Path, image: &Image, hits: &[Hit]) -> crate::Result<()> {
    check_writable(image)?;
    check_per_pixel("hits", hits.len(), image.width, image.height)?;
    let colour = |c: usize| image.pixels.iter().map(|p| p[c]).collect();
    let depth = hits
        .iter()
        .map(|h| if h.is_hit() { h.t } else { f32::INFINITY })
        .collect();
    let normal = |c: usize| {
        hits.iter()
            .map(|h| if h.is_hit() { h.normal[c] } else { 0.0 })
            .collect()
    };
    let channel = |name: &str, samples: Vec<f32>| AnyChannel::new(name, FlatSamples::F32(samples));
    let channels = AnyChannels::sort(SmallVec::from_vec(vec![
        channel("R", colour(0)),
        channel("G", colour(1)),
        channel("B", colour(2)),
        channel("Z", depth),
        channel("N.X", normal(0)),
        channel("N.Y", normal(1)),
        channel("N.Z", normal(2)),
    ]));
    let size = (image.width as usize, image.height as usize);
    let layer = Layer::new(
        size,
        LayerAttributes::default(),
        Encoding::FAST_LOSSLESS,
        channels,
    );
    let exr_image = ::exr::prelude::Image::from_layer(layer);
    write_atomically(path, |w| {
        exr_image.write().to_buffered(w).map_err(io::Error::other)
    })
}
