//! CPU reference of the column march of a coarse representation (`glsl/lod.glsl` mirrors it step
//! for step):
//!
//! 1. **Grid space**: `x`, `y` in columns from the record's origin along `u`, `v`; `z` in world
//!    units along `w`. The map is affine, so `t` is shared with the world ray.
//! 2. **Clip** to the grid's box `[0, res_u] × [0, res_v] × [0, MAX_CODE·h_scale]`, padded in `z`.
//! 3. **Walk** the columns the ray crosses with the 2D DDA of Amanatides & Woo (1987).
//! 4. **Column**: solid between its bottom and top; the ray hits it where its height over the
//!    column's stretch `[t_in, t_out]` first lies in that range — through the top (top normal),
//!    the bottom (bottom normal) or a side (the normal of the nearer of the two).
//!
//! Every index is checked (out of range = empty) and the walk is bounded by the column count.

use glam::Vec3;

use super::layout::GpuLod;
use crate::geom::grid::{height_at, Grid, GridRay, GridWalk};
use crate::geom::{safe_inverse, Aabb, Ray};
use crate::probe::{Array, Probe, RayCounters, Read};
use crate::rbvh::layout::{decode_octahedral, MARCH_SLACK};
use crate::rbvh::Texel;

/// Marches `lod`'s columns (words in `texels`) over `[tmin, t_closest)`; returns the hit distance
/// and world normal. `counters` counts a walk when the ray crosses the grid's box and each column
/// visited as a cell; `probe` hears each column's read (its two words).
pub(crate) fn march<P: Probe>(
    lod: &GpuLod,
    texels: &[u32],
    ray: &Ray,
    t_closest: f32,
    counters: &mut RayCounters,
    probe: &mut P,
) -> Option<(f32, Vec3)> {
    if !lod.is_some() || lod.res_u == 0 || lod.res_v == 0 || lod.axis > 2 {
        return None;
    }
    let last = u64::from(lod.base) + 2 * u64::from(lod.res_u) * u64::from(lod.res_v);
    if last > texels.len() as u64 {
        return None;
    }
    // 1. Grid space.
    let [u, v, w] = lod.axes();
    let (o, d, origin) = (ray.origin(), ray.dir(), Vec3::from(lod.origin));
    let go = Vec3::new(
        (o[u] - origin[u]) * lod.inv_texel,
        (o[v] - origin[v]) * lod.inv_texel,
        o[w] - origin[w],
    );
    let gd = Vec3::new(d[u] * lod.inv_texel, d[v] * lod.inv_texel, d[w]);
    let inv = safe_inverse(gd);
    // 2. Clip.
    let h_top = f32::from(Texel::MAX_CODE) * lod.h_scale;
    let slack = MARCH_SLACK * (go.z.abs() + h_top) + lod.h_scale;
    let grid = Aabb {
        min: Vec3::new(0.0, 0.0, -slack),
        max: Vec3::new(lod.res_u as f32, lod.res_v as f32, h_top + slack),
    };
    let t0 = grid.intersect(go, inv, ray.tmin, t_closest)?;
    counters.walks += 1;
    let e0 = (grid.min - go) * inv;
    let e1 = (grid.max - go) * inv;
    let t1 = e0.max(e1).min_element().min(t_closest);
    // 3. Walk.
    let entry = go + gd * t0;
    let last = [i64::from(lod.res_u) - 1, i64::from(lod.res_v) - 1];
    let cells = GridRay::new(
        Grid::COLUMNS,
        [go.x, go.y],
        [gd.x, gd.y],
        [inv.x, inv.y],
        last,
    );
    let cell = [0, 1].map(|a| Grid::COLUMNS.cell_of(entry[a], last[a]));
    let mut w = GridWalk::new(cells, cell, t0);
    for _ in 0..lod.res_u + lod.res_v {
        let ([ci, cj], t_in) = (w.cell, w.t_in);
        if t_in > t1 {
            break;
        }
        counters.cells += 1;
        let t_out = w.t_out().min(t1);
        // 4. Column.
        if let Some((column, index)) = lod.column(texels, ci as u32, cj as u32) {
            probe.read(Read {
                array: Array::LodColumns,
                offset: 4 * index as u64,
                bytes: 8,
            });
            if !column.is_empty() {
                let top = f32::from(column.top.height_code()) * lod.h_scale;
                let bottom = f32::from(column.bottom.height_code()) * lod.h_scale;
                let za = height_at(go.z, gd.z, t_in);
                let zb = height_at(go.z, gd.z, t_out);
                if za.max(zb) >= bottom && za.min(zb) <= top {
                    let (t, texel) = if za > top {
                        ((top - go.z) * inv.z, column.top)
                    } else if za < bottom {
                        ((bottom - go.z) * inv.z, column.bottom)
                    } else if top - za <= za - bottom {
                        (t_in, column.top)
                    } else {
                        (t_in, column.bottom)
                    };
                    // The first column met ends the walk; a hit at t_closest is not nearer than
                    // the one found (the stretch ends there), so [tmin, t_closest) holds.
                    let t = t.max(t_in).min(t_out);
                    return (t < t_closest).then(|| (t, decode_octahedral((texel.0 >> 16) as u16)));
                }
            }
        }
        if w.advance().is_none() {
            break;
        }
    }
    None
}
