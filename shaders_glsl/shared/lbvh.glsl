// The LBVH point query: the GLSL twin of Lbvh::for_each_cluster_at in src/backend/shaders/cpu/lbvh.rs (read
// that file's documentation for how the tree is built). Written once, used by the wgpu
// backend's kernels and by the Vulkan backend's compute-traversal comparison.
//
// Node layout (8 words, 2 vec4 per node):
//     lbvh_node(2j)     = (min.xyz, uintBitsToFloat(left child))
//     lbvh_node(2j + 1) = (max.xyz, uintBitsToFloat(right child))
// A child pointer is LBVH_LEAF | c for cluster c, whose box is lbvh_box(2c) (min.xyz) and
// lbvh_box(2c + 1) (max.xyz), else the index of an internal node. Node 0 is a header: the
// w of lbvh_node(0) holds the root pointer (LBVH_NONE for an empty tree). Cluster c holds
// particles c * CLUSTER_SIZE .. min((c + 1) * CLUSTER_SIZE, field_params.counts.x).
//
// The includer defines, before this file (after rbf.glsl, whose particle_radius and
// rbf_accumulate it calls, and which needs particle_lo), the accessors of the arrays (functions rather than buffer names so
// that the wgpu backend can split an array too large for one binding over several: see
// wgpu/split.glsl; the Vulkan kernels read one buffer each):
//     vec4 particle(uint k);       // particle k
//     vec4 lbvh_node(uint v);      // vec4 number v of the nodes
//     vec4 lbvh_box(uint v);       // vec4 number v of the cluster boxes
//
// The stack holds at most one entry per internal node on the path from the root; a Karras
// tree over 30-bit keys extended by a 32-bit index is at most 62 internal nodes deep, so 64
// entries cannot overflow (the build also reports the depth, and the host checks it).

bool lbvh_contains(vec4 lo, vec4 hi, vec3 x) {
    return x.x >= lo.x && x.y >= lo.y && x.z >= lo.z && x.x <= hi.x && x.y <= hi.y && x.z <= hi.z;
}

// Adds every particle of cluster c to acc (those out of reach add nothing): their sum, then
// that to the point's (sum_add: compensated where the scene needs it).
void lbvh_visit_cluster(uint c, vec3 x, vec3 x_lo, inout vec4 acc, inout vec4 comp) {
    uint first = c * CLUSTER_SIZE;
    uint end = min(first + CLUSTER_SIZE, field_params.counts.x);
    vec4 part = vec4(0.0);
    for (uint k = first; k < end; k++) {
        vec4 p = particle(k);
        rbf_accumulate(part, x, x_lo, p, k, particle_radius(p, k));
    }
    sum_add(acc, comp, part);
}

// Visits the cluster behind leaf pointer ptr. Its box is tested first, except for single
// particles, whose own sphere test costs no more than the box test.
void lbvh_visit_leaf(uint ptr, vec3 x, vec3 x_lo, inout vec4 acc, inout vec4 comp) {
    uint c = ptr & ~LBVH_LEAF;
    if (CLUSTER_SIZE == 1u || lbvh_contains(lbvh_box(2u * c), lbvh_box(2u * c + 1u), x)) {
        lbvh_visit_cluster(c, x, x_lo, acc, comp);
    }
}

// (Phi, Theta numerator) at local position x (+ x_lo with double-single positions; the boxes
// are tested with x alone, which their padding allows): every cluster whose box contains x, its
// particles tested one by one. A node's box is tested when it is popped; inside, the left
// child is next and the right one waits on the stack. (Measured on lavapipe and not kept:
// testing children from their parent, so only nodes containing x are pushed, was slower for
// K >= 4; tracking the distance to the nearest box to skip empty space gained nothing on the
// demo scene, whose samples mostly lie inside the fluid.)
vec4 lbvh_field(vec3 x, vec3 x_lo) {
    vec4 acc = vec4(0.0);
    vec4 comp = vec4(0.0);
    uint ptr = floatBitsToUint(lbvh_node(0u).w);
    if (ptr == LBVH_NONE) {
        return acc;
    }
    uint stack[LBVH_STACK_SIZE];
    uint sp = 0u;
    for (;;) {
        if ((ptr & LBVH_LEAF) != 0u) {
            lbvh_visit_leaf(ptr, x, x_lo, acc, comp);
        } else {
            vec4 lo = lbvh_node(2u * ptr);
            vec4 hi = lbvh_node(2u * ptr + 1u);
            if (lbvh_contains(lo, hi, x)) {
                stack[sp] = floatBitsToUint(hi.w);
                sp++;
                ptr = floatBitsToUint(lo.w);
                continue;
            }
        }
        if (sp == 0u) {
            break;
        }
        sp--;
        ptr = stack[sp];
    }
    return acc;
}
