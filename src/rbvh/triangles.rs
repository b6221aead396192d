//! The RBVH's exact triangles — its hybrid leaves' and the exact parts beside its height fields —
//! in leaf order, in two forms of the same triangles:
//!
//! * **gathered** ([`GpuTriangle`], 48 bytes each): the vertices copied into each triangle, with
//!   the part flags. The builder, the file and everything on the host that asks which leaf a
//!   part stands beside read this form (through `Deref` to `[GpuTriangle]`).
//! * **indexed**, as the device holds them: a 16-byte [`GpuIndexedTriangle`] per slot (its three
//!   vertex indices and its scene triangle index), then every distinct vertex once, 12 bytes
//!   each, in the order the slots first name them, so that a leaf's vertices lie together.
//!
//! At the paper's scale the exact parts are most of an RBVH's bytes, and they are patches of a
//! scan's surface whose neighbours share vertices: at Q2 on `scenes/paper-scale.toml`, 479,124
//! triangles name 354,971 distinct vertices, 24.9 bytes a triangle indexed against 48 gathered.
//! The vertices are the scene's own floats, bit for bit, so indexing changes no hit: the device
//! and the CPU twin ([`TriangleSlots`]) read the same values as the gathered form holds, and
//! triangles that share an edge share its vertices exactly, as the watertight test needs.

use std::collections::HashMap;
use std::ops::Deref;

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

use crate::bvh::{GpuTriangle, TriangleSlots};
use crate::probe::{element, Array, Probe, Read};

/// One slot of the device's indexed triangles (GLSL `rbvh_exact_triangle` in `glsl/bvh.glsl`):
/// the indices of its vertices `v0, v1, v2` (winding kept) in the vertices after the slots, and
/// the scene's index of the triangle, returned as the hit `id`. 16 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct GpuIndexedTriangle {
    /// GLSL words 0–2 of the slot: vertex indices.
    pub vertices: [u32; 3],
    /// GLSL word 3: the triangle's index in the scene.
    pub prim: u32,
}
const _: () = assert!(std::mem::size_of::<GpuIndexedTriangle>() == 16);

/// Bytes of one vertex on the device: three floats, unpadded.
pub const VERTEX_BYTES: u64 = 12;

/// The RBVH's exact triangles, gathered for the host and indexed for the device (module docs).
/// Built once from the gathered triangles; neither form can change without the other.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ExactTriangles {
    gathered: Vec<GpuTriangle>,
    /// The device's array: a [`GpuIndexedTriangle`] per slot, then the vertices.
    words: Vec<u32>,
}

impl ExactTriangles {
    /// Both forms of `gathered` (in leaf order): each distinct vertex (by its bits) stored once,
    /// numbered in the order the slots first name it.
    pub fn new(gathered: Vec<GpuTriangle>) -> ExactTriangles {
        let mut index: HashMap<[u32; 3], u32> = HashMap::with_capacity(gathered.len());
        let mut vertices: Vec<[f32; 3]> = Vec::new();
        let indexed: Vec<GpuIndexedTriangle> = gathered
            .iter()
            .map(|t| {
                let mut at = |v: [f32; 3]| {
                    *index.entry(v.map(f32::to_bits)).or_insert_with(|| {
                        vertices.push(v);
                        (vertices.len() - 1) as u32
                    })
                };
                GpuIndexedTriangle {
                    vertices: [at(t.v0), at(t.v1), at(t.v2)],
                    prim: t.prim,
                }
            })
            .collect();
        let mut words: Vec<u32> = bytemuck::cast_slice(&indexed).to_vec();
        words.extend_from_slice(bytemuck::cast_slice(&vertices));
        ExactTriangles { gathered, words }
    }

    /// The gathered form, with the part flags (also what `Deref` gives).
    pub fn gathered(&self) -> &[GpuTriangle] {
        &self.gathered
    }

    /// The device's slots, one per triangle in leaf order.
    pub fn indexed(&self) -> &[GpuIndexedTriangle] {
        bytemuck::cast_slice(&self.words[..self.slot_words()])
    }

    /// The distinct vertices the slots index.
    pub fn vertices(&self) -> &[[f32; 3]] {
        bytemuck::cast_slice(&self.words[self.slot_words()..])
    }

    /// The device's array: the slots, then the vertices (the shaders find the vertices after
    /// `4 × tri_count` words).
    pub fn device_words(&self) -> &[u32] {
        &self.words
    }

    /// Bytes of the device's array ([`ExactTriangles::device_words`]).
    pub fn device_bytes(&self) -> u64 {
        std::mem::size_of_val(self.words.as_slice()) as u64
    }

    fn slot_words(&self) -> usize {
        4 * self.gathered.len()
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

impl Deref for ExactTriangles {
    type Target = [GpuTriangle];

    fn deref(&self) -> &[GpuTriangle] {
        &self.gathered
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
        let base = 4 * self.slot_words() as u64;
        let vertices = record.vertices.map(|v| {
            probe.read(Read {
                array: Array::Triangles,
                offset: base + u64::from(v) * VERTEX_BYTES,
                bytes: VERTEX_BYTES as u32,
            });
            Vec3::from(self.vertices()[v as usize])
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
        assert_eq!(exact.vertices(), &[a, b, c, d]);
        assert_eq!(exact.indexed()[1].vertices, [0, 2, 3]);
        assert_eq!(exact.device_bytes(), 2 * 16 + 4 * 12);
        assert_eq!(exact.device_words().len() as u64 * 4, exact.device_bytes());
        // The part's slot and the one vertex it names first (d).
        assert_eq!(exact.part_bytes(), 16 + 12);
        for (slot, t) in exact.gathered().iter().enumerate() {
            let mut reads = Vec::new();
            let (v, prim) = exact.read(slot, &mut reads);
            assert_eq!(
                v.map(|v| v.to_array().map(f32::to_bits)),
                t.vertices().map(|v| v.to_array().map(f32::to_bits))
            );
            assert_eq!(prim, t.prim);
            assert_eq!(reads.len(), 4);
            assert_eq!(
                reads[0],
                Read {
                    array: Array::Triangles,
                    offset: 16 * slot as u64,
                    bytes: 16
                }
            );
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
