//! Rays and hits: the records of the ray and hit files and of the GPU buffers, byte for byte.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

/// A ray: `origin`, `tmin`, `dir`, `tmax`, 8 little-endian `f32` (32 bytes). This is the ray
/// file record and the GPU's `Ray` in `glsl/common.glsl`. `dir` need not be unit length; `t` is
/// measured in units of `dir`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Ray {
    /// Start point in world space (GLSL `vec3 origin`).
    pub origin: [f32; 3],
    /// Nearest accepted hit distance, in units of `dir`; at least 0 (GLSL `float tmin`).
    pub tmin: f32,
    /// Direction in world space, not necessarily unit length (GLSL `vec3 dir`).
    pub dir: [f32; 3],
    /// Farthest accepted hit distance, in units of `dir`; may be `+inf` (GLSL `float tmax`).
    pub tmax: f32,
}
const _: () = assert!(std::mem::size_of::<Ray>() == 32);

impl Ray {
    /// A ray from `origin` along `dir`, accepting hits at `t` in `[tmin, tmax)`; not validated
    /// (see [`is_valid`](Self::is_valid)).
    pub fn new(origin: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> Self {
        Ray {
            origin: origin.to_array(),
            tmin,
            dir: dir.to_array(),
            tmax,
        }
    }

    /// [`origin`](Self::origin) as a vector.
    pub fn origin(&self) -> Vec3 {
        Vec3::from_array(self.origin)
    }

    /// [`dir`](Self::dir) as a vector.
    pub fn dir(&self) -> Vec3 {
        Vec3::from_array(self.dir)
    }

    /// A ray the tracers can answer: finite origin and direction, a non-zero direction, and
    /// `0 ≤ tmin ≤ tmax` (tmax may be +inf). Tracers report anything else as a miss.
    pub fn is_valid(&self) -> bool {
        self.origin().is_finite()
            && self.dir().is_finite()
            && self.dir() != Vec3::ZERO
            && self.tmin >= 0.0
            && self.tmin <= self.tmax
    }
}

/// A hit: `t` (+inf on a miss), the unit geometric normal in world space (as wound: not flipped
/// towards the ray), the primitive `id` (`u32::MAX` on a miss), the `instance` hit and two
/// reserved words (zero). 32 bytes; the hit file record and the GPU's `Hit`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct Hit {
    /// Hit distance in units of the ray's `dir`; `+inf` on a miss (GLSL `float t`).
    pub t: f32,
    /// Unit geometric normal in world space, as wound; zero on a miss (GLSL `nx`, `ny`, `nz`).
    pub normal: [f32; 3],
    /// Scene triangle index, `u32::MAX` on a miss (GLSL `uint id`). RBVH height-field hits set
    /// bit 31 ([`LEAF_BIT`](crate::bvh::LEAF_BIT)) over the leaf index, coarse level-of-detail
    /// hits also [`LOD_BIT`](crate::lod::LOD_BIT) over the node index.
    pub id: u32,
    /// The instance hit (GLSL `instance_id`), whose mesh `id` indexes
    /// ([`InstancedScene`](crate::scene::InstancedScene)); 0 in a structure without instances (a
    /// flat scene is its only instance) and on a miss.
    pub instance: u32,
    /// Padding to 32 bytes; always zero (GLSL `reserved1`, `reserved2`).
    pub reserved: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<Hit>() == 32);

impl Hit {
    /// The miss record: `t = +inf`, zero normal, `id = u32::MAX`.
    pub const MISS: Hit = Hit {
        t: f32::INFINITY,
        normal: [0.0; 3],
        id: u32::MAX,
        instance: 0,
        reserved: [0; 2],
    };

    /// True unless `id` is the miss id `u32::MAX`.
    pub fn is_hit(&self) -> bool {
        self.id != u32::MAX
    }

    /// [`normal`](Self::normal) as a vector.
    pub fn normal(&self) -> Vec3 {
        Vec3::from_array(self.normal)
    }
}

impl Default for Hit {
    fn default() -> Self {
        Self::MISS
    }
}

/// `1/d` per component, with components too small to invert (zero, ±0, denormal) replaced by
/// `±f32::MAX` carrying the component's sign. This keeps the slab test free of `0 · ∞ = NaN` when
/// the origin lies on a slab plane, while still treating the ray as parallel to it.
#[inline]
pub fn safe_inverse(d: Vec3) -> Vec3 {
    let inv = |x: f32| {
        if x.abs() < f32::MIN_POSITIVE {
            f32::MAX.copysign(x)
        } else {
            1.0 / x
        }
    };
    Vec3::new(inv(d.x), inv(d.y), inv(d.z))
}
