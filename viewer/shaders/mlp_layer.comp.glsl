#version 430
// One dense layer of the appearance MLP, y = act(W x + b), for a chunk of strands.
// One invocation per (group of 4 strands, group of 4 outputs): weights are stored transposed
// and padded as vec4s, w4[j * out4 + o4] = W[4 o4 .. 4 o4 + 3, j], so each input costs one vec4
// load shared by 4 strands (a 4 x 4 register tile).
layout(local_size_x = LOCAL_SIZE) in;
#include "common.glsl"

layout(std430, binding = 0) readonly buffer Input { float x[]; };     // [chunk * in]
layout(std430, binding = 1) readonly buffer Weight { vec4 w4[]; };    // [in * out4]
layout(std430, binding = 2) readonly buffer Bias { vec4 b4[]; };      // [out4]
layout(std430, binding = 3) writeonly buffer Output { float y[]; };   // [chunk * out]

uniform uint u_strands;  // strands in the chunk
uniform uint u_count;    // ceil(strands / 4) * out4
uniform uint u_in;
uniform uint u_out;
uniform uint u_out4;     // ceil(out / 4)
uniform bool u_relu;

void main() {
    uint i = global_index();
    if (i >= u_count) return;
    uint s0 = 4u * (i / u_out4);
    uint o4 = i % u_out4;
    uint rows = min(4u, u_strands - s0);
    // strands past the chunk's end read strand s0 again (in bounds) and are not written
    uint x0 = s0 * u_in;
    uint x1 = (rows > 1u ? s0 + 1u : s0) * u_in;
    uint x2 = (rows > 2u ? s0 + 2u : s0) * u_in;
    uint x3 = (rows > 3u ? s0 + 3u : s0) * u_in;
    vec4 a0 = vec4(0.0), a1 = vec4(0.0), a2 = vec4(0.0), a3 = vec4(0.0);
    for (uint j = 0u; j < u_in; ++j) {
        vec4 w = w4[j * u_out4 + o4];
        a0 += w * x[x0 + j];
        a1 += w * x[x1 + j];
        a2 += w * x[x2 + j];
        a3 += w * x[x3 + j];
    }
    vec4 b = b4[o4];
    mat4 acc = mat4(a0 + b, a1 + b, a2 + b, a3 + b);
    if (u_relu) acc = mat4(max(acc[0], 0.0), max(acc[1], 0.0), max(acc[2], 0.0), max(acc[3], 0.0));
    uint n = min(4u, u_out - 4u * o4);
    for (uint r = 0u; r < rows; ++r) {
        uint base = (s0 + r) * u_out + 4u * o4;
        for (uint k = 0u; k < n; ++k) y[base + k] = acc[r][k];
    }
}
