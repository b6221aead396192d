// Robust ray/box and watertight ray/triangle tests: the GLSL twins of src/geom/aabb.rs and
// src/geom/triangle.rs. `precise` forbids FMA contraction, so an edge shared by two triangles
// gives exactly negated edge functions (watertightness) and the CPU reference agrees bit for bit.
#ifndef RBVH_INTERSECT_GLSL
#define RBVH_INTERSECT_GLSL

#include "common.glsl"

// 1 + 2*gamma(3), gamma(n) = n*eps/(1 - n*eps), eps = 2^-24 (Ize 2013); equals geom::ROBUST_FAR_SCALE
// to the bit (tests/glsl_header.rs checks, on the device).
const float RBVH_FAR_SCALE = 1.0 + 2.0 * (3.0 * 5.9604645e-8) / (1.0 - 3.0 * 5.9604645e-8);

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

// Per-ray shear of Woop, Benthin & Wald, "Watertight Ray/Triangle Intersection" (JCGT 2013).
// The permutation (kx, ky, kz) and shear are folded into three row vectors, so a vertex is
// transformed with plain multiply-adds instead of dynamically indexed components (which compile to
// chains of selects per SIMD lane on lavapipe). The rows mx and my each have one entry 1, one -S
// and one 0, and mz one entry Sz and two 0s, so every sum is exactly the paper's
// `a[kx] - Sx * a[kz]` (or `Sz * a[kz]`): adding a product with 0 changes nothing, and the CPU
// reference computes bit-identical values.
struct RbvhShear {
    vec3 origin;
    vec3 mx;   // e[kx] - Sx e[kz]
    vec3 my;   // e[ky] - Sy e[kz]
    vec3 mz;   // Sz e[kz]
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
    float sx = r.dir[kx] / r.dir[kz];
    float sy = r.dir[ky] / r.dir[kz];
    float sz = 1.0 / r.dir[kz];
    vec3 ex = vec3(equal(ivec3(kx), ivec3(0, 1, 2)));
    vec3 ey = vec3(equal(ivec3(ky), ivec3(0, 1, 2)));
    vec3 ez = vec3(equal(ivec3(kz), ivec3(0, 1, 2)));
    RbvhShear sh;
    sh.origin = r.origin;
    sh.mx = ex - sx * ez;
    sh.my = ey - sy * ez;
    sh.mz = sz * ez;
    return sh;
}

// A vertex in the ray's sheared frame: x and y (the edge functions' plane) and z (the distance
// scale), each sum exact as RbvhShear's rows make it.
vec3 rbvh_sheared(RbvhShear sh, vec3 v) {
    precise vec3 a = v - sh.origin;
    precise vec3 ax = a * sh.mx;
    precise vec3 ay = a * sh.my;
    precise vec3 az = a * sh.mz;
    precise float x = (ax.x + ax.y) + ax.z;
    precise float y = (ay.x + ay.y) + ay.z;
    precise float z = (az.x + az.y) + az.z;
    return vec3(x, y, z);
}

// The watertight test of the triangle whose vertices are A, B, C in the ray's sheared frame
// (rbvh_sheared): hit distance in [tmin, tmax), or a negative value on a miss. Edge functions that
// are exactly zero count as inside on both sides (see src/geom/triangle.rs for why no double
// fallback).
float rbvh_intersect_sheared(vec3 A, vec3 B, vec3 C, float tmin, float tmax) {
    precise float u = C.x * B.y - C.y * B.x;
    precise float v = A.x * C.y - A.y * C.x;
    precise float w = B.x * A.y - B.y * A.x;
    if ((u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0)) {
        return -1.0;
    }
    precise float det = u + v + w;
    if (det == 0.0) {
        return -1.0;
    }
    precise float t_scaled = u * A.z + v * B.z + w * C.z;
    precise float lo = tmin * det;
    precise float hi = tmax * det;
    bool inside = det > 0.0 ? (t_scaled >= lo && t_scaled < hi) : (t_scaled <= lo && t_scaled > hi);
    return inside ? t_scaled / det : -1.0;
}

// The watertight test of triangle (v0, v1, v2) for the ray sheared by `sh` (intersect_triangle in
// src/geom/triangle.rs): hit distance in [tmin, tmax), or a negative value on a miss.
float rbvh_intersect_triangle(RbvhShear sh, vec3 v0, vec3 v1, vec3 v2, float tmin, float tmax) {
    return rbvh_intersect_sheared(rbvh_sheared(sh, v0), rbvh_sheared(sh, v1), rbvh_sheared(sh, v2), tmin, tmax);
}

#endif
