//! The one light a scene file may name, for shading and shadow rays.

use glam::Vec3;

/// A single light. Scenes carry at most one: the renders exist to show hits and their
/// normals, and one light is enough to make shape readable and to cast testable shadows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Light {
    /// Light from infinitely far away; `direction` is the unit direction in which it travels.
    Directional {
        /// World-space direction of travel, from the light towards the scene (unit length from
        /// scene files; users normalize anyway).
        direction: Vec3,
    },
    /// Light emitted from `position` in all directions.
    Point {
        /// World-space position of the light.
        position: Vec3,
    },
}
