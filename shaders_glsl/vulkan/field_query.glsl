// The field query of the RT pipeline (method.md §3): one ray from x along (1, 1, 1) with
// tmin = tmax = 0. A zero-length ray is what the specification allows (0 <= tmin <= tmax) and
// what lavapipe honours exactly (vulkan-setup.md): the traversal visits exactly the boxes that
// contain x, the intersection shader reports what such a box's particles add at x (at t = 0,
// inside [tmin, tmax]; particle.rint), and the any-hit shader adds it to the payload and
// ignores the hit so the traversal goes on. Non-opaque: the geometry is not opaque and the
// ray says so too, so any-hit runs for every report; no closest-hit shader exists.
//
// The includer declares `accelerationStructureEXT tlas` before this file.

layout(location = 0) rayPayloadEXT FieldPayload payload;

vec4 field_query(vec3 x) {
    payload.sum = vec4(0.0);
    payload.comp = vec4(0.0);
    traceRayEXT(tlas, gl_RayFlagsNoOpaqueEXT | gl_RayFlagsSkipClosestHitShaderEXT, 0xffu,
                0u, 0u, 0u, x, 0.0, vec3(1.0), 0.0, 0);
    return payload.sum;
}
