// The one nearest-first traversal of the node array, for every structure: the GLSL twin of
// crate::bvh::traverse (src/bvh/traverse.rs), step for step, with the leaf as a hook (the shape of
// madmann91/bvh's `intersect(ray, ..., leaf_fn)` and obvhs' `traverse(ray, hit, intersection_fn)`).
//
// A template, so it has no include guard: GLSL has no generics, so each structure includes it once
// with its own hook. Before the #include, define
//   RBVH_TRAVERSE  the function's name
//   RBVH_LEAVES    the hook: a struct type that keeps the nearest hit, with these overloads for it
//     uint rbvh_node_count(RBVH_LEAVES leaves)    inner nodes (node 0 the root)
//     uint rbvh_round_bound(RBVH_LEAVES leaves)   bounds both loops: at least the leaves + 1
//                                                 (rounds) and the inner nodes (visits)
//     bool rbvh_is_leaf(RBVH_LEAVES leaves, uint reference)
//         whether a child reference goes to rbvh_test rather than being descended into
//     uint rbvh_enter(RBVH_LEAVES leaves, uint child, uint count, float t_entry)
//         the reference an inner child entered at t_entry is pushed as (level of detail marks one)
//     bool rbvh_test(inout RBVH_LEAVES leaves, Ray ray, bool any_hit, uint reference, uint count,
//                    inout float t_closest, inout uint steps, inout bool cut)
//         tests the leaf over [tmin, t_closest); on a hit lowers t_closest, keeps the hit and
//         returns true. Sets `cut` where the device ended one of its loops early.
// and, optionally, RBVH_KEEPS_RAY: the traversal then keeps the ray in rbvh_stack and reads it
// back at each round's start rather than holding it in registers through the leaf tests (the
// RBVH's marches, where that costs occupancy; the exact BVH's triangle tests hold few registers,
// so its tracer keeps the ray where it is); the caller reads the ray back with rbvh_kept_ray()
// after the traversal (with instances, rbvh_kept_world_ray()).
// With RBVH_TRAVERSE_INSTANCES (the two-level structures: bvh.glsl's exact BVH, rbvh.glsl's RBVH),
// two levels in one loop, as crate::bvh::traverse: the hook also has
//     uint rbvh_instance_root(RBVH_LEAVES leaves, uint reference, uint count)
//         the root of the mesh that top-level leaf `reference` places (where the next round
//         starts), asked for leaves of count RBVH_INSTANCE_LEAF alone, which the traversal
//         checks; RBVH_INVALID for none (an instance whose root is RBVH_INVALID is none)
//     Ray rbvh_enter_instance(inout RBVH_LEAVES leaves, uint reference, Ray ray)
//         enters that instance: the ray in its mesh's space
//     void rbvh_exit_instance(inout RBVH_LEAVES leaves, inout Ray ray)
//         leaves it: the world ray back in `ray` (the traversal keeps it with rbvh_keep_world_ray);
//         the leaves met next, in the top level, are the grafted mesh's, whose hits the hook
//         names instance 0 (bvh::GRAFTED)
// and with RBVH_KEEPS_RAY
//     Ray rbvh_level_ray(RBVH_LEAVES leaves, bool inside)
//         the ray of the level a round is in: the world ray, kept with rbvh_keep_world_ray, or
//         inside an instance that ray in its mesh's space, made again each round rather than
//         kept (the traversal then ignores the ray the other two hooks give)
// (the first two return their results, with one exit: inlined in this loop, an early return or
// an out parameter leaves the compiler a value merged across rounds, which ACO held in a
// register through every leaf test; docs/speed.md, "The two-level RBVH tracer's registers"),
// and the traversal pushes an instance's end (distance -inf, RBVH_INSTANCE_END, which no nearest
// hit drops; its word the top level's visits so far) when it enters one, and leaves the instance
// when it pops that entry. It hands the hook's rbvh_test the leaves met inside an instance and,
// in the top level, every leaf whose count is not RBVH_INSTANCE_LEAF: the mesh the top level
// grafts (bvh::GRAFTED, the first instance where it is the identity), walked there with the world
// ray, so that its rays enter and leave no instance, each of which takes a round. Distances are
// the same along both rays (the direction is transformed, not normalized). Visits are bounded per
// level: a mesh placed twice may be visited twice.
// It also uses, from bvh.glsl (included before it wherever it is instantiated: bvh.glsl,
// rbvh.glsl, lod.glsl) and what that includes (common.glsl, intersect.glsl): Ray, BvhNode,
// RBVH_BVH_NODE(i), rbvh_node_boxes, RBVH_LEAF_BIT, RBVH_INVALID, RBVH_STACK_SIZE, rbvh_stack,
// with instances RBVH_INSTANCE_LEAF,
// rbvh_keep_ray, rbvh_kept_ray, rbvh_stack_entry, rbvh_stack_pop, rbvh_ray_valid, with instances rbvh_keep_world_ray,
// rbvh_safe_inverse, rbvh_intersect_box, RBVH_COUNT_RESET and RBVH_COUNT_ADD. Define the two names above and include it; then
// `float RBVH_TRAVERSE(Ray ray, bool any_hit, inout RBVH_LEAVES leaves, out uint steps, out bool
// overflow)` returns the nearest distance found (ray.tmax if none; the
// hook tells whether it kept a hit). `steps` = nodes visited plus what the hook adds;
// `overflow` is set when the stack or a loop bound was exceeded or the device ended a loop early,
// and the hit is then not trustworthy, so the caller reports it.
//
// "While-while" (Aila & Laine 2009): leaves take the same nearest-first/stack path as inner nodes;
// the inner loop visits inner nodes only and leaves for the outer loop when it meets a leaf,
// which the outer loop hands to the hook at the end of that round. On SIMD
// hardware the leaf tests then run for all lanes that reached a leaf together, instead of beside
// node visits in every iteration (about 1.4x faster on lavapipe for triangle leaves; inlined in
// the per-child loop, the march's registers weighed on every node visit, 4x slower). Each round
// tests at most one leaf (the last none), and a tree has one leaf more than it has inner nodes,
// which bounds the rounds.
// The leaf is tested at the end of the round that met it, and what the traversal needs again
// after the test is made anew each round (the ray's inverse, the next node, with RBVH_KEEPS_RAY
// the ray itself, read back from rbvh_stack, or with instances made from the world ray read
// back) rather than carried through it: a value live across
// the march holds a register through it (docs/speed.md, "The leaf tested where it is met",
// "Words kept beside the stack").
//
// Ended early: lavapipe (llvmpipe) stops any shader loop once the loops of an invocation's SIMD
// group have run LP_MAX_TGSI_LOOP_ITERATIONS (65535) iterations in all, silently, as if the loop
// condition had failed; a traversal of ~4000 nodes reaches that. So every loop records how it
// ended, and one that stopped with its condition still true and no break of its own flags
// `overflow`. This adds no arithmetic: the hit is computed exactly as on the CPU.
//
// One stack of (word, distance) pairs (rbvh_stack_entry in bvh.glsl says what the word holds): an
// entry whose box was entered beyond the nearest hit found since it was pushed is dropped when it
// comes off the stack, neither visited nor marched (as crate::bvh::traverse does).
//
// Corrupt data never loops forever: a node index out of range has no children, and more node
// visits than nodes (only a cycle can make them) end the ray as an overflow.

float RBVH_TRAVERSE(Ray ray, bool any_hit, inout RBVH_LEAVES leaves, out uint steps, out bool overflow) {
    steps = 0u;
    RBVH_COUNT_RESET();
    overflow = false;
    float t_closest = ray.tmax;
#ifdef RBVH_TRAVERSE_INSTANCES
    rbvh_keep_world_ray(ray);
#elif defined(RBVH_KEEPS_RAY)
    rbvh_keep_ray(ray);
#endif
    if (!rbvh_ray_valid(ray)) {
        return t_closest;
    }
    uint node_count = rbvh_node_count(leaves);
    uint bound = rbvh_round_bound(leaves);
#ifdef RBVH_TRAVERSE_INSTANCES
    // The instance's end on the stack: floatBitsToUint(-inf).
    const uint RBVH_INSTANCE_END = 0xFF800000u;
    bool inside = false;
    // Where the next round starts: the root, then an instance's root after it is entered.
    uint start = 0u;
    // Whether the inner loop popped an instance's end, which the next round's start takes back.
    bool leaving = false;
#endif
    // The stack's entries in rbvh_stack: rbvh_stack_entry's word and the distance at which the
    // child's box was entered, so that an entry whose box now lies beyond the nearest hit is
    // dropped when popped instead of visited or marched.
    uint sp = 0u;
    uint visits = 0u;
    // Loops the device ended early flag `overflow` too.
    bool cut = false;
    bool finished = false;
    uint iter = 0u;
    for (uint round = 0u; round <= bound; ++round) {
#ifdef RBVH_TRAVERSE_INSTANCES
        // An instance's end popped in the last round: the world ray back, here rather than in
        // the inner loop, which would carry the hook's work beside every node visit.
        if (leaving) {
            rbvh_exit_instance(leaves, ray);
            inside = false;
            // The top level's visits, kept in the instance's end entry (still at sp) rather than
            // in a register through the instance's marches.
            visits = rbvh_stack[sp].x;
            leaving = false;
        }
#endif
        // Read back and made anew each round rather than kept through the leaf test, where each
        // would hold registers through the march (docs/speed.md, "What holds the RBVH tracer's
        // registers", "Words kept beside the stack").
#ifdef RBVH_KEEPS_RAY
#ifdef RBVH_TRAVERSE_INSTANCES
        // Made from the world ray each round, so that entering and leaving an instance write no
        // ray: keeping the mesh ray beside the stack, and copying the world ray back there on
        // leaving, cost the two-level RBVH 8-10% of its speed on lavapipe, whose SIMD groups run
        // each round's branches whether a lane takes them or not (docs/paper-scale.md, "What two
        // levels cost a ray on lavapipe").
        ray = rbvh_level_ray(leaves, inside);
#else
        ray = rbvh_kept_ray();
#endif
#endif
        vec3 inv_dir = rbvh_safe_inverse(ray.dir);
        // The reference to visit next: the root in the first round, else RBVH_INVALID (pop one).
#ifdef RBVH_TRAVERSE_INSTANCES
        uint node = start;
        start = RBVH_INVALID;
#else
        uint node = round == 0u ? 0u : RBVH_INVALID;
#endif
        uint count_of_node = 0u;
        // The leaf the inner loop leaves for the hook; RBVH_INVALID while none.
        uint pending = RBVH_INVALID;
        uint pending_count = 0u;
        for (; iter <= bound; ++iter) {
            if (node == RBVH_INVALID) {
                // Each pass pops one entry: at most the stack's entries, and no more than sp.
                bool popped = false;
                for (; sp > 0u;) {
                    sp -= 1u;
#ifdef RBVH_TRAVERSE_INSTANCES
                    if (rbvh_stack[sp].y == RBVH_INSTANCE_END) {
                        leaving = true;
                        break;
                    }
#endif
                    if (uintBitsToFloat(rbvh_stack[sp].y) <= t_closest) {
                        rbvh_stack_pop(rbvh_stack[sp].x, node, count_of_node);
                        popped = true;
                        break;
                    }
                }
                if (!popped) {
#ifdef RBVH_TRAVERSE_INSTANCES
                    if (leaving) {
                        break;
                    }
#endif
                    if (sp > 0u) {
                        cut = true;
                    } else {
                        finished = true;
                    }
                    break;
                }
            }
            if (rbvh_is_leaf(leaves, node)) {
                pending = node;
                pending_count = count_of_node;
                break;
            }
            uint next = RBVH_INVALID;
            uint next_count = 0u;
            if (node < node_count) {
                if (visits >= node_count) {
                    overflow = true;
                    finished = true;
                    break;
                }
                visits += 1u;
                steps += 1u;
                RBVH_COUNT_ADD(nodes, 1u);
#ifdef RBVH_TRAVERSE_INSTANCES
                RBVH_COUNT_ADD(top_nodes, inside ? 0u : 1u);
#endif
                BvhNode n = RBVH_BVH_NODE(node);
                vec3 a_min;
                vec3 a_max;
                vec3 b_min;
                vec3 b_max;
                rbvh_node_boxes(n, a_min, a_max, b_min, b_max);
                float ta;
                float tb;
                bool ha = rbvh_intersect_box(a_min, a_max, ray.origin, inv_dir, ray.tmin, t_closest, ta);
                bool hb = rbvh_intersect_box(b_min, b_max, ray.origin, inv_dir, ray.tmin, t_closest, tb);
                // Nearest child first; b only goes first when strictly nearer.
                bool b_first = ha && hb && tb < ta;
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
                    if ((child & RBVH_LEAF_BIT) == 0u) {
                        child = rbvh_enter(leaves, child, count, t_entry);
                    }
                    if (next == RBVH_INVALID) {
                        next = child;
                        next_count = count;
                    } else if (sp < RBVH_STACK_SIZE) {
                        rbvh_stack[sp] = uvec2(rbvh_stack_entry(child, node, use_b), floatBitsToUint(t_entry));
                        sp += 1u;
                    } else {
                        overflow = true;
                    }
                }
                if (k < 2) {
                    cut = true;
                }
            }
            node = next;
            count_of_node = next_count;
        }
        // A leaf met in the last round is left untested: the bound ran out.
#ifdef RBVH_TRAVERSE_INSTANCES
        if (leaving && round < bound) {
            continue;
        }
#endif
        if (pending == RBVH_INVALID || round == bound) {
            break;
        }
#ifdef RBVH_TRAVERSE_INSTANCES
        bool instance_leaf = !inside && pending_count == RBVH_INSTANCE_LEAF;
        uint root = instance_leaf ? rbvh_instance_root(leaves, pending, pending_count) : RBVH_INVALID;
        if (root != RBVH_INVALID) {
            ray = rbvh_enter_instance(leaves, pending, ray);
            if (sp < RBVH_STACK_SIZE) {
                RBVH_COUNT_ADD(instances, 1u);
                rbvh_stack[sp] = uvec2(visits, RBVH_INSTANCE_END);
                sp += 1u;
                inside = true;
                visits = 0u;
                start = root;
            } else {
                rbvh_exit_instance(leaves, ray);
                overflow = true;
            }
            continue;
        }
        // An instance leaf with nothing to enter holds nothing; any other leaf met in the top
        // level is the grafted mesh's.
        if (instance_leaf) {
            continue;
        }
#endif
        bool hit = rbvh_test(leaves, ray, any_hit, pending, pending_count, t_closest, steps, cut);
        if (hit && any_hit) {
            finished = true;
            break;
        }
    }
    // Every normal ending (an empty stack, an any-hit, a visit bound) sets `finished`; a loop the
    // device cut short, or bounds run out, does not.
    if (cut || !finished) {
        overflow = true;
    }
    return t_closest;
}
