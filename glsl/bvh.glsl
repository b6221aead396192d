// The exact triangle BVH: layouts of src/bvh/layout.rs, and its leaf hook for the one traversal
// (traverse.glsl), the twins of src/bvh/traverse.rs operation for operation.
//
// The includer chooses where the two buffers live by defining, before the #include:
//   RBVH_BVH_SET            descriptor set              (default 0)
//   RBVH_BVH_NODES_BINDING  binding of the node buffer
//   RBVH_BVH_TRIS_BINDING   binding of the triangles
//   RBVH_BVH_INSTANCES_BINDING  binding of the instances, with RBVH_INSTANCES (below)
// (the bindings' defaults below are those of the library's own shaders, glsl/bindings.glsl, as
// tests/glsl_header.rs checks; so are rbvh.glsl's and lod.glsl's)
// or, to read every array through buffer device addresses instead of bindings (for arrays over
// maxStorageBufferRange; src/gpu/addressing.rs), RBVH_DEVICE_ADDRESS, having enabled
// GL_EXT_buffer_reference and GL_EXT_buffer_reference_uvec2, with each array's address as a uvec2
// expression: RBVH_BVH_NODES_ADDRESS, RBVH_BVH_TRIS_ADDRESS, with RBVH_INSTANCES
// RBVH_BVH_INSTANCES_ADDRESS (and those of rbvh.glsl and lod.glsl).
// RBVH_INSTANCES makes the structure two-level (src/bvh/top_level.rs): a top level over instances
// whose leaves (count RBVH_INSTANCE_LEAF) enter a mesh's tree in the same node array, the ray
// taken into the mesh's space by the instance's record (the first instance, placed where it is,
// grafted: its mesh's tree is walked in the top level, bvh::GRAFTED); rbvh_trace_instances traces the exact
// BVH's (src/bvh/instanced.rs), rbvh.glsl's rbvh_trace_rbvh_instances the RBVH's.
// The traversals read the arrays only through the accessor macros RBVH_BVH_NODE(i) and
// RBVH_BVH_TRIANGLE(i) (or RBVH_EXACT_QUAD(i)), which hide the difference.
// RBVH_INDEXED_TRIANGLES, which rbvh.glsl defines before including this file, makes the triangle
// array an RBVH's: indexed (src/rbvh/triangles.rs), ExactTriangles::device_words() as uvec4s, a
// slot per triangle (.xyz its vertices' indices, .w its scene index), then the vertices (.xyz,
// float bits): vertex v is element tri_count + v, where tri_count counts the slots, not the
// elements. rbvh_bvh_triangle reads a triangle of either array as a BvhTriangle. So a shader
// traces either the exact BVH or an RBVH (rbvh_trace_bvh is then not defined), as the two share
// these bindings anyway.
#ifndef RBVH_BVH_GLSL
#define RBVH_BVH_GLSL

#include "intersect.glsl"

#ifndef RBVH_BVH_SET
#define RBVH_BVH_SET 0
#endif
#ifndef RBVH_BVH_NODES_BINDING
#define RBVH_BVH_NODES_BINDING 0
#endif
#ifndef RBVH_BVH_TRIS_BINDING
#define RBVH_BVH_TRIS_BINDING 1
#endif
#ifndef RBVH_BVH_INSTANCES_BINDING
#define RBVH_BVH_INSTANCES_BINDING 11
#endif

// Must equal bvh::STACK_SIZE; tests/glsl_header.rs checks it on the device.
#define RBVH_STACK_SIZE 64
// The traversal's memory (traverse.glsl): its stack of (word, distance) entries, then the words an
// RBVH ray's loops read too rarely to hold a register for: the ray (four entries, RBVH_KEEPS_RAY;
// in a two-level trace the world ray, from which each round makes the ray of its level), which
// only each round's start and the hit need again after a leaf's march;
// the nearest hit's normal source (RbvhLeafHook, read once the ray is done); the level-of-detail
// cone (lod.glsl, read where an inner child is entered). They share the stack's array on
// purpose: the stack's pushes write it at indices the compiler measured (ACO) does not resolve (a
// compiler that proved them below RBVH_STACK_SIZE could forward the words; the hits would be the
// same), so a word stored there is read back from memory (scratch on AMD, local memory on NVIDIA,
// cached) instead of held in a register through every march, where each value live costs
// occupancy on wide SIMD (docs/speed.md, "Words kept beside the stack"). A global, so that a hook
// reaches it; a ray's trace writes its words before it reads them, and a shader that traces
// several rays traces them one after another.
// With RBVH_INSTANCES, the ray's words hold the world ray of a two-level trace (RBVH_STACK_WORLD:
// with RBVH_KEEPS_RAY the ray of an instance's mesh space is made from it each round, not kept),
// and two more entries: the instance entered last and the nearest hit's (the two-level RBVH's
// hook, read where a round inside an instance starts, where an instance is entered and once the
// ray is done).
#define RBVH_STACK_RAY RBVH_STACK_SIZE
#define RBVH_STACK_HIT (RBVH_STACK_SIZE + 4)
#define RBVH_STACK_CONE (RBVH_STACK_SIZE + 5)
#ifdef RBVH_INSTANCES
#define RBVH_STACK_WORLD RBVH_STACK_RAY
#define RBVH_STACK_INSTANCE (RBVH_STACK_SIZE + 6)
#define RBVH_STACK_HIT_INSTANCE (RBVH_STACK_SIZE + 7)
uvec2 rbvh_stack[RBVH_STACK_SIZE + 8];
#else
uvec2 rbvh_stack[RBVH_STACK_SIZE + 6];
#endif

void rbvh_keep_ray_at(uint at, Ray ray) {
    rbvh_stack[at] = floatBitsToUint(ray.origin.xy);
    rbvh_stack[at + 1u] = floatBitsToUint(vec2(ray.origin.z, ray.tmin));
    rbvh_stack[at + 2u] = floatBitsToUint(ray.dir.xy);
    rbvh_stack[at + 3u] = floatBitsToUint(vec2(ray.dir.z, ray.tmax));
}

// The ray rbvh_keep_ray_at kept at `at`, bit for bit.
Ray rbvh_kept_ray_at(uint at) {
    vec2 o = uintBitsToFloat(rbvh_stack[at]);
    vec2 oz_tmin = uintBitsToFloat(rbvh_stack[at + 1u]);
    vec2 d = uintBitsToFloat(rbvh_stack[at + 2u]);
    vec2 dz_tmax = uintBitsToFloat(rbvh_stack[at + 3u]);
    return Ray(vec3(o, oz_tmin.x), oz_tmin.y, vec3(d, dz_tmax.x), dz_tmax.y);
}

void rbvh_keep_ray(Ray ray) {
    rbvh_keep_ray_at(RBVH_STACK_RAY, ray);
}

Ray rbvh_kept_ray() {
    return rbvh_kept_ray_at(RBVH_STACK_RAY);
}

#ifdef RBVH_INSTANCES
void rbvh_keep_world_ray(Ray ray) {
    rbvh_keep_ray_at(RBVH_STACK_WORLD, ray);
}

Ray rbvh_kept_world_ray() {
    return rbvh_kept_ray_at(RBVH_STACK_WORLD);
}
#endif
const uint RBVH_LEAF_BIT = 0x80000000u;

// Aila & Laine (2009) node, both children's boxes quantized against the node's own box (Ylitie,
// Karras & Laine 2017) in 48 bytes: GpuNode in src/bvh/layout.rs says how.
struct BvhNode {
    vec3 origin;
    uint exponents;
    uvec3 planes;
    uint a_child;
    uint a_count;
    uint b_child;
    uint b_count;
    uint pad;
};

// The children's boxes of node `n`, as GpuNode::boxes decodes them: plane q of axis k is
// origin_k + q * 2^(e_k - 127); the product is exact, so the sum rounds once and the boxes are the
// CPU's bit for bit. `precise` keeps it unfused as on the CPU for the one case where the product
// is not exact (past FLT_MAX, a node spanning more than half the float range).
void rbvh_node_boxes(BvhNode n, out vec3 a_min, out vec3 a_max, out vec3 b_min, out vec3 b_max) {
    vec3 step = uintBitsToFloat(((uvec3(n.exponents) >> uvec3(0u, 8u, 16u)) & 0xFFu) << 23);
    precise vec3 lo_a = n.origin + vec3(n.planes & 0xFFu) * step;
    precise vec3 hi_a = n.origin + vec3((n.planes >> 8) & 0xFFu) * step;
    precise vec3 lo_b = n.origin + vec3((n.planes >> 16) & 0xFFu) * step;
    precise vec3 hi_b = n.origin + vec3(n.planes >> 24) * step;
    a_min = lo_a;
    a_max = hi_a;
    b_min = lo_b;
    b_max = hi_b;
}

// 48 bytes: vertices gathered in leaf order, with the scene's triangle index (the exact BVH's
// array; an RBVH's indexed one is read into it by rbvh_bvh_triangle).
struct BvhTriangle {
    vec3 v0;
    uint prim;
    vec3 v1;
    uint flags; // GpuTriangle::PART | BARE? | leaf << 2, or 0; not read by the tracers
    vec3 v2;
    uint pad2;
};

#ifdef RBVH_DEVICE_ADDRESS
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer RbvhBvhNodesRef {
    BvhNode nodes[];
};
#define RBVH_BVH_NODE(i) RbvhBvhNodesRef(RBVH_BVH_NODES_ADDRESS).nodes[i]
#ifdef RBVH_INDEXED_TRIANGLES
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer RbvhExactQuadsRef {
    uvec4 quads[];
};
#define RBVH_EXACT_QUAD(i) RbvhExactQuadsRef(RBVH_BVH_TRIS_ADDRESS).quads[i]
#else
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer RbvhBvhTrianglesRef {
    BvhTriangle triangles[];
};
#define RBVH_BVH_TRIANGLE(i) RbvhBvhTrianglesRef(RBVH_BVH_TRIS_ADDRESS).triangles[i]
#endif
#else
layout(std430, set = RBVH_BVH_SET, binding = RBVH_BVH_NODES_BINDING) readonly buffer RbvhBvhNodes {
    BvhNode rbvh_bvh_nodes[];
};
#define RBVH_BVH_NODE(i) rbvh_bvh_nodes[i]
#ifdef RBVH_INDEXED_TRIANGLES
layout(std430, set = RBVH_BVH_SET, binding = RBVH_BVH_TRIS_BINDING) readonly buffer RbvhExactQuads {
    uvec4 rbvh_exact_quads[];
};
#define RBVH_EXACT_QUAD(i) rbvh_exact_quads[i]
#else
layout(std430, set = RBVH_BVH_SET, binding = RBVH_BVH_TRIS_BINDING) readonly buffer RbvhBvhTriangles {
    BvhTriangle rbvh_bvh_triangles[];
};
#define RBVH_BVH_TRIANGLE(i) rbvh_bvh_triangles[i]
#endif
#endif

#ifdef RBVH_INDEXED_TRIANGLES
// Vertex `v` of the indexed triangles, whose vertices start at element `base` (GpuVertex).
vec3 rbvh_exact_vertex(uint base, uint v) {
    return uintBitsToFloat(RBVH_EXACT_QUAD(base + v).xyz);
}
#endif

// The triangle in `slot` of an array of `tri_count`: gathered (the exact BVH's), or read through
// its slot's vertex indices (RBVH_INDEXED_TRIANGLES: ExactTriangles's TriangleSlots twin in
// src/rbvh/triangles.rs), its flags and padding then 0.
BvhTriangle rbvh_bvh_triangle(uint slot, uint tri_count) {
#ifdef RBVH_INDEXED_TRIANGLES
    uvec4 r = RBVH_EXACT_QUAD(slot);
    uint base = tri_count;
    return BvhTriangle(rbvh_exact_vertex(base, r.x), r.w, rbvh_exact_vertex(base, r.y), 0u,
                       rbvh_exact_vertex(base, r.z), 0u);
#else
    return RBVH_BVH_TRIANGLE(slot);
#endif
}

// The traversal stack's entry for `child`, the child of inner node `node` on side b (or a): an
// inner child's reference as it is (with the level of detail's mark), and for a leaf
// LEAF_BIT | node << 1 | side, from which rbvh_stack_pop reads the leaf's reference and count back
// from the node. So the stack holds one word per entry, not two (a leaf's count does not fit beside
// its first triangle in one word), and the read this costs is of a node the ray has just read.
// Inner node indices stay below 2^30 (bvh::MAX_NODES, checked where a tree is built or loaded).
uint rbvh_stack_entry(uint child, uint node, bool b) {
    return (child & RBVH_LEAF_BIT) == 0u ? child : RBVH_LEAF_BIT | (node << 1) | (b ? 1u : 0u);
}

// The reference and count that stack entry `entry` stands for (an inner child's count is 0: the
// traversal reads a count only from leaves).
void rbvh_stack_pop(uint entry, out uint reference, out uint count) {
    uint node = (entry & ~RBVH_LEAF_BIT) >> 1;
    if ((entry & RBVH_LEAF_BIT) == 0u) {
        reference = entry;
        count = 0u;
    } else if ((entry & 1u) != 0u) {
        reference = RBVH_BVH_NODE(node).b_child;
        count = RBVH_BVH_NODE(node).b_count;
    } else {
        reference = RBVH_BVH_NODE(node).a_child;
        count = RBVH_BVH_NODE(node).a_count;
    }
}

// Sizes the exact traversal needs to bound its reads.
struct BvhSizes {
    uint node_count;
    uint tri_count;
};

// The end of a leaf's triangle slots [first, first + count), clamped to the array: without the
// wrap of uint addition that corrupt counts could cause (as saturating_add in src/bvh/traverse.rs).
uint rbvh_slot_end(uint first, uint count, uint tri_count) {
    return count > tri_count - min(first, tri_count) ? tri_count : first + count;
}

// Tests the triangles in slots [first, end) of `tri_count` over [tmin, t_closest) with the
// watertight test: the leaves of the exact BVH and the RBVH's hybrid leaves alike
// (bvh::BvhLeafHook in src/bvh/traverse.rs). On a hit, lowers t_closest, keeps the slot in
// `best_slot` and returns true; with `any_hit` it stops at the first. `steps` counts the
// triangles tested.
bool rbvh_test_triangles(RbvhShear sh, Ray ray, bool any_hit, uint first, uint end, uint tri_count,
                         inout float t_closest, inout uint best_slot, inout uint steps, inout bool cut) {
    RBVH_COUNT_ADD(triangle_leaves, 1u);
    bool hit = false;
    bool stop = false;
    uint slot = first;
    for (; slot < end; ++slot) {
        steps += 1u;
        RBVH_COUNT_ADD(triangles, 1u);
        BvhTriangle tri = rbvh_bvh_triangle(slot, tri_count);
        float t = rbvh_intersect_triangle(sh, tri.v0, tri.v1, tri.v2, ray.tmin, t_closest);
        if (t >= 0.0) {
            t_closest = t;
            best_slot = slot;
            hit = true;
            if (any_hit) {
                stop = true;
                break;
            }
        }
    }
    if (slot < end && !stop) {
        cut = true;  // ended early by the device
    }
    return hit;
}

// Instances (RBVH_INSTANCES): what both two-level structures share, the exact BVH's (below) and
// the RBVH's (rbvh.glsl).
#ifdef RBVH_INSTANCES
// The count of a top-level leaf (bvh::INSTANCE_LEAF): its reference is LEAF_BIT | instance. No
// mesh's leaf has it (an RBVH height field's is 0xFFFFFFFF), so a top-level leaf of another count
// is the grafted mesh's (bvh::GRAFTED: the first instance, where it is the identity, walked in the
// top level with the world ray).
const uint RBVH_INSTANCE_LEAF = 0xFFFFFFFEu;

// One instance (GpuInstance in src/bvh/layout.rs), 64 bytes: world to mesh space by rows (p'_i =
// dot(row_i.xyz, p) + row_i.w), the root node of its mesh's tree, the mesh.
struct BvhInstance {
    vec4 world_to_mesh[3];
    uint root;
    uint mesh;
    uint pad0;
    uint pad1;
};

#ifdef RBVH_DEVICE_ADDRESS
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer RbvhBvhInstancesRef {
    BvhInstance instances[];
};
#define RBVH_BVH_INSTANCE(i) RbvhBvhInstancesRef(RBVH_BVH_INSTANCES_ADDRESS).instances[i]
#else
layout(std430, set = RBVH_BVH_SET, binding = RBVH_BVH_INSTANCES_BINDING) readonly buffer RbvhBvhInstances {
    BvhInstance rbvh_bvh_instances[];
};
#define RBVH_BVH_INSTANCE(i) rbvh_bvh_instances[i]
#endif

// `ray` in instance `inst`'s mesh space (GpuInstance::ray_into): the direction transformed, not
// normalized, so a hit's t is the same along both; tmin and tmax kept.
Ray rbvh_ray_into(BvhInstance inst, Ray ray) {
    vec3 o = vec3(dot(inst.world_to_mesh[0].xyz, ray.origin), dot(inst.world_to_mesh[1].xyz, ray.origin),
                  dot(inst.world_to_mesh[2].xyz, ray.origin))
             + vec3(inst.world_to_mesh[0].w, inst.world_to_mesh[1].w, inst.world_to_mesh[2].w);
    vec3 d = vec3(dot(inst.world_to_mesh[0].xyz, ray.dir), dot(inst.world_to_mesh[1].xyz, ray.dir),
                  dot(inst.world_to_mesh[2].xyz, ray.dir));
    return Ray(o, ray.tmin, d, ray.tmax);
}

// The normal `n` of a hit in instance `inst`'s mesh space, in world space (GpuInstance::normal_out):
// by the transpose of world_to_mesh.
vec3 rbvh_normal_out(BvhInstance inst, vec3 n) {
    return rbvh_unit(inst.world_to_mesh[0].xyz * n.x + inst.world_to_mesh[1].xyz * n.y + inst.world_to_mesh[2].xyz * n.z);
}
#endif  // RBVH_INSTANCES

// The exact BVH's traversal: not with RBVH_INDEXED_TRIANGLES, whose triangle array is an RBVH's.
#ifndef RBVH_INDEXED_TRIANGLES
// The exact BVH's leaf hook for traverse.glsl: its triangles, with the ray's shear made once.
struct BvhLeafHook {
    BvhSizes sz;
    RbvhShear shear;
    uint best_slot;  // the nearest hit's triangle slot, RBVH_INVALID while none
};

uint rbvh_node_count(BvhLeafHook leaves) {
    return leaves.sz.node_count;
}

// A binary tree has one leaf more than it has inner nodes: n visits and n + 2 rounds at most.
uint rbvh_round_bound(BvhLeafHook leaves) {
    return 2u * leaves.sz.node_count + 1u;
}

bool rbvh_is_leaf(BvhLeafHook leaves, uint reference) {
    return (reference & RBVH_LEAF_BIT) != 0u;
}

uint rbvh_enter(BvhLeafHook leaves, uint child, uint count, float t_entry) {
    return child;
}

bool rbvh_test(inout BvhLeafHook leaves, Ray ray, bool any_hit, uint reference, uint count,
               inout float t_closest, inout uint steps, inout bool cut) {
    uint first = reference & ~RBVH_LEAF_BIT;
    uint end = rbvh_slot_end(first, count, leaves.sz.tri_count);
    return rbvh_test_triangles(leaves.shear, ray, any_hit, first, end, leaves.sz.tri_count, t_closest,
                               leaves.best_slot, steps, cut);
}

#define RBVH_TRAVERSE rbvh_traverse_bvh
#define RBVH_LEAVES BvhLeafHook
#include "traverse.glsl"
#undef RBVH_TRAVERSE
#undef RBVH_LEAVES

// The exact BVH's closest (or, with `any_hit`, any) hit: traverse.glsl over its triangles.
// `steps` = nodes visited + triangles tested; `overflow` as in traverse.glsl.
Hit rbvh_trace_bvh(Ray ray, bool any_hit, BvhSizes sz, out uint steps, out bool overflow) {
    BvhLeafHook leaves = BvhLeafHook(sz, rbvh_shear(ray), RBVH_INVALID);
    float t = rbvh_traverse_bvh(ray, any_hit, leaves, steps, overflow);
    if (leaves.best_slot == RBVH_INVALID) {
        return rbvh_miss();
    }
    BvhTriangle tri = rbvh_bvh_triangle(leaves.best_slot, sz.tri_count);
    vec3 n = rbvh_unit_normal(tri.v0, tri.v1, tri.v2);
    return Hit(t, n.x, n.y, n.z, tri.prim, 0u, 0u, 0u);
}

#ifdef RBVH_INSTANCES
// Sizes the two-level traversal needs to bound its reads.
struct BvhInstanceSizes {
    uint node_count;
    uint tri_count;
    uint instance_count;
};

// The two-level exact BVH's hook (InstanceHook in src/bvh/top_level.rs around BvhLeafHook): top-level instance
// leaves enter instances, the meshes' leaves are triangle leaves tested in the mesh's space (the
// grafted mesh's in the top level, with the world ray). The ray's shear is
// made where a leaf is tested, from the ray of the level the traversal is in, rather than kept
// in the hook: 16 VGPRs fewer on RADV, 72 to 56, when it was made (docs/speed.md, "The two-level exact tracer's
// registers"); the same shear as the CPU's, which makes it once per level.
struct BvhInstanceHook {
    BvhInstanceSizes sz;
    uint best_slot;      // the nearest hit's triangle slot, RBVH_INVALID while none
    uint best_instance;  // its instance
    uint entered;        // the instance the ray is in; in the top level the grafted one, 0
};

uint rbvh_node_count(BvhInstanceHook leaves) {
    return leaves.sz.node_count;
}

// The top level's rounds and each instance's (2 · nodes + 2 at most, as for one tree), at most
// 2^32 − 2 so that the loops' counters cannot wrap.
uint rbvh_round_bound(BvhInstanceHook leaves) {
    uint per_tree = 2u * min(leaves.sz.node_count, 0x7FFFFFFEu) + 2u;
    uint trees = min(leaves.sz.instance_count, 0xFFFFFFFEu) + 1u;
    return trees > 0xFFFFFFFEu / per_tree ? 0xFFFFFFFEu : trees * per_tree;
}

bool rbvh_is_leaf(BvhInstanceHook leaves, uint reference) {
    return (reference & RBVH_LEAF_BIT) != 0u;
}

uint rbvh_enter(BvhInstanceHook leaves, uint child, uint count, float t_entry) {
    return child;
}

// The root of the mesh that the instance leaf `reference` names places (the traversal asks for
// top-level leaves of count RBVH_INSTANCE_LEAF alone); RBVH_INVALID for an index past the
// instances. It returns its result, with one exit: inlined in the
// traversal's loop, an early return or an out parameter leaves the compiler a value merged
// across rounds, which it holds in a register through every leaf test (docs/speed.md, "The
// two-level RBVH tracer's registers").
uint rbvh_instance_root(BvhInstanceHook leaves, uint reference, uint count) {
    uint k = reference & ~RBVH_LEAF_BIT;
    uint root = RBVH_INVALID;
    if (k < leaves.sz.instance_count) {
        root = RBVH_BVH_INSTANCE(k).root;
    }
    return root;
}

// Enters the instance leaf `reference` names (rbvh_instance_root found its root): the ray in its
// mesh's space.
Ray rbvh_enter_instance(inout BvhInstanceHook leaves, uint reference, Ray ray) {
    uint k = reference & ~RBVH_LEAF_BIT;
    leaves.entered = k;
    return rbvh_ray_into(RBVH_BVH_INSTANCE(k), ray);
}

// Leaves the instance entered last: `ray` is the world's again (kept beside the stack), and the
// leaves met next are the top level's grafted mesh's (bvh::GRAFTED).
void rbvh_exit_instance(inout BvhInstanceHook leaves, inout Ray ray) {
    ray = rbvh_kept_world_ray();
    leaves.entered = 0u;
}

bool rbvh_test(inout BvhInstanceHook leaves, Ray ray, bool any_hit, uint reference, uint count,
               inout float t_closest, inout uint steps, inout bool cut) {
    // Triangles are the meshes': the traversal hands over leaves met inside an instance and, in
    // the top level, the grafted mesh's.
    uint first = reference & ~RBVH_LEAF_BIT;
    uint end = rbvh_slot_end(first, count, leaves.sz.tri_count);
    bool hit = rbvh_test_triangles(rbvh_shear(ray), ray, any_hit, first, end, leaves.sz.tri_count, t_closest,
                                   leaves.best_slot, steps, cut);
    if (hit) {
        leaves.best_instance = leaves.entered;
    }
    return hit;
}

#define RBVH_TRAVERSE rbvh_traverse_instances
#define RBVH_LEAVES BvhInstanceHook
#define RBVH_TRAVERSE_INSTANCES
#include "traverse.glsl"
#undef RBVH_TRAVERSE
#undef RBVH_LEAVES
#undef RBVH_TRAVERSE_INSTANCES

// The two-level exact BVH's closest (or, with `any_hit`, any) hit: its instance in `instance_id`,
// its mesh's triangle in `id`, the normal taken to world space by the instance (the transpose of
// world_to_mesh: GpuInstance::normal_out).
Hit rbvh_trace_instances(Ray ray, bool any_hit, BvhInstanceSizes sz, out uint steps, out bool overflow) {
    BvhInstanceHook leaves = BvhInstanceHook(sz, RBVH_INVALID, RBVH_INVALID, 0u);
    float t = rbvh_traverse_instances(ray, any_hit, leaves, steps, overflow);
    if (leaves.best_slot == RBVH_INVALID) {
        return rbvh_miss();
    }
    BvhTriangle tri = rbvh_bvh_triangle(leaves.best_slot, sz.tri_count);
    vec3 n = rbvh_unit_normal(tri.v0, tri.v1, tri.v2);
    vec3 w = rbvh_normal_out(RBVH_BVH_INSTANCE(leaves.best_instance), n);
    return Hit(t, w.x, w.y, w.z, tri.prim, leaves.best_instance, 0u, 0u);
}
#endif  // RBVH_INSTANCES

#endif  // RBVH_INDEXED_TRIANGLES

#endif
