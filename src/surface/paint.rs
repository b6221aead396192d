//! Painting with brushes, the application Novák & Dachsbacher (2012) show on the RBVH's atlas:
//! the CPU reference of the rule that `glsl/paint.comp` runs on the device
//! ([`crate::gpu::Painter`]).
//!
//! **Rule.** A surface texel (not a hole) of any height-field leaf is painted by a brush when its
//! world-space sample point ([`crate::rbvh::layout::SampleGrid::point`]) lies within the brush's
//! radius of the brush centre, `|p − c|² ≤ r²`: the brush's colour is composited over the
//! texel's ([`crate::rgba::over`], integer arithmetic), brushes in list order, so that the device
//! and the CPU agree bit for bit; an opaque brush replaces the colour. Deciding in world space rather than per tile is what makes strokes
//! cross leaf borders without seams: neighbouring tiles that overlap (the builder's dilation and
//! window overlap) paint their shared surface alike. Triangle leaves carry no texels and stay
//! unpainted.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

use crate::geom::Aabb;
use crate::rbvh::{GpuHeightfield, Rbvh};
use crate::rgba;

/// One brush dab. 32 bytes, the `PaintBrush` of `glsl/paint.comp`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Brush {
    /// World-space centre (a stroke ray's hit point).
    pub centre: [f32; 3],
    /// World-space radius.
    pub radius: f32,
    /// Packed RGBA8 ([`crate::rgba`]).
    pub colour: u32,
    /// GLSL `pad0`..`pad2`: padding to 32 bytes; always 0.
    pub pad: [u32; 3],
}
const _: () = assert!(std::mem::size_of::<Brush>() == 32);

impl Brush {
    /// A dab at world-space `centre` of world-space `radius` in packed RGBA8 `colour`, padding
    /// zeroed.
    pub fn new(centre: Vec3, radius: f32, colour: u32) -> Brush {
        Brush {
            centre: centre.to_array(),
            radius,
            colour,
            pad: [0; 3],
        }
    }

    /// Whether world point `p` is painted by this brush; the arithmetic order of
    /// `glsl/paint.comp`.
    pub fn covers(&self, p: Vec3) -> bool {
        let d = p - Vec3::from(self.centre);
        let d2 = d.x * d.x + d.y * d.y + d.z * d.z;
        d2 <= self.radius * self.radius
    }

    /// Whether the brush's ball reaches the box `b` (closed).
    fn reaches(&self, b: &Aabb) -> bool {
        let c = Vec3::from(self.centre);
        let nearest = c.clamp(b.min, b.max);
        (c - nearest).length_squared() <= self.radius * self.radius
    }
}

/// Indices of the leaves whose world box ([`GpuHeightfield::world_bounds`], which holds every
/// sample point) some brush reaches: the only leaves a painting pass needs to visit.
pub fn candidate_leaves(leaves: &[GpuHeightfield], brushes: &[Brush]) -> Vec<u32> {
    leaves
        .iter()
        .enumerate()
        .filter(|(_, leaf)| {
            let b = leaf.world_bounds();
            brushes.iter().any(|brush| brush.reaches(&b))
        })
        .map(|(k, _)| k as u32)
        .collect()
}

impl Rbvh {
    /// Paints `brushes` on the CPU by the rule of the module docs, over every leaf (no culling,
    /// so that it also checks the device's culling); creates the colour channel if there is none
    /// ([`Rbvh::colour_channel`]). Returns the number of texels painted.
    pub fn paint_cpu(&mut self, brushes: &[Brush]) -> u64 {
        let pitch = u64::from(self.atlas.pitch);
        let leaves = self.heightfields.clone();
        let texels = self.atlas.texels.clone();
        let colours = self.colour_channel();
        let mut painted = 0;
        for leaf in &leaves {
            let grid = leaf.grid();
            for j in 0..leaf.res_v {
                for i in 0..leaf.res_u {
                    let index = u64::from(leaf.atlas_base) + u64::from(j) * pitch + u64::from(i);
                    let Some(texel) = texels.get(index as usize) else {
                        continue;
                    };
                    if texel.is_hole() {
                        continue;
                    }
                    let p = grid.point(i, j, texel.height_code());
                    // A channel shorter than the atlas (set by hand) loses the paint past its end
                    // rather than panicking; `Painter::new` refuses one outright.
                    let Some(c) = colours.get_mut(index as usize) else {
                        continue;
                    };
                    let mut covered = false;
                    for brush in brushes.iter().filter(|b| b.covers(p)) {
                        *c = rgba::over(brush.colour, *c);
                        covered = true;
                    }
                    painted += u64::from(covered);
                }
            }
        }
        painted
    }
}
