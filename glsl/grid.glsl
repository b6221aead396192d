// Stepping a ray through a 2D grid of cells (Amanatides & Woo 1987), and the walk itself
// (RbvhGridWalk): the GLSL twin of src/geom/grid.rs, operation for operation, for the height-field
// march (rbvh.glsl, cells between samples at i + 1/2) and the column march of level of detail
// (lod.glsl, integer boundaries).
// A grid is named by its origin: cell i spans [i + origin, i + 1 + origin) along each axis.
#ifndef RBVH_GRID_GLSL
#define RBVH_GRID_GLSL

#include "common.glsl"

#define RBVH_BETWEEN_SAMPLES 0.5
#define RBVH_COLUMNS 0.0

// The cell holding coordinate x, clamped to [0, last].
int rbvh_grid_cell(float origin, float x, int last) {
    return int(clamp(floor(x - origin), 0.0, float(last)));
}

// The step along one axis: the sign of the direction; a zero component never steps.
int rbvh_grid_step(float d) {
    return d > 0.0 ? 1 : (d < 0.0 ? -1 : 0);
}

// Where a ray at o (inv = 1/direction) stepping by `step` leaves cell c along one axis; +inf along
// an axis it never steps. From the boundary itself, so that long walks do not drift. Adding an
// origin of 0 is exact, so both grids round alike.
float rbvh_grid_boundary_t(float origin, int c, int step, float o, float inv) {
    precise float far_side = (float(c + 1) + origin - o) * inv;
    precise float near_side = (float(c) + origin - o) * inv;
    return step > 0 ? far_side : (step < 0 ? near_side : RBVH_INF);
}

// A ray's walk through a grid: the cell it is in, where it leaves that cell along each axis, and
// where it entered it. The one walk of both marches (rbvh.glsl's height fields, lod.glsl's columns).
struct RbvhGridWalk {
    int ci;
    int cj;
    float next_i;
    float next_j;
    float t_in;
};

// The walk from cell (ci, cj), entered at t_in, of a ray at `o` (inv = 1/direction) stepping by
// step_i, step_j.
RbvhGridWalk rbvh_grid_walk(float origin, int ci, int cj, int step_i, int step_j, vec2 o, vec2 inv, float t_in) {
    float next_i = rbvh_grid_boundary_t(origin, ci, step_i, o.x, inv.x);
    float next_j = rbvh_grid_boundary_t(origin, cj, step_j, o.y, inv.y);
    return RbvhGridWalk(ci, cj, next_i, next_j, t_in);
}

// Steps `w` into the next cell, across the nearer boundary (i's on a tie): returns the axis it
// crossed (0: i, 1: j), or -1 where the walk ends: no step along that axis, or the cell beyond is
// outside [0, last_i] x [0, last_j].
int rbvh_grid_advance(inout RbvhGridWalk w, float origin, int step_i, int step_j, int last_i, int last_j, vec2 o,
                      vec2 inv) {
    bool across_i = w.next_i <= w.next_j;
    int axis = -1;
    if (across_i && step_i != 0) {
        w.ci += step_i;
        w.t_in = w.next_i;
        if (w.ci >= 0 && w.ci <= last_i) {
            w.next_i = rbvh_grid_boundary_t(origin, w.ci, step_i, o.x, inv.x);
            axis = 0;
        }
    } else if (!across_i && step_j != 0) {
        w.cj += step_j;
        w.t_in = w.next_j;
        if (w.cj >= 0 && w.cj <= last_j) {
            w.next_j = rbvh_grid_boundary_t(origin, w.cj, step_j, o.y, inv.y);
            axis = 1;
        }
    }
    return axis;
}

// The ray's height at t; exactly o for a ray parallel to the grid (no 0 * inf).
float rbvh_height_at(float o, float d, float t) {
    precise float h = o + d * t;
    return d == 0.0 ? o : h;
}

#endif
