//! Which structure rays are traced through: the exact BVH, an RBVH, or an RBVH with its levels of
//! detail. One type for the CLI, the image regression and embedders alike (pbrt-v4 has one
//! `CreateAccelerator` behind one interface), so that "which structure" is decided once and every
//! user uploads ([`crate::gpu::Tracer::new`] takes one), traces and names it the same way. It
//! sits below the GPU side: a structure is data, and the tracer chooses its shader by
//! [`Structure::kind`].

use std::sync::Arc;

use crate::bvh::Bvh;
use crate::geom::{Hit, Ray};
use crate::lod::{Lod, RayCone};
use crate::rbvh::Rbvh;
use crate::Result;

/// Which structure, without it: the `method` of benchmark records (`"exact"`, `"rbvh"`,
/// `"rbvh-lod"`) and what [`Structure::kind`] says.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Kind {
    /// The exact triangle BVH ([`crate::bvh`]), the referee.
    Exact,
    /// An RBVH ([`crate::rbvh`]) traced at full resolution.
    Rbvh,
    /// An RBVH traced with its levels of detail ([`crate::lod`]).
    #[serde(rename = "rbvh-lod")]
    RbvhLod,
}

impl Kind {
    /// `"exact"`, `"rbvh"` or `"rbvh-lod"`, as records and file names write it.
    pub fn name(self) -> &'static str {
        match self {
            Kind::Exact => "exact",
            Kind::Rbvh => "rbvh",
            Kind::RbvhLod => "rbvh-lod",
        }
    }
}

/// A built structure, ready to upload ([`crate::gpu::Tracer::new`]) or to trace on the CPU.
pub enum Structure {
    /// The exact triangle BVH, the referee.
    Exact(Bvh),
    /// An RBVH traced at full resolution. Shared, so that one RBVH can be traced both with and
    /// without levels of detail (as the benchmark does) without a copy.
    Rbvh(Arc<Rbvh>),
    /// An RBVH with its levels of detail (built for it), traced with one cone per ray.
    RbvhLod(Arc<Rbvh>, Box<Lod>),
}

impl From<Bvh> for Structure {
    fn from(bvh: Bvh) -> Self {
        Structure::Exact(bvh)
    }
}

impl From<Rbvh> for Structure {
    fn from(rbvh: Rbvh) -> Self {
        Structure::Rbvh(Arc::new(rbvh))
    }
}

impl From<Arc<Rbvh>> for Structure {
    fn from(rbvh: Arc<Rbvh>) -> Self {
        Structure::Rbvh(rbvh)
    }
}

impl Structure {
    /// `rbvh` traced with its levels of detail `lod` (built for it by [`Lod::build`]).
    pub fn with_lod(rbvh: impl Into<Arc<Rbvh>>, lod: Lod) -> Self {
        Structure::RbvhLod(rbvh.into(), Box::new(lod))
    }

    /// The exact BVH, if that is what is traced.
    pub fn bvh(&self) -> Option<&Bvh> {
        match self {
            Structure::Exact(bvh) => Some(bvh),
            _ => None,
        }
    }

    /// The RBVH traced, if any (for the colour of its hits, its texel size).
    pub fn rbvh(&self) -> Option<&Rbvh> {
        match self {
            Structure::Exact(_) => None,
            Structure::Rbvh(rbvh) | Structure::RbvhLod(rbvh, _) => Some(rbvh),
        }
    }

    /// The RBVH traced, if any, to change (painting its colour channel, say); a copy of it
    /// when it is shared with another structure.
    pub fn rbvh_mut(&mut self) -> Option<&mut Rbvh> {
        match self {
            Structure::Exact(_) => None,
            Structure::Rbvh(rbvh) | Structure::RbvhLod(rbvh, _) => Some(Arc::make_mut(rbvh)),
        }
    }

    /// The levels of detail, when traced with them.
    pub fn lod(&self) -> Option<&Lod> {
        match self {
            Structure::RbvhLod(_, lod) => Some(lod),
            _ => None,
        }
    }

    /// Which of the three it is.
    pub fn kind(&self) -> Kind {
        match self {
            Structure::Exact(_) => Kind::Exact,
            Structure::Rbvh(_) => Kind::Rbvh,
            Structure::RbvhLod(..) => Kind::RbvhLod,
        }
    }

    /// "exact BVH", "RBVH" or "RBVH with levels of detail": for messages.
    pub fn label(&self) -> &'static str {
        match self {
            Structure::Exact(_) => "exact BVH",
            Structure::Rbvh(_) => "RBVH",
            Structure::RbvhLod(..) => "RBVH with levels of detail",
        }
    }

    /// The CPU reference of a trace of `rays`: closest hits, or with `any_hit` any hits. `cones`
    /// (one per ray) are read only with levels of detail, which fail without them.
    pub fn trace_cpu(&self, rays: &[Ray], cones: &[RayCone], any_hit: bool) -> Result<Vec<Hit>> {
        Ok(match self {
            Structure::Exact(bvh) => bvh.trace_cpu(rays, any_hit),
            Structure::Rbvh(rbvh) => rbvh.trace_cpu(rays, any_hit),
            Structure::RbvhLod(rbvh, lod) => rbvh.trace_cpu_lod(lod, rays, cones, any_hit)?,
        })
    }
}
