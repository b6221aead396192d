//! Stepping a ray through a 2D grid of cells, the DDA of Amanatides & Woo ("A fast voxel traversal
//! algorithm for ray tracing", Eurographics 1987): the one grid walk of every march. [`Grid`]
//! places the cells, [`GridRay`] is the ray's part in the grid's plane, and [`GridWalk`] is the
//! walk, with its three moves: to the next cell, to the cell beyond a grid vertex passed too
//! closely to resolve, and a jump over cells known to hold no hit. Used by the height-field march
//! (`crate::rbvh::march`, whose cells lie between samples at `i + ½`, and whose blocks jump) and
//! the column march of level of detail (`crate::lod::march`, whose columns have integer
//! boundaries); `glsl/grid.glsl` is their GLSL twin, operation for operation. Where the march
//! steps cells, it is here.

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

/// A ray's part in a grid's plane and the grid's extent: what every step of a walk reads, fixed
/// for the walk. Indexed by axis (0: `i`, 1: `j`).
#[derive(Clone, Copy, Debug)]
pub(crate) struct GridRay {
    pub(crate) grid: Grid,
    /// The ray's origin, direction and `1 / direction` ([`crate::geom::safe_inverse`]).
    pub(crate) o: [f32; 2],
    pub(crate) d: [f32; 2],
    pub(crate) inv: [f32; 2],
    /// The DDA's step along each axis ([`step_of`]).
    pub(crate) step: [i64; 2],
    /// The last cell along each axis: the grid's cells are `0..=last`.
    pub(crate) last: [i64; 2],
}

impl GridRay {
    pub(crate) fn new(
        grid: Grid,
        o: [f32; 2],
        d: [f32; 2],
        inv: [f32; 2],
        last: [i64; 2],
    ) -> GridRay {
        GridRay {
            grid,
            o,
            d,
            inv,
            step: [step_of(d[0]), step_of(d[1])],
            last,
        }
    }

    /// Where the ray leaves cell `c` across its boundary along `axis` ([`Grid::boundary_t`]).
    pub(crate) fn boundary_t(&self, axis: usize, c: i64) -> f32 {
        self.grid
            .boundary_t(c, self.step[axis], self.o[axis], self.inv[axis])
    }

    /// Whether `cell` is in the grid.
    pub(crate) fn contains(&self, cell: [i64; 2]) -> bool {
        (0..=self.last[0]).contains(&cell[0]) && (0..=self.last[1]).contains(&cell[1])
    }

    /// The cell a walk that enters the grid at `t0`, at `entry`, starts in: the cell holding the
    /// entry, or along an axis where the ray crossed the boundary behind it within `slack` grid
    /// units of the entry, the cell behind. Rounding in the entry point (a box thinner than it,
    /// far from the origin) must not start the walk past a cell the ray reaches.
    pub(crate) fn start_cell(&self, entry: [f32; 2], t0: f32, slack: f32) -> [i64; 2] {
        let start = |axis: usize| {
            let (step, last) = (self.step[axis], self.last[axis]);
            let c = self.grid.cell_of(entry[axis], last);
            let back = c - step;
            let behind = step != 0
                && (0..=last).contains(&back)
                && (t0 - self.boundary_t(axis, back)) * self.d[axis].abs() <= slack;
            if behind {
                back
            } else {
                c
            }
        };
        [start(0), start(1)]
    }
}

/// A ray's walk through a grid: the cell it is in, where it leaves that cell along each axis, and
/// where it entered it. The one walk of every march, with its three moves: [`GridWalk::advance`]
/// to the next cell, [`GridWalk::across_vertex`] to the cell beyond a grid vertex the ray passes
/// too closely to resolve, and [`GridWalk::jump`] over cells known to be empty (the height
/// fields' blocks). `glsl/grid.glsl`'s `RbvhGridWalk` is its twin, operation for operation; there
/// the [`GridRay`] is passed to each move rather than held, so that the march keeps its steps
/// packed in one register.
#[derive(Clone, Copy, Debug)]
pub(crate) struct GridWalk {
    pub(crate) ray: GridRay,
    pub(crate) cell: [i64; 2],
    /// Where the ray leaves the cell across its boundary along each axis
    /// ([`GridRay::boundary_t`]).
    pub(crate) next: [f32; 2],
    /// Where the ray entered the cell.
    pub(crate) t_in: f32,
}

impl GridWalk {
    /// The walk from `cell`, entered at `t_in`.
    pub(crate) fn new(ray: GridRay, cell: [i64; 2], t_in: f32) -> GridWalk {
        GridWalk {
            ray,
            cell,
            next: [ray.boundary_t(0, cell[0]), ray.boundary_t(1, cell[1])],
            t_in,
        }
    }

    /// The axis whose boundary the ray leaves the cell across: the nearer, `i`'s on a tie (a ray
    /// through a grid vertex steps `i` first).
    pub(crate) fn across(&self) -> usize {
        // `<=` as the GLSL twin writes it: a NaN (only in corrupt data) crosses `j` there too.
        if self.next[0] <= self.next[1] {
            0
        } else {
            1
        }
    }

    /// Where the ray leaves the cell.
    pub(crate) fn t_out(&self) -> f32 {
        self.next[0].min(self.next[1])
    }

    /// Steps into the next cell across the nearer boundary ([`GridWalk::across`]): the axis
    /// crossed, or `None` where the walk ends: no step along that axis, or the cell beyond
    /// outside the grid along it.
    pub(crate) fn advance(&mut self) -> Option<usize> {
        let a = self.across();
        let step = self.ray.step[a];
        if step == 0 {
            return None;
        }
        self.cell[a] += step;
        self.t_in = self.next[a];
        if !(0..=self.ray.last[a]).contains(&self.cell[a]) {
            return None;
        }
        self.next[a] = self.ray.boundary_t(a, self.cell[a]);
        Some(a)
    }

    /// The cell beyond the grid vertex the ray passes on leaving this cell, when it misses the
    /// vertex by at most `slack` grid units and that cell is in the grid: the cell the step
    /// would reach had rounding put the crossing on the other side of the vertex. The ray is in
    /// it (if at all) from [`GridWalk::t_out`] to the farther boundary.
    pub(crate) fn across_vertex(&self, slack: f32) -> Option<[i64; 2]> {
        let step = self.ray.step;
        if step[0] == 0 || step[1] == 0 {
            return None;
        }
        // The other axis than the one crossed: the step went round the vertex on its near side.
        let other = 1 - self.across();
        let gap = (self.next[other] - self.next[1 - other]) * self.ray.d[other].abs();
        let mut cell = self.cell;
        cell[other] += step[other];
        (gap <= slack && self.ray.contains(cell)).then_some(cell)
    }

    /// Jumps to `edge`, the last cell of a rectangle of cells the ray crosses from this one (a
    /// block known to hold no hit), which it leaves along each axis at `leave`
    /// ([`GridRay::boundary_t`] of `edge`): the cell and state the walk would reach cell by cell,
    /// without visiting the cells between. Leaving across the nearer side (`i`'s on a tie, as
    /// [`GridWalk::advance`]), the steps along the other axis before it, then the step into the
    /// edge row or column. Returns the axis the last step crossed, `None` if it took none.
    pub(crate) fn jump(&mut self, edge: [i64; 2], leave: [f32; 2]) -> Option<usize> {
        let out = if leave[0] <= leave[1] { 0 } else { 1 };
        let other = 1 - out;
        // A step along `other` before the one across the `out` side; equal times go to `i`.
        let before = |t: f32| {
            if out == 0 {
                t < leave[out]
            } else {
                t <= leave[out]
            }
        };
        let mut crossed = None;
        let mut t_last = self.t_in;
        // Each step moves towards `edge` and none passes it (the boundaries grow with the cell),
        // so this bound is never what ends the loop.
        let steps = (edge[other] - self.cell[other]).unsigned_abs();
        let step = self.ray.step[other];
        for _ in 0..steps {
            if step == 0 || !before(self.next[other]) {
                break;
            }
            t_last = self.next[other];
            crossed = Some(other);
            self.cell[other] += step;
            self.next[other] = self.ray.boundary_t(other, self.cell[other]);
        }
        if self.cell[out] != edge[out] {
            let into_edge = self.ray.boundary_t(out, edge[out] - self.ray.step[out]);
            if into_edge >= t_last {
                crossed = Some(out);
            }
            t_last = t_last.max(into_edge);
            self.cell[out] = edge[out];
            self.next[out] = leave[out];
        }
        self.t_in = t_last;
        crossed
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
        let ray = GridRay::new(Grid::COLUMNS, [0.5; 2], [1.0; 2], [1.0; 2], [1, 1]);
        let mut w = GridWalk::new(ray, [0, 0], 0.0);
        assert_eq!(w.next, [0.5, 0.5]);
        assert_eq!(w.advance(), Some(0));
        assert_eq!((w.cell, w.t_in, w.next[0]), ([1, 0], 0.5, 1.5));
        assert_eq!(w.advance(), Some(1));
        assert_eq!((w.cell, w.t_in), ([1, 1], 0.5));
        // Beyond the last cell the walk ends, having stepped.
        assert_eq!(w.advance(), None);
        assert_eq!((w.cell[0], w.t_in), (2, 1.5));
        // A ray along j alone never steps i, and ends where it cannot step.
        let ray = GridRay::new(Grid::COLUMNS, [0.5; 2], [0.0, 1.0], [f32::MAX, 1.0], [1, 1]);
        let mut w = GridWalk::new(ray, [0, 0], 0.0);
        assert_eq!(w.next[0], f32::INFINITY);
        assert_eq!(w.advance(), Some(1));
        assert_eq!(w.advance(), None);
        let ray = GridRay::new(Grid::COLUMNS, [0.5; 2], [0.0; 2], [f32::MAX; 2], [1, 1]);
        assert_eq!(GridWalk::new(ray, [0, 0], 0.0).advance(), None);
    }

    #[test]
    fn a_walk_starts_behind_an_entry_within_slack_of_a_boundary() {
        // Entering at t0 = 1.0000001 at s = 1.5000001, just past the boundary between cells 0 and
        // 1 (which it crosses at t = 1).
        let ray = GridRay::new(
            Grid::BETWEEN_SAMPLES,
            [0.5, 0.2],
            [1.0, 0.0],
            [1.0, f32::MAX],
            [5, 5],
        );
        let t0 = 1.000_000_1;
        assert_eq!(ray.start_cell([0.5 + t0, 0.2], t0, 1e-5), [0, 0]);
        assert_eq!(ray.start_cell([0.5 + t0, 0.2], t0, 0.0), [1, 0]);
        assert_eq!(ray.start_cell([1.6, 0.2], 1.1, 1e-5), [1, 0]);
    }

    #[test]
    fn the_cell_across_a_vertex_passed_closely() {
        // Along (1, 1) from just beside the diagonal: it leaves cell (0, 0) across i at 0.5 and
        // passes the vertex (1, 1) 1e-3 from it.
        let ray = GridRay::new(Grid::COLUMNS, [0.5, 0.499], [1.0; 2], [1.0; 2], [3, 3]);
        let w = GridWalk::new(ray, [0, 0], 0.0);
        assert_eq!(w.across(), 0);
        assert_eq!(w.across_vertex(1e-2), Some([0, 1]));
        assert_eq!(w.across_vertex(1e-4), None);
        // Not beyond the grid's edge, nor for a ray that steps along one axis only.
        let w = GridWalk::new(ray, [0, 3], 0.0);
        assert_eq!(w.across_vertex(1e-2), None);
        let ray = GridRay::new(
            Grid::COLUMNS,
            [0.5, 0.5],
            [1.0, 0.0],
            [1.0, f32::MAX],
            [3, 3],
        );
        assert_eq!(GridWalk::new(ray, [0, 0], 0.0).across_vertex(1.0), None);
    }

    #[test]
    fn a_jump_lands_where_the_walk_does() {
        // Rays from every direction (some along i alone) through a 10 × 10 grid; from each cell, a
        // jump to the last cell of its 4 × 4 block (as the march's blocks) lands where stepping
        // cell by cell ends before its first step out of the block, in the same state.
        let mut steps = 0;
        for k in 0..64 {
            let phi = 0.1 + 0.39 * k as f32;
            let d = [phi.cos(), if k % 5 == 0 { 0.0 } else { phi.sin() }];
            let o = [5.1 + 0.03 * k as f32, 4.9 - 0.02 * k as f32];
            let ray = GridRay::new(Grid::BETWEEN_SAMPLES, o, d, d.map(|x| 1.0 / x), [9, 9]);
            let mut w = GridWalk::new(ray, ray.start_cell(o, 0.0, 0.0), 0.0);
            loop {
                let edge = [0, 1].map(|a| {
                    let first = w.cell[a] / 4 * 4;
                    if ray.step[a] > 0 {
                        (first + 3).min(9)
                    } else {
                        first
                    }
                });
                let mut jumped = w;
                let crossed = jumped.jump(edge, [0, 1].map(|a| ray.boundary_t(a, edge[a])));
                let mut walked = w;
                let mut last = None;
                while walked.cell[walked.across()] != edge[walked.across()] {
                    last = walked.advance();
                    steps += 1;
                }
                let state = |w: &GridWalk| (w.cell, w.next, w.t_in);
                assert_eq!(state(&jumped), state(&walked), "{ray:?} from {:?}", w.cell);
                assert_eq!(crossed, last, "{ray:?} from {:?}", w.cell);
                if w.advance().is_none() {
                    break;
                }
            }
        }
        assert!(
            steps > 300,
            "{steps} steps jumped: the test would not test much"
        );
    }
}
