// Stepping a ray through a 2D grid of cells (Amanatides & Woo 1987): the GLSL twin of
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

// The ray's height at t; exactly o for a ray parallel to the grid (no 0 * inf).
float rbvh_height_at(float o, float d, float t) {
    precise float h = o + d * t;
    return d == 0.0 ? o : h;
}

#endif
