// Rays and hits, byte for byte the records of src/geom/ray.rs (32 bytes each, std430).
#ifndef RBVH_COMMON_GLSL
#define RBVH_COMMON_GLSL

struct Ray {
    vec3 origin;
    float tmin;
    vec3 dir;
    float tmax;
};

// The normal is three floats, not a vec3: std430 would align a vec3 to 16 bytes and move it.
struct Hit {
    float t;        // +inf on a miss
    float nx;       // unit geometric normal as wound, world space
    float ny;
    float nz;
    uint id;        // primitive index, 0xFFFFFFFF on a miss
    uint instance_id;  // the instance hit (src/scene/instances.rs); 0 without instances, on a miss
    uint reserved1;
    uint reserved2;
};

// One ray's work (src/probe.rs, RayCounters; 40 bytes, tests/glsl_header.rs checks the order): counted
// by the traversals only where the includer defines RBVH_COUNT as a true condition before the
// #include (the trace shaders define it as a specialization constant, so that their timed runs
// compile the counting away); other includers pay nothing. The traversal (traverse.glsl) resets
// the counters when it starts. They live in a private variable, rbvh_counters, unless the
// includer defines RBVH_COUNTER(field) as the lvalue of each: the trace shaders count in the
// ray's records of their counters buffers (trace_io.glsl), since ten counters held in registers
// through the walk took the counting pipelines 16 VGPRs above the timed ones on RADV
// (docs/speed.md, "Counters out of the registers").
struct RbvhCounters {
    uint nodes;            // inner nodes visited
    uint leaves;           // height-field leaves (and chosen LOD nodes) handed to the march
    uint walks;            // of those, the ones whose tile box the ray crosses
    uint cells;            // cells (LOD columns) handed to the cell test
    uint cells_tested;     // cells past the cheap height rejection
    uint jumps;            // block jumps (src/rbvh/ranges.rs)
    uint triangle_leaves;  // triangle leaves tested
    uint triangles;        // triangles tested in them
    uint instances;        // instances entered (a two-level BVH's top-level instance leaves)
    uint top_nodes;        // of `nodes`, those a two-level BVH's ray visits outside any instance
                           // (the top level's and the grafted mesh's, bvh::GRAFTED)
};
#ifndef RBVH_COUNT
#define RBVH_COUNT false
#endif
#ifndef RBVH_COUNTER
RbvhCounters rbvh_counters;
#define RBVH_COUNTER(field) rbvh_counters.field
#endif
#define RBVH_COUNT_ADD(field, n) if (RBVH_COUNT) { RBVH_COUNTER(field) += (n); }
#define RBVH_COUNT_RESET() if (RBVH_COUNT) { \
    RBVH_COUNTER(nodes) = 0u; RBVH_COUNTER(leaves) = 0u; RBVH_COUNTER(walks) = 0u; RBVH_COUNTER(cells) = 0u; \
    RBVH_COUNTER(cells_tested) = 0u; RBVH_COUNTER(jumps) = 0u; RBVH_COUNTER(triangle_leaves) = 0u; \
    RBVH_COUNTER(triangles) = 0u; RBVH_COUNTER(instances) = 0u; RBVH_COUNTER(top_nodes) = 0u; }

const uint RBVH_INVALID = 0xFFFFFFFFu;
#define RBVH_INF uintBitsToFloat(0x7F800000u)
#define RBVH_FLT_MAX 3.40282347e+38
#define RBVH_FLT_MIN 1.17549435e-38

Hit rbvh_miss() {
    return Hit(RBVH_INF, 0.0, 0.0, 0.0, RBVH_INVALID, 0u, 0u, 0u);
}

// Same rule as Ray::is_valid: finite origin and direction, non-zero direction, 0 <= tmin <= tmax.
bool rbvh_ray_valid(Ray r) {
    bool finite = !any(isnan(r.origin)) && !any(isinf(r.origin)) && !any(isnan(r.dir)) && !any(isinf(r.dir));
    return finite && r.dir != vec3(0.0) && r.tmin >= 0.0 && r.tmin <= r.tmax;
}

// 1/d per component; components too small to invert become +-FLT_MAX with their sign (see
// safe_inverse in src/geom/ray.rs), so the slab test never computes 0 * inf.
vec3 rbvh_safe_inverse(vec3 d) {
    vec3 big = mix(vec3(RBVH_FLT_MAX), vec3(-RBVH_FLT_MAX), lessThan(floatBitsToInt(d), ivec3(0)));
    return mix(1.0 / d, big, lessThan(abs(d), vec3(RBVH_FLT_MIN)));
}

#endif
