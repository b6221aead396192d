//! Data on surfaces, and painting (Novák & Dachsbacher 2012 name "real-time painting on surfaces"
//! among the RBVH's applications: its atlas is a surface parameterization for free).
//!
//! * `bake`: the scene's base colour into a per-texel colour channel at build time;
//! * [`rgba`]: how a texel's colour is packed;
//! * `query`: from a hit to the texel it landed on, its colour, and per-pixel albedo for renders;
//! * `paint`: brushes, and the CPU reference of the painting rule that `glsl/paint.comp` runs;
//! * `strokes`: the text file of brush strokes that `rbvh paint` reads.

mod bake;
mod paint;
mod query;
pub mod rgba;
pub mod strokes;

pub(crate) use bake::bake;
pub use paint::{candidate_leaves, Brush};
pub use query::{blank_colours, hit_albedo, SurfaceLocation};
