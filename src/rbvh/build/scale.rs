//! Scenes too large or too small for float32's squares (`geom::scale`): built scaled by a power
//! of two into the range where the builder is exact, then scaled back, so that such a scene gets
//! the RBVH of the same scene at an ordinary size, scaled, bit for bit (tests/stability, scale
//! and offset).

use std::time::Instant;

use super::{Rbvh, RbvhParams, RbvhSource};
use crate::geom::scale::pow2;
use crate::progress::Progress;
use crate::rbvh::ExactTriangles;
use crate::Result;

/// Builds `source`'s scene scaled by `2^k` at the texel `texel · 2^k`, and scales the RBVH back.
/// The scaled scene is a copy, prepared for this level alone. A scene that scaling would take
/// beyond float32 (a vertex, the camera or a light far from the rest, beside a tiny part) is
/// built as it is.
pub(super) fn build_scaled(
    source: &RbvhSource,
    params: &RbvhParams,
    texel: f32,
    k: i32,
    progress: &dyn Progress,
) -> Result<Rbvh> {
    let start = Instant::now();
    let scene = source.scene.scaled_pow2(k);
    let finite = |p: glam::Vec3| p.is_finite();
    let fits = scene.validate().is_ok()
        && scene
            .camera
            .is_none_or(|c| finite(c.eye) && finite(c.target))
        && match scene.light {
            Some(crate::scene::Light::Point { position, .. }) => finite(position),
            _ => true,
        }
        && scene.points.as_ref().is_none_or(|points| {
            points.positions.iter().all(|&p| finite(p))
                && points.spacing.iter().all(|&d| d.is_normal())
        });
    if !fits {
        return Rbvh::build_native(source, params, texel, progress);
    }
    let scaled = RbvhSource::new(&scene)?;
    let mut rbvh = Rbvh::build_native(&scaled, params, texel * pow2(k), progress)?.scaled_pow2(-k);
    rbvh.stats.build_ms = source.new_ms + start.elapsed().as_secs_f64() * 1e3;
    Ok(rbvh)
}

impl Rbvh {
    /// This RBVH in a world `2^k` times larger, exactly: every world-space quantity of its nodes,
    /// height-field records, exact triangles, bounds and texel scaled by `2^k` (and the records'
    /// tangents over the texel by `2^-k`), its atlas and counts kept.
    fn scaled_pow2(self, k: i32) -> Rbvh {
        let s = pow2(k);
        Rbvh {
            nodes: self.nodes.into_iter().map(|n| n.scaled_pow2(k)).collect(),
            triangles: ExactTriangles::new(
                self.triangles
                    .gathered()
                    .iter()
                    .map(|t| t.scaled_pow2(k))
                    .collect(),
            ),
            heightfields: self
                .heightfields
                .into_iter()
                .map(|h| h.scaled_pow2(k))
                .collect(),
            bounds: crate::geom::Aabb {
                min: self.bounds.min * s,
                max: self.bounds.max * s,
            },
            texel_size: self.texel_size * s,
            ..self
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    /// A scene scaled by a power of two far outside the range the builder is exact in builds the
    /// RBVH of the same scene at its own size, scaled, bit for bit (before, the sphere a
    /// trillionth of a unit across was traced all exactly, and a trillion units across refused
    /// as needing infinitely many texels).
    #[test]
    fn vast_and_tiny_scenes_build_the_same_rbvh_scaled() {
        let params = RbvhParams::quality(0).unwrap();
        for name in ["sphere", "default"] {
            let unit = Scene::builtin(name).unwrap();
            let base = Rbvh::build(&unit, &params).unwrap();
            assert!(base.stats.heightfield_leaves > 0, "{name}");
            for k in [-40, 40] {
                let r = Rbvh::build(&unit.scaled_pow2(k), &params).unwrap();
                let expected = base.clone().scaled_pow2(k);
                let what = format!("{name} at 2^{k}");
                assert_eq!(r.nodes, expected.nodes, "{what}");
                assert_eq!(r.heightfields, expected.heightfields, "{what}");
                assert_eq!(r.atlas, expected.atlas, "{what}");
                assert_eq!(
                    r.triangles.gathered(),
                    expected.triangles.gathered(),
                    "{what}"
                );
                assert_eq!(r.bounds, expected.bounds, "{what}");
                assert_eq!(r.texel_size, expected.texel_size, "{what}");
            }
        }
    }
}
