// The exact triangle BVH: layouts of src/bvh/layout.rs and the stack traversal of
// src/bvh/traverse.rs, operation for operation.
//
// The includer chooses where the two buffers live by defining, before the #include:
//   RBVH_BVH_SET            descriptor set              (default 0)
//   RBVH_BVH_NODES_BINDING  binding of the node buffer  (default 0)
//   RBVH_BVH_TRIS_BINDING   binding of the triangles    (default 1)
// or, to read every array through buffer device addresses instead of bindings (for arrays over
// maxStorageBufferRange; src/gpu/addressing.rs), RBVH_DEVICE_ADDRESS, having enabled
// GL_EXT_buffer_reference and GL_EXT_buffer_reference_uvec2, with each array's address as a uvec2
// expression: RBVH_BVH_NODES_ADDRESS, RBVH_BVH_TRIS_ADDRESS (and those of rbvh.glsl and lod.glsl).
// The traversals read the arrays only through the accessor macros RBVH_BVH_NODE(i) and
// RBVH_BVH_TRIANGLE(i), which hide the difference.
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

// Must equal bvh::STACK_SIZE; tests/glsl_header.rs checks it on the device.
#define RBVH_STACK_SIZE 64
const uint RBVH_LEAF_BIT = 0x80000000u;

// Aila & Laine (2009) node: both children's boxes in 64 bytes.
struct BvhNode {
    vec3 a_min;
    uint a_child;
    vec3 a_max;
    uint a_count;
    vec3 b_min;
    uint b_child;
    vec3 b_max;
    uint b_count;
};

// 48 bytes: vertices gathered in leaf order, with the scene's triangle index.
struct BvhTriangle {
    vec3 v0;
    uint prim;
    vec3 v1;
    uint pad1;
    vec3 v2;
    uint pad2;
};

#ifdef RBVH_DEVICE_ADDRESS
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer RbvhBvhNodesRef {
    BvhNode nodes[];
};
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer RbvhBvhTrianglesRef {
    BvhTriangle triangles[];
};
#define RBVH_BVH_NODE(i) RbvhBvhNodesRef(RBVH_BVH_NODES_ADDRESS).nodes[i]
#define RBVH_BVH_TRIANGLE(i) RbvhBvhTrianglesRef(RBVH_BVH_TRIS_ADDRESS).triangles[i]
#else
layout(std430, set = RBVH_BVH_SET, binding = RBVH_BVH_NODES_BINDING) readonly buffer RbvhBvhNodes {
    BvhNode rbvh_bvh_nodes[];
};
layout(std430, set = RBVH_BVH_SET, binding = RBVH_BVH_TRIS_BINDING) readonly buffer RbvhBvhTriangles {
    BvhTriangle rbvh_bvh_triangles[];
};
#define RBVH_BVH_NODE(i) rbvh_bvh_nodes[i]
#define RBVH_BVH_TRIANGLE(i) rbvh_bvh_triangles[i]
#endif

// Traverses nearest child first with a bounded stack. `node_count` bounds the loop (a tree visits
// each node at most once). `overflow` is set when the stack or the loop bound was exceeded, or when
// the device ended a loop early; the hit is then not trustworthy, and the caller reports it.
// `steps` = nodes visited + triangles tested.
//
// Ended early: lavapipe (llvmpipe) stops any shader loop once the loops of an invocation's SIMD
// group have run LP_MAX_TGSI_LOOP_ITERATIONS (65535) iterations in all, silently, as if the loop
// condition had failed; a traversal of ~4000 nodes reaches that. So every loop below records how
// it ended, and one that stopped with its condition still true and no break of its own flags
// `overflow`. This adds no arithmetic: the hit is computed exactly as in src/bvh/traverse.rs.
Hit rbvh_trace_bvh(Ray ray, bool any_hit, uint node_count, out uint steps, out bool overflow) {
    steps = 0u;
    RBVH_COUNT_RESET();
    overflow = false;
    if (!rbvh_ray_valid(ray)) {
        return rbvh_miss();
    }
    vec3 inv_dir = rbvh_safe_inverse(ray.dir);
    RbvhShear sh = rbvh_shear(ray);
    float t_closest = ray.tmax;
    uint best = RBVH_INVALID;
    uint stack[RBVH_STACK_SIZE];
    uint sp = 0u;
    uint node = 0u;
    // Each stack entry is a child reference with its count (the triangles of a leaf).
    uint stack_count[RBVH_STACK_SIZE];
    uint count_of_node = 0u;
    bool finished = false;
    // "While-while" (Aila & Laine 2009): leaves are pushed and popped like inner nodes; the inner
    // loop visits inner nodes only and leaves for the outer loop, which tests the leaf's
    // triangles and resumes it. On SIMD hardware the triangle tests then run for all lanes that
    // reached a leaf together (about 1.4x faster on lavapipe than testing leaves in the per-child
    // loop). A binary tree has one leaf more than it has inner nodes, which bounds the rounds.
    uint leaf = RBVH_INVALID;
    uint leaf_count = 0u;
    uint visit = 0u;
    for (uint round = 0u; round <= node_count + 1u; ++round) {
        if (leaf != RBVH_INVALID) {
            uint first = leaf & ~RBVH_LEAF_BIT;
            uint slot = first;
            RBVH_COUNT_ADD(triangle_leaves, 1u);
            for (; slot < first + leaf_count; ++slot) {
                steps += 1u;
                RBVH_COUNT_ADD(triangles, 1u);
                BvhTriangle tri = RBVH_BVH_TRIANGLE(slot);
                float t = rbvh_intersect_triangle(sh, tri.v0, tri.v1, tri.v2, ray.tmin, t_closest);
                if (t >= 0.0) {
                    t_closest = t;
                    best = slot;
                    if (any_hit) {
                        break;
                    }
                }
            }
            if (any_hit && best != RBVH_INVALID) {
                finished = true;
                break;
            }
            if (slot < first + leaf_count) {
                overflow = true;  // ended early by the device
            }
            leaf = RBVH_INVALID;
            if (sp == 0u) {
                finished = true;
                break;
            }
            sp -= 1u;
            node = stack[sp];
            count_of_node = stack_count[sp];
        }
        for (; visit <= node_count; ++visit) {
            if ((node & RBVH_LEAF_BIT) != 0u) {
                leaf = node;
                leaf_count = count_of_node;
                break;
            }
            steps += 1u;
            RBVH_COUNT_ADD(nodes, 1u);
            BvhNode n = RBVH_BVH_NODE(node);
            float ta;
            float tb;
            bool ha = rbvh_intersect_box(n.a_min, n.a_max, ray.origin, inv_dir, ray.tmin, t_closest, ta);
            bool hb = rbvh_intersect_box(n.b_min, n.b_max, ray.origin, inv_dir, ray.tmin, t_closest, tb);
            bool b_first = ha && hb && tb < ta;
            uint next = RBVH_INVALID;
            uint next_count = 0u;
            int k = 0;
            for (; k < 2; ++k) {
                bool use_b = (k == 0) == b_first;
                bool h = use_b ? hb : ha;
                float t_entry = use_b ? tb : ta;
                uint child = use_b ? n.b_child : n.a_child;
                uint count = use_b ? n.b_count : n.a_count;
                if (!h || t_entry > t_closest) {
                    continue;
                }
                if (next == RBVH_INVALID) {
                    next = child;
                    next_count = count;
                } else if (sp < RBVH_STACK_SIZE) {
                    stack[sp] = child;
                    stack_count[sp] = count;
                    sp += 1u;
                } else {
                    overflow = true;
                }
            }
            if (k < 2) {
                overflow = true;  // ended early by the device
            }
            if (next == RBVH_INVALID) {
                if (sp == 0u) {
                    finished = true;
                    break;
                }
                sp -= 1u;
                next = stack[sp];
                next_count = stack_count[sp];
            }
            node = next;
            count_of_node = next_count;
        }
        if (leaf == RBVH_INVALID) {
            break;
        }
    }
    if (!finished) {
        overflow = true;  // the loop bound, or ended early by the device
    }
    if (best == RBVH_INVALID) {
        return rbvh_miss();
    }
    BvhTriangle tri = RBVH_BVH_TRIANGLE(best);
    vec3 n = normalize(cross(tri.v1 - tri.v0, tri.v2 - tri.v0));
    return Hit(t_closest, n.x, n.y, n.z, tri.prim, 0u, 0u, 0u);
}

#endif
