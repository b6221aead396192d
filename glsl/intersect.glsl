// Robust ray/box and watertight ray/triangle tests: the GLSL twins of src/geom/aabb.rs and
// src/geom/triangle.rs. `precise` forbids FMA contraction, so an edge shared by two triangles
// gives exactly negated edge functions (watertightness) and the CPU reference agrees bit for bit.
#ifndef RBVH_INTERSECT_GLSL
#define RBVH_INTERSECT_GLSL

#include "common.glsl"

// 1 + 2*gamma(3), gamma(n) = n*eps/(1 - n*eps), eps = 2^-24 (Ize 2013); equals geom::ROBUST_FAR_SCALE
// to the bit (tests/glsl_header.rs checks, on the device).
const float RBVH_FAR_SCALE = 1.0 + 2.0 * (3.0 * 5.9604645e-8) / (1.0 - 3.0 * 5.9604645e-8);

// `v` scaled by the power of two that brings its largest component's magnitude into [0.5, 1), the
// exponent kept within +-125; as it is where that component is zero or not finite (as
// geom::triangle's pow2_scaled, to the bit but for subnormal components, which a device may flush
// to zero: a sliver below 1e-38 units may then normalize to NaN here and to a unit vector there).
vec3 rbvh_pow2_scaled(vec3 v) {
    float m = max(max(abs(v.x), abs(v.y)), abs(v.z));
    int e;
    frexp(m, e);
    e = clamp(e, -125, 125);
    return (m > 0.0 && !isinf(m) && !isnan(m)) ? ldexp(v, ivec3(-e)) : v;
}

// `v` normalized at any magnitude (geom::unit): an instance's transformed normal too.
vec3 rbvh_unit(vec3 v) {
    return normalize(rbvh_pow2_scaled(v));
}

// The unit normal of the triangle (a, b, c) as wound, at any scale: geom::unit_normal's steps.
// The edges and their cross product are scaled by powers of two (exact) before normalizing: a
// triangle a trillionth of a unit across has a squared cross product below f32's range.
vec3 rbvh_unit_normal(vec3 a, vec3 b, vec3 c) {
    return rbvh_unit(cross(rbvh_pow2_scaled(b - a), rbvh_pow2_scaled(c - a)));
}

// Conservative slab test (Ize, "Robust BVH Ray Traversal", JCGT 2013).
bool rbvh_intersect_box(vec3 bmin, vec3 bmax, vec3 origin, vec3 inv_dir, float tmin, float tmax,
                        out float t_entry) {
    precise vec3 t0 = (bmin - origin) * inv_dir;
    precise vec3 t1 = (bmax - origin) * inv_dir;
    vec3 lo = min(t0, t1);
    vec3 hi = max(t0, t1);
    t_entry = max(max(max(lo.x, lo.y), lo.z), tmin);
    precise float t_exit = min(min(hi.x, hi.y), hi.z) * RBVH_FAR_SCALE;
    t_exit = min(t_exit, tmax);
    return t_entry <= t_exit;
}

// Per-ray shear of Woop, Benthin & Wald, "Watertight Ray/Triangle Intersection" (JCGT 2013), as
// src/geom/triangle.rs keeps it: the permutation (kx, ky, kz), kz the direction's largest
// component, and the shear (Sx, Sy, Sz). A vertex is sheared as the host shears it,
// `a[kx] - Sx * a[kz]`, its components picked by index (selects on a GPU), so that the CPU
// reference computes the same bits. Six values a ray keeps, where the permutation folded into
// three row vectors (an earlier form) kept twelve: on RADV's null device this took the exact
// tracer from 56 VGPRs to 48 and the RBVH tracer, whose cell test shears four corners at once,
// from 96 to 88 (docs/speed.md, "Values the compiler carried from leaf to leaf").
struct RbvhShear {
    vec3 origin;
    ivec3 k;  // kx, ky, kz
    vec3 s;   // Sx, Sy, Sz
};

RbvhShear rbvh_shear(Ray r) {
    vec3 a = abs(r.dir);
    int kz = (a.x >= a.y && a.x >= a.z) ? 0 : ((a.y >= a.z) ? 1 : 2);
    int kx = (kz + 1) % 3;
    int ky = (kx + 1) % 3;
    if (r.dir[kz] < 0.0) {
        int tmp = kx;
        kx = ky;
        ky = tmp;
    }
    vec3 s = vec3(r.dir[kx] / r.dir[kz], r.dir[ky] / r.dir[kz], 1.0 / r.dir[kz]);
    return RbvhShear(r.origin, ivec3(kx, ky, kz), s);
}

// A vertex in the ray's sheared frame: x and y (the edge functions' plane) and z (the distance
// scale).
vec3 rbvh_sheared(RbvhShear sh, vec3 v) {
    precise vec3 a = v - sh.origin;
    precise float x = a[sh.k.x] - sh.s.x * a[sh.k.z];
    precise float y = a[sh.k.y] - sh.s.y * a[sh.k.z];
    precise float z = sh.s.z * a[sh.k.z];
    return vec3(x, y, z);
}

// The watertight test's second half (rbvh_intersect_sheared): the triangle whose edge functions
// are u, v, w and whose corners' sheared depths are az, bz, cz. Hit distance in [tmin, tmax), or
// a negative value on a miss.
float rbvh_intersect_edges(float u, float v, float w, float az, float bz, float cz, float tmin, float tmax) {
    bool mixed = (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0);
    precise float det = u + v + w;
    precise float t_scaled = u * az + v * bz + w * cz;
    precise float lo = tmin * det;
    precise float hi = tmax * det;
    bool inside = det > 0.0 ? (t_scaled >= lo && t_scaled < hi) : (t_scaled <= lo && t_scaled > hi);
    // The quotient rounds apart from the products: checked again, so that a ray cast again with
    // tmax at its hit does not meet the same triangle there (intersect_triangle says more).
    precise float t = t_scaled / det;
    // One return: see rbvh_grid_start in grid.glsl.
    return !mixed && det != 0.0 && inside && t >= tmin && t < tmax ? t : -1.0;
}

// The watertight test of the triangle whose vertices are A, B, C in the ray's sheared frame
// (rbvh_sheared): hit distance in [tmin, tmax), or a negative value on a miss. Edge functions that
// are exactly zero count as inside on both sides (see src/geom/triangle.rs for why no double
// fallback).
float rbvh_intersect_sheared(vec3 A, vec3 B, vec3 C, float tmin, float tmax) {
    precise float u = C.x * B.y - C.y * B.x;
    precise float v = A.x * C.y - A.y * C.x;
    precise float w = B.x * A.y - B.y * A.x;
    return rbvh_intersect_edges(u, v, w, A.z, B.z, C.z, tmin, tmax);
}

// The watertight test of triangle (v0, v1, v2) for the ray sheared by `sh` (intersect_triangle in
// src/geom/triangle.rs): hit distance in [tmin, tmax), or a negative value on a miss.
float rbvh_intersect_triangle(RbvhShear sh, vec3 v0, vec3 v1, vec3 v2, float tmin, float tmax) {
    return rbvh_intersect_sheared(rbvh_sheared(sh, v0), rbvh_sheared(sh, v1), rbvh_sheared(sh, v2), tmin, tmax);
}

#endif
