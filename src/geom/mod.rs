//! Geometry shared by every stage: boxes, rays and hits, and the two robust intersection tests
//! (watertight ray/triangle, conservative ray/box) that the CPU reference tracers use. The GLSL
//! twins of these tests live in `glsl/intersect.glsl` and must stay operation-for-operation equal.
//! `grid` steps a ray through a 2D grid of cells, for the two marches (`glsl/grid.glsl`); `clip`
//! (polygon clipping) and `sat` (separating-axis overlap tests) cut and test shapes in 2D, for the
//! RBVH's rasterizer; `scale` scales by powers of two, exactly, for the RBVH's builder.

mod aabb;
pub(crate) mod clip;
pub(crate) mod grid;
mod ray;
pub(crate) mod sat;
pub mod scale;
mod triangle;

pub use aabb::{Aabb, ROBUST_FAR_SCALE};
pub use ray::{safe_inverse, Hit, Ray};
pub use triangle::{intersect_triangle, unit, unit_normal, RayShear};
