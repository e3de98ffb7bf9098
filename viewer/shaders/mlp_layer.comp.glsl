#version 430
// One dense layer of the appearance MLP: y = act(W x + b) for a chunk of strands.
// One invocation per (strand, output) pair; W is row-major [out, in].
layout(local_size_x = 256) in;
#include "common.glsl"

layout(std430, binding = 0) readonly buffer Input { float x[]; };     // [chunk*in]
layout(std430, binding = 1) readonly buffer Weight { float w[]; };    // [out*in]
layout(std430, binding = 2) readonly buffer Bias { float b[]; };      // [out]
layout(std430, binding = 3) writeonly buffer Output { float y[]; };   // [chunk*out]

uniform uint u_count;  // chunk * out
uniform uint u_in;
uniform uint u_out;
uniform bool u_relu;

void main() {
    uint i = global_index();
    if (i >= u_count) return;
    uint s = i / u_out;
    uint o = i % u_out;
    float acc = 0.0;
    uint xo = s * u_in, wo = o * u_in;
    for (uint j = 0u; j < u_in; ++j) acc += w[wo + j] * x[xo + j];
    acc += b[o];
    y[i] = u_relu ? max(acc, 0.0) : acc;
}
