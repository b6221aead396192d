//! Stepping a ray through a 2D grid of cells, the DDA of Amanatides & Woo ("A fast voxel traversal
//! algorithm for ray tracing", Eurographics 1987): the cell of a point, the step along an axis, where
//! the ray leaves a cell, its height there, and the walk itself ([`GridWalk`]). Shared by the
//! height-field march
//! (`crate::rbvh::march`, whose cells lie between samples at `i + ½`) and the column march of level
//! of detail (`crate::lod::march`, whose columns have integer boundaries); `glsl/grid.glsl` is
//! their GLSL twin, operation for operation.

/// A grid whose cell `i` spans `[i + origin, i + 1 + origin)` along each axis.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Grid {
    origin: f32,
}

impl Grid {
    /// The cells of a height field: between its samples, which sit at `i + ½`.
    pub(crate) const BETWEEN_SAMPLES: Grid = Grid { origin: 0.5 };
    /// Columns with integer boundaries (a coarse representation's).
    pub(crate) const COLUMNS: Grid = Grid { origin: 0.0 };

    /// The cell holding coordinate `x`, clamped to `0..=last`. `as` saturates and maps NaN to 0,
    /// so any input gives a valid cell.
    pub(crate) fn cell_of(self, x: f32, last: i64) -> i64 {
        ((x - self.origin).floor() as i64).clamp(0, last)
    }

    /// The ray parameter at which a ray at `o` (with `inv` = 1/direction) stepping by `step`
    /// leaves cell `c` along one axis, `+inf` for an axis it never steps along. Computed from the
    /// boundary itself rather than by accumulating `1/d` per step as Amanatides & Woo do, so that
    /// long marches do not drift and every boundary has the same distance whichever way the ray
    /// reaches it. (Adding an origin of 0 is exact, so both grids round alike.)
    pub(crate) fn boundary_t(self, c: i64, step: i64, o: f32, inv: f32) -> f32 {
        if step > 0 {
            ((c + 1) as f32 + self.origin - o) * inv
        } else if step < 0 {
            (c as f32 + self.origin - o) * inv
        } else {
            f32::INFINITY
        }
    }
}

/// A ray's walk through a grid: the cell it is in, where it leaves that cell along each axis, and
/// where it entered it. The one walk of both marches (`glsl/grid.glsl`'s `RbvhGridWalk`); the
/// height fields' block jumps move it too.
#[derive(Clone, Copy, Debug)]
pub(crate) struct GridWalk {
    pub(crate) ci: i64,
    pub(crate) cj: i64,
    /// Where the ray leaves the cell across its `i` and its `j` boundary ([`Grid::boundary_t`]).
    pub(crate) next_i: f32,
    pub(crate) next_j: f32,
    /// Where the ray entered the cell.
    pub(crate) t_in: f32,
}

impl GridWalk {
    /// The walk from cell `(ci, cj)`, entered at `t_in`, of a ray at `o` (`inv` = 1/direction)
    /// stepping by `step` along each axis.
    pub(crate) fn new(
        grid: Grid,
        (ci, cj): (i64, i64),
        step: (i64, i64),
        o: (f32, f32),
        inv: (f32, f32),
        t_in: f32,
    ) -> GridWalk {
        GridWalk {
            ci,
            cj,
            next_i: grid.boundary_t(ci, step.0, o.0, inv.0),
            next_j: grid.boundary_t(cj, step.1, o.1, inv.1),
            t_in,
        }
    }

    /// Steps into the next cell across the nearer boundary (`i`'s on a tie, as a ray through a
    /// grid vertex steps `i` first): the axis crossed (0: `i`, 1: `j`), or `None` where the walk
    /// ends: no step along that axis, or the cell beyond outside `0..=last` along it.
    pub(crate) fn advance(
        &mut self,
        grid: Grid,
        step: (i64, i64),
        last: (i64, i64),
        o: (f32, f32),
        inv: (f32, f32),
    ) -> Option<usize> {
        if self.next_i <= self.next_j {
            if step.0 == 0 {
                return None;
            }
            self.ci += step.0;
            self.t_in = self.next_i;
            if !(0..=last.0).contains(&self.ci) {
                return None;
            }
            self.next_i = grid.boundary_t(self.ci, step.0, o.0, inv.0);
            Some(0)
        } else {
            if step.1 == 0 {
                return None;
            }
            self.cj += step.1;
            self.t_in = self.next_j;
            if !(0..=last.1).contains(&self.cj) {
                return None;
            }
            self.next_j = grid.boundary_t(self.cj, step.1, o.1, inv.1);
            Some(1)
        }
    }
}

/// The DDA's step along one axis: the sign of the direction; a zero component never steps.
pub(crate) fn step_of(d: f32) -> i64 {
    if d > 0.0 {
        1
    } else if d < 0.0 {
        -1
    } else {
        0
    }
}

/// The ray's height at `t`; exactly `o` for a ray parallel to the grid, so that `0 · ∞` cannot
/// make a NaN when a cell's exit distance is infinite.
pub(crate) fn height_at(o: f32, d: f32, t: f32) -> f32 {
    if d == 0.0 {
        o
    } else {
        o + d * t
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_and_boundaries_of_both_grids() {
        let samples = Grid::BETWEEN_SAMPLES;
        let columns = Grid::COLUMNS;
        assert_eq!(samples.cell_of(1.49, 9), 0);
        assert_eq!(samples.cell_of(1.5, 9), 1);
        assert_eq!(columns.cell_of(1.5, 9), 1);
        assert_eq!(columns.cell_of(f32::NAN, 9), 0);
        assert_eq!(columns.cell_of(1e30, 9), 9);
        assert_eq!(columns.cell_of(-3.0, 9), 0);
        // A ray from 0.25 with direction 0.5 (inv 2): sample cell 0 ends at 1.5, column 0 at 1.
        assert_eq!(samples.boundary_t(0, 1, 0.25, 2.0), 2.5);
        assert_eq!(columns.boundary_t(0, 1, 0.25, 2.0), 1.5);
        assert_eq!(columns.boundary_t(3, -1, 4.25, -2.0), 2.5);
        assert_eq!(samples.boundary_t(3, 0, 4.25, 2.0), f32::INFINITY);
        assert_eq!((step_of(-0.0), step_of(1e-40), step_of(-2.0)), (0, 1, -1));
        assert_eq!(height_at(2.0, 0.0, f32::INFINITY), 2.0);
        assert_eq!(height_at(2.0, -1.0, 0.5), 1.5);
    }

    #[test]
    fn a_walk_steps_the_nearer_boundary_first_and_ends_at_the_grid_edge() {
        // From (0.5, 0.5) along (1, 1): through the vertex at (1, 1), i first on the tie.
        let (o, inv, step, last) = ((0.5, 0.5), (1.0, 1.0), (1, 1), (1, 1));
        let mut w = GridWalk::new(Grid::COLUMNS, (0, 0), step, o, inv, 0.0);
        assert_eq!((w.next_i, w.next_j), (0.5, 0.5));
        assert_eq!(w.advance(Grid::COLUMNS, step, last, o, inv), Some(0));
        assert_eq!((w.ci, w.cj, w.t_in, w.next_i), (1, 0, 0.5, 1.5));
        assert_eq!(w.advance(Grid::COLUMNS, step, last, o, inv), Some(1));
        assert_eq!((w.ci, w.cj, w.t_in), (1, 1, 0.5));
        // Beyond the last cell the walk ends, having stepped.
        assert_eq!(w.advance(Grid::COLUMNS, step, last, o, inv), None);
        assert_eq!((w.ci, w.t_in), (2, 1.5));
        // A ray along j alone never steps i, and ends where it cannot step.
        let (inv, step) = ((f32::MAX, 1.0), (0, 1));
        let mut w = GridWalk::new(Grid::COLUMNS, (0, 0), step, o, inv, 0.0);
        assert_eq!(w.next_i, f32::INFINITY);
        assert_eq!(w.advance(Grid::COLUMNS, step, last, o, inv), Some(1));
        assert_eq!(w.advance(Grid::COLUMNS, step, last, o, inv), None);
        let mut w = GridWalk::new(Grid::COLUMNS, (0, 0), (0, 0), o, inv, 0.0);
        assert_eq!(w.advance(Grid::COLUMNS, (0, 0), last, o, inv), None);
    }
}
