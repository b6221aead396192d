// Stepping a ray through a 2D grid of cells (Amanatides & Woo 1987), and the walk itself
// (RbvhGridWalk, with its moves: advance, across a vertex, jump): the GLSL twin of
// src/geom/grid.rs, operation for operation, for the height-field march (rbvh.glsl, cells between
// samples at i + 1/2) and the column march of level of detail (lod.glsl, integer boundaries).
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

// The cell a walk that enters the grid at t0, at `entry`, starts in along one axis (GridRay's
// start_cell): the cell holding the entry, or the one behind it where the ray crossed their
// boundary within `slack` grid units of the entry.
int rbvh_grid_start(float origin, float entry, int step, int last, float o, float inv, float d, float t0, float slack) {
    int c = rbvh_grid_cell(origin, entry, last);
    int back = c - step;
    // One return: an early one leaves, once inlined into the traversal's loop, a value the
    // compiler carries from one leaf to the next.
    bool behind = false;
    if (step != 0 && back >= 0 && back <= last) {
        precise float gap = (t0 - rbvh_grid_boundary_t(origin, back, step, o, inv)) * abs(d);
        behind = gap <= slack;
    }
    return behind ? back : c;
}

// A ray's walk through a grid: the cell it is in, where it leaves that cell along each axis, and
// where it entered it. The one walk of both marches (rbvh.glsl's height fields, lod.glsl's
// columns), with its three moves: rbvh_grid_advance to the next cell, rbvh_grid_across_vertex to
// the cell beyond a grid vertex passed too closely to resolve, rbvh_grid_jump over cells known
// to be empty (GridWalk in src/geom/grid.rs). The ray's constants are passed to each move rather
// than held, so that the march can keep its steps packed in one register.
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

// Whether the ray, leaving w's cell, passes the grid vertex there within `slack` grid units with
// the cell beyond it in [0, last_i] x [0, last_j] (GridWalk's across_vertex): the cell the step
// would reach had rounding put the crossing on the other side of the vertex.
bool rbvh_grid_across_vertex(RbvhGridWalk w, int step_i, int step_j, int last_i, int last_j, vec2 d, float slack) {
    bool across_i = w.next_i <= w.next_j;
    int xi = across_i ? w.ci : w.ci + step_i;
    int xj = across_i ? w.cj + step_j : w.cj;
    precise float gap = across_i ? (w.next_j - w.next_i) * abs(d.y) : (w.next_i - w.next_j) * abs(d.x);
    return step_i != 0 && step_j != 0 && gap <= slack && xi >= 0 && xi <= last_i && xj >= 0 && xj <= last_j;
}

// Jumps `w` to (edge_i, edge_j), the last cell of a rectangle of cells the ray crosses from w's
// (a block known to hold no hit), which it leaves at leave_i, leave_j (rbvh_grid_boundary_t of
// the edge): the cell and state the walk reaches cell by cell, without the cells between. Leaving
// across the nearer side (i's on a tie), the steps along the other axis before it, then the step
// into the edge row or column: one loop for both sides (lavapipe runs every loop at least once,
// whether or not a lane needs it). Each step moves towards the edge and none passes it, so the
// loop's bound never ends it. Returns the axis the last step crossed, -1 if it took none.
int rbvh_grid_jump(inout RbvhGridWalk w, float origin, int step_i, int step_j, int edge_i, int edge_j, float leave_i,
                   float leave_j, vec2 o, vec2 inv) {
    bool out_i = leave_i <= leave_j;
    int minor_step = out_i ? step_j : step_i;
    int major_step = out_i ? step_i : step_j;
    float leave = out_i ? leave_i : leave_j;
    int minor = out_i ? w.cj : w.ci;
    int steps = abs((out_i ? edge_j : edge_i) - minor);
    float next = out_i ? w.next_j : w.next_i;
    float minor_o = out_i ? o.y : o.x;
    float minor_inv = out_i ? inv.y : inv.x;
    float t_last = w.t_in;
    int crossed = -1;
    for (int m = 0; m < steps && minor_step != 0 && (out_i ? next < leave : next <= leave); ++m) {
        t_last = next;
        crossed = out_i ? 1 : 0;
        minor += minor_step;
        next = rbvh_grid_boundary_t(origin, minor, minor_step, minor_o, minor_inv);
    }
    int major = out_i ? w.ci : w.cj;
    int edge = out_i ? edge_i : edge_j;
    float major_next = out_i ? w.next_i : w.next_j;
    if (major != edge) {
        float into_edge = rbvh_grid_boundary_t(origin, edge - major_step, major_step, out_i ? o.x : o.y,
                                               out_i ? inv.x : inv.y);
        if (into_edge >= t_last) {
            crossed = out_i ? 0 : 1;
        }
        t_last = max(t_last, into_edge);
        major = edge;
        major_next = leave;
    }
    w.ci = out_i ? major : minor;
    w.cj = out_i ? minor : major;
    w.next_i = out_i ? major_next : next;
    w.next_j = out_i ? next : major_next;
    w.t_in = t_last;
    return crossed;
}

// The ray's height at t; exactly o for a ray parallel to the grid (no 0 * inf).
float rbvh_height_at(float o, float d, float t) {
    precise float h = o + d * t;
    return d == 0.0 ? o : h;
}

#endif
