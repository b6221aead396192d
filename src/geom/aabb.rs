//! Axis-aligned bounding boxes and the robust slab test.

use glam::Vec3;

/// An axis-aligned box. The empty box has `min = +inf`, `max = -inf`, so that growing it by any
/// point gives that point's box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Lower corner, per axis; `+inf` on every axis for the empty box.
    pub min: Vec3,
    /// Upper corner, per axis; `-inf` on every axis for the empty box.
    pub max: Vec3,
}

impl Default for Aabb {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl Aabb {
    /// The empty box, identity of [`grow`](Self::grow) and [`union`](Self::union).
    pub const EMPTY: Aabb = Aabb {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };

    /// The tightest box around `points`; [`EMPTY`](Self::EMPTY) when there are none.
    pub fn from_points(points: impl IntoIterator<Item = Vec3>) -> Self {
        points.into_iter().fold(Self::EMPTY, |b, p| b.grow(p))
    }

    /// Whether `p` lies in this box, its faces included.
    pub fn contains(&self, p: Vec3) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }

    /// This box extended to contain `p`.
    #[must_use]
    pub fn grow(self, p: Vec3) -> Self {
        Aabb {
            min: self.min.min(p),
            max: self.max.max(p),
        }
    }

    /// The tightest box containing both boxes.
    #[must_use]
    pub fn union(self, o: Aabb) -> Self {
        Aabb {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }

    /// True when `min > max` on some axis (no point inside); a degenerate flat box is not empty.
    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x || self.min.y > self.max.y || self.min.z > self.max.z
    }

    /// Edge lengths `max − min` per axis; zero for the empty box.
    pub fn extent(&self) -> Vec3 {
        if self.is_empty() {
            Vec3::ZERO
        } else {
            self.max - self.min
        }
    }

    /// Midpoint of `min` and `max`; meaningless (NaN) for the empty box.
    pub fn center(&self) -> Vec3 {
        0.5 * (self.min + self.max)
    }

    /// Length of the main diagonal, in scene units; 0 for the empty box. The scale that relative
    /// tolerances (hit distances, texel sizes) are measured against. Finite for every box of
    /// finite corners: where the f32 length overflows (an extent beyond about 1.8e19) it is taken
    /// in f64 and held to `f32::MAX`, so that a vast scene still gets a finite texel; elsewhere
    /// it is the f32 length, bit for bit as before.
    pub fn diagonal(&self) -> f32 {
        let length = self.extent().length();
        if length.is_finite() || self.is_empty() || !(self.min.is_finite() && self.max.is_finite())
        {
            length
        } else {
            ((self.max.as_dvec3() - self.min.as_dvec3()).length()).min(f64::from(f32::MAX)) as f32
        }
    }

    /// Surface area; 0 for the empty box (the SAH's probability measure).
    pub fn area(&self) -> f32 {
        let e = self.extent();
        2.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
    }

    /// Index (0 = x, 1 = y, 2 = z) of the longest edge; ties go to the lower index.
    pub fn largest_axis(&self) -> usize {
        let e = self.extent();
        if e.x >= e.y && e.x >= e.z {
            0
        } else if e.y >= e.z {
            1
        } else {
            2
        }
    }

    /// Conservative slab test after Ize, "Robust BVH Ray Traversal" (JCGT 2013): the far distance is
    /// widened by `1 + 2γ₃` so that rounding can never make a ray miss a box it touches.
    /// `inv_dir` must come from [`crate::geom::safe_inverse`] so that no `0 · ∞` NaN arises.
    /// Returns the entry distance, or `None` when the ray misses `[tmin, tmax]`.
    #[inline]
    pub fn intersect(&self, origin: Vec3, inv_dir: Vec3, tmin: f32, tmax: f32) -> Option<f32> {
        let t0 = (self.min - origin) * inv_dir;
        let t1 = (self.max - origin) * inv_dir;
        let near = t0.min(t1).max_element().max(tmin);
        let far = t0.max(t1).min_element() * ROBUST_FAR_SCALE;
        let far = far.min(tmax);
        (near <= far).then_some(near)
    }
}

/// `1 + 2γ₃` with `γₙ = nε / (1 − nε)`, `ε = 2⁻²⁴` (Ize 2013, pbrt-v3 §3.9).
pub const ROBUST_FAR_SCALE: f32 =
    1.0 + 2.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);

#[cfg(test)]
mod tests {
    use super::*;

    /// A box too long for f32 to square its extent has a finite diagonal all the same (a
    /// two-level RBVH of such a scene saved an infinite texel its loader refused).
    #[test]
    fn diagonal_of_a_vast_box_is_finite() {
        let b = Aabb {
            min: Vec3::new(-1e21, 0.0, 0.0),
            max: Vec3::new(1e21, 3e20, 5.8e-39),
        };
        let d = b.diagonal();
        assert!(d.is_finite(), "{d}");
        assert!(
            (f64::from(d) / (4e42f64 + 9e40).sqrt() - 1.0).abs() < 1e-6,
            "{d}"
        );
        let small = Aabb {
            min: Vec3::ZERO,
            max: Vec3::new(3.0, 4.0, 12.0),
        };
        assert_eq!(small.diagonal(), 13.0);
        assert_eq!(Aabb::EMPTY.diagonal(), 0.0);
        // Corners so far apart that the extent itself overflows f32: held to the largest float.
        let widest = Aabb {
            min: Vec3::new(-3e38, -3e38, 0.0),
            max: Vec3::new(3e38, 3e38, 0.0),
        };
        assert_eq!(widest.diagonal(), f32::MAX);
    }
}
