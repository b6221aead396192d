//! Data on surfaces, and painting (Novák & Dachsbacher 2012 name "real-time painting on surfaces"
//! among the RBVH's applications: its atlas is a surface parameterization for free).
//!
//! * `query`: from a hit to the texel it landed on, its colour, and per-pixel albedo for renders;
//! * `paint`: brushes, and the CPU reference of the painting rule that `glsl/paint.comp` runs;
//! * `strokes`: the text file of brush strokes that `rbvh paint` reads.
//!
//! The colour channel is baked by the RBVH's build (`crate::rbvh`'s `bake`) and packed as
//! [`crate::rgba`] says.

mod paint;
mod query;
pub mod strokes;

pub use paint::{candidate_leaves, Brush};
pub use query::{blank_colours, hit_albedo, SurfaceLocation};
