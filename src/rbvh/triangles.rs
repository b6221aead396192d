//! The RBVH's exact triangles — its hybrid leaves' and the exact parts beside its height fields —
//! in leaf order, in two forms of the same triangles:
//!
//! * **gathered** ([`GpuTriangle`], 48 bytes each): the vertices copied into each triangle, with
//!   the part flags. The builder, the file and everything on the host that asks which leaf a
//!   part stands beside read this form ([`ExactTriangles::gathered`], `iter`, indexing).
//! * **indexed**, as the device holds them: a 16-byte [`GpuIndexedTriangle`] per slot (its three
//!   vertex indices and its scene triangle index), then every distinct vertex once, a 16-byte
//!   [`GpuVertex`], in the order the slots first name them, so that a leaf's vertices lie
//!   together. Four aligned 16-byte reads a triangle, one more than gathered.
//!
//! At the paper's scale the exact triangles were most of an RBVH's bytes, and they are patches of
//! a scan's surface whose neighbours share vertices: at Q2 on `scenes/paper-scale.toml`, 479,124
//! triangles name 354,971 distinct vertices, 27.9 bytes a triangle indexed against 48 gathered.
//! The vertices are the scene's own floats, bit for bit, so indexing changes no hit: the device
//! and the CPU twin (`crate::bvh::TriangleSlots`) read the same values as the gathered form holds, and
//! triangles that share an edge share its vertices exactly, as the watertight test needs.

use std::collections::HashMap;

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

use crate::bvh::{GpuTriangle, TriangleSlots};
use crate::probe::{element, Array, Probe};

/// One slot of the device's indexed triangles (GLSL `rbvh_bvh_triangle` in `glsl/bvh.glsl`):
/// the indices of its vertices `v0, v1, v2` (winding kept) among the vertices after the slots, and
/// the scene's index of the triangle, returned as the hit `id`. 16 bytes, one aligned read.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct GpuIndexedTriangle {
    /// GLSL `.xyz` of the slot's `uvec4`: vertex indices.
    pub vertices: [u32; 3],
    /// GLSL `.w`: the triangle's index in the scene.
    pub prim: u32,
}
const _: () = assert!(std::mem::size_of::<GpuIndexedTriangle>() == 16);

/// One distinct vertex of the device's indexed triangles: its position, padded to 16 bytes so that
/// it is one aligned read (packed at 12 bytes, the array was 11% smaller at the paper's scale and
/// its three scalar reads made lavapipe's RBVH tracer 8–12% slower on primary rays, where 16-byte
/// reads cost 1–3% on the small scenes: docs/paper-scale.md, "Exact triangles indexed").
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuVertex {
    /// GLSL `.xyz` of the vertex's `uvec4`, as float bits: the scene's vertex, bit for bit.
    pub position: [f32; 3],
    /// GLSL `.w`: 0.
    pub pad: u32,
}
const _: () = assert!(std::mem::size_of::<GpuVertex>() == 16);

/// Bytes of one vertex on the device ([`GpuVertex`]).
pub const VERTEX_BYTES: u64 = std::mem::size_of::<GpuVertex>() as u64;

/// The RBVH's exact triangles, gathered for the host and indexed for the device (module docs).
/// Built once from the gathered triangles; neither form can change without the other. It does not
/// deref to a slice, so that the gathered bytes cannot be uploaded by mistake: the device's are
/// [`ExactTriangles::device_words`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ExactTriangles {
    gathered: Vec<GpuTriangle>,
    /// The device's array, 16 bytes an element: a [`GpuIndexedTriangle`] per slot, then the
    /// [`GpuVertex`]es.
    quads: Vec<[u32; 4]>,
}

impl ExactTriangles {
    /// Both forms of `gathered` (in leaf order): each distinct vertex (by its bits) stored once,
    /// numbered in the order the slots first name it.
    pub fn new(gathered: Vec<GpuTriangle>) -> ExactTriangles {
        let mut index: HashMap<[u32; 3], u32> = HashMap::with_capacity(gathered.len());
        let mut vertices: Vec<[u32; 4]> = Vec::new();
        let mut quads: Vec<[u32; 4]> = gathered
            .iter()
            .map(|t| {
                let mut at = |v: [f32; 3]| {
                    let bits = v.map(f32::to_bits);
                    *index.entry(bits).or_insert_with(|| {
                        vertices.push(bytemuck::cast(GpuVertex {
                            position: v,
                            pad: 0,
                        }));
                        (vertices.len() - 1) as u32
                    })
                };
                bytemuck::cast(GpuIndexedTriangle {
                    vertices: [at(t.v0), at(t.v1), at(t.v2)],
                    prim: t.prim,
                })
            })
            .collect();
        quads.extend(vertices);
        ExactTriangles { gathered, quads }
    }

    /// The gathered form, with the part flags: the host's (not what the shaders read).
    pub fn gathered(&self) -> &[GpuTriangle] {
        &self.gathered
    }

    /// Triangles (slots), in leaf order.
    pub fn len(&self) -> usize {
        self.gathered.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.gathered.is_empty()
    }

    /// The gathered triangles in leaf order.
    pub fn iter(&self) -> std::slice::Iter<'_, GpuTriangle> {
        self.gathered.iter()
    }

    /// The device's slots, one per triangle in leaf order.
    pub fn indexed(&self) -> &[GpuIndexedTriangle] {
        bytemuck::cast_slice(&self.quads[..self.gathered.len()])
    }

    /// The distinct vertices the slots index.
    pub fn vertices(&self) -> &[GpuVertex] {
        bytemuck::cast_slice(&self.quads[self.gathered.len()..])
    }

    /// The device's array: the slots, then the vertices (the shaders find vertex `v` at element
    /// `tri_count + v`).
    pub fn device_words(&self) -> &[u32] {
        bytemuck::cast_slice(&self.quads)
    }

    /// Bytes of the device's array ([`ExactTriangles::device_words`]).
    pub fn device_bytes(&self) -> u64 {
        std::mem::size_of_val(self.quads.as_slice()) as u64
    }

    /// Of [`ExactTriangles::device_bytes`], those of the exact parts beside height fields
    /// ([`GpuTriangle::PART`]): their slots, and each vertex that a part's slot names first (so
    /// that the parts' bytes and the hybrid leaves' add up to the whole).
    pub fn part_bytes(&self) -> u64 {
        let mut seen = vec![false; self.vertices().len()];
        let mut bytes = 0;
        for (t, slot) in self.gathered.iter().zip(self.indexed()) {
            let part = t.part_leaf().is_some();
            for &v in &slot.vertices {
                let first = !std::mem::replace(&mut seen[v as usize], true);
                if part && first {
                    bytes += VERTEX_BYTES;
                }
            }
            if part {
                bytes += std::mem::size_of::<GpuIndexedTriangle>() as u64;
            }
        }
        bytes
    }
}

/// The gathered triangle in `slot`.
impl std::ops::Index<usize> for ExactTriangles {
    type Output = GpuTriangle;

    fn index(&self, slot: usize) -> &GpuTriangle {
        &self.gathered[slot]
    }
}

impl<'a> IntoIterator for &'a ExactTriangles {
    type Item = &'a GpuTriangle;
    type IntoIter = std::slice::Iter<'a, GpuTriangle>;

    fn into_iter(self) -> Self::IntoIter {
        self.gathered.iter()
    }
}

/// The device's reads: the 16-byte slot, then its three vertices after the slots.
impl TriangleSlots for ExactTriangles {
    fn slots(&self) -> usize {
        self.gathered.len()
    }

    fn read<P: Probe>(&self, slot: usize, probe: &mut P) -> ([Vec3; 3], u32) {
        probe.read(element::<GpuIndexedTriangle>(Array::Triangles, slot));
        let record = self.indexed()[slot];
        let vertices = record.vertices.map(|v| {
            let at = self.gathered.len() + v as usize;
            probe.read(element::<GpuVertex>(Array::Triangles, at));
            Vec3::from(self.vertices()[v as usize].position)
        });
        (vertices, record.prim)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri(v: [[f32; 3]; 3], prim: u32) -> GpuTriangle {
        GpuTriangle::new(v.map(Vec3::from), prim)
    }

    /// A quad's two triangles share two vertices: four stored, in the order first named, and
    /// every slot reads back the gathered triangle bit for bit.
    #[test]
    fn shared_vertices_are_stored_once_and_read_back_exactly() {
        let (a, b, c, d) = (
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.1],
            [0.0, 1.0, -0.0],
        );
        let mut part = tri([a, c, d], 7);
        part.flags = GpuTriangle::part_flags(3, false);
        let exact = ExactTriangles::new(vec![tri([a, b, c], 5), part]);
        let positions: Vec<[f32; 3]> = exact.vertices().iter().map(|v| v.position).collect();
        assert_eq!(positions, [a, b, c, d]);
        assert!(exact.vertices().iter().all(|v| v.pad == 0));
        assert_eq!(exact.indexed()[1].vertices, [0, 2, 3]);
        assert_eq!(exact.device_bytes(), 2 * 16 + 4 * 16);
        assert_eq!(exact.device_words().len() as u64 * 4, exact.device_bytes());
        // The part's slot and the one vertex it names first (d).
        assert_eq!(exact.part_bytes(), 16 + 16);
        for (slot, t) in exact.gathered().iter().enumerate() {
            let mut reads = Vec::new();
            let (v, prim) = exact.read(slot, &mut reads);
            assert_eq!(
                v.map(|v| v.to_array().map(f32::to_bits)),
                t.vertices().map(|v| v.to_array().map(f32::to_bits))
            );
            assert_eq!(prim, t.prim);
            // The slot, then its vertices after both slots, each 16 bytes at its own offset.
            let indexed = exact.indexed()[slot]
                .vertices
                .map(|v| 16 * (2 + u64::from(v)));
            let offsets: Vec<u64> = reads.iter().map(|r| r.offset).collect();
            assert_eq!(
                offsets,
                [16 * slot as u64, indexed[0], indexed[1], indexed[2]]
            );
            assert!(reads
                .iter()
                .all(|r| r.array == Array::Triangles && r.bytes == 16));
        }
        // -0.0 and 0.0 are different bits: kept apart, so no vertex moves.
        let signed = ExactTriangles::new(vec![tri([a, b, c], 0), tri([[-0.0, 0.0, 0.0], b, c], 1)]);
        assert_eq!(signed.vertices().len(), 4);
    }

    #[test]
    fn no_triangles_cost_nothing() {
        let exact = ExactTriangles::new(Vec::new());
        assert_eq!((exact.device_bytes(), exact.part_bytes()), (0, 0));
        assert!(exact.device_words().is_empty());
    }
}
