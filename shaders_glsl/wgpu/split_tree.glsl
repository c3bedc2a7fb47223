// The LBVH nodes and cluster boxes, in up to SPLIT_PARTS parts each, read-only: see
// wgpu/split.glsl.

// vec4 number v of the nodes (node j is vec4s 2j and 2j + 1).
#split_array lbvh_nodes 14 vec4 readonly field_params.counts.w get:lbvh_node
// vec4 number v of the cluster boxes (cluster c's box is vec4s 2c and 2c + 1).
#split_array lbvh_boxes 18 vec4 readonly field_params.counts.w get:lbvh_box
