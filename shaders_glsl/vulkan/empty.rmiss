#version 460
// Miss: nothing to do; the payload already holds the sum.
// twin: none: it does nothing
#extension GL_EXT_ray_tracing : require

void main() {
}
