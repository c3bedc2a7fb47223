// What a compute thread knows of where it is: the entry points' one parameter, and the
// flattened indices of the host's 2D dispatch grids (src/backend/wgpu_lbvh/util.rs, grid).

struct Invocation {
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
}

// The workgroup's index in the 2D grid.
fn workgroup_index(id: Invocation) -> u32 {
    return id.wg.y * id.groups.x + id.wg.x;
}

// The thread's index, for 64-thread workgroups.
fn thread_index(id: Invocation) -> u32 {
    return workgroup_index(id) * 64u + id.lid;
}
