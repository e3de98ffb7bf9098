#version 430
// Strand points from card coordinates (cghair_format.geometry.strand_points) and the segment
// Gaussians' means, rotations and scales (cghair_format.gaussians.segment_frames).
// One invocation per Gaussian g = s (P-1) + i, for segment p_i -> p_i+1 of strand s; with u_indexed
// (an animated frame at a splat budget, viewer/lod.py) only the strands lod_strands[u_list_base...]
// are decoded, as the preprocess reads them. With u_turn (an animated scene turning its SH), also each
// segment's rotation from rest (cghair_format.animation.shading.segment_rotations): its card frame's
// turn at the spine sample nearest it (card_mesh), then the smallest rotation from that-turned rest
// direction to its direction now; the preprocess evaluates its SH at the view direction turned back.
layout(local_size_x = LOCAL_SIZE) in;
#include "common.glsl"

layout(std430, binding = 0) readonly buffer MeshPos { vec4 mesh_pos[]; };
layout(std430, binding = 1) readonly buffer MeshNrm { vec4 mesh_nrm[]; };
layout(std430, binding = 2) readonly buffer StrandCard { uint strand_card[]; };  // [S]
layout(std430, binding = 3) readonly buffer Uvd { float uvd[]; };                // [S*P*3]
layout(std430, binding = 4) readonly buffer Opacity { float opacity[]; };        // [G]
layout(std430, binding = 5) writeonly buffer Points { vec4 points[]; };          // [S*P] xyz
layout(std430, binding = 6) readonly buffer LodStrands { uint lod_strands[]; };  // per SH chunk, by priority
// The Gaussians as data images, texel g (viewer/decode.py GpuScene): the preprocess fetches them.
layout(rgba32f, binding = 0) uniform writeonly image2D u_means;      // xyz, opacity
layout(rgba32f, binding = 1) uniform writeonly image2D u_rotations;  // wxyz
layout(rgba32f, binding = 2) uniform writeonly image2D u_scales;     // xyz, 0
layout(rgba32f, binding = 3) uniform writeonly image2D u_turns;      // wxyz, where u_turn
// Per Gaussian, fixed at load (viewer/decode.py): its rest direction and the spine sample it turns with.
uniform sampler2D u_rest;  // xyz, k
uniform sampler2D u_card_turns;  // texel c (M+1) + k: card c's frame turn at spine sample k (card_mesh)

uniform bool u_turn;  // write u_turns (else it, u_rest and u_card_turns are bound to nothing: not read)

uniform uint u_count;       // Gaussians decoded: G, or this chunk's drawn ones where u_indexed
uniform bool u_indexed;
uniform uint u_list_base;   // where u_indexed: this chunk's first entry in lod_strands
uniform uint u_points;      // P
uniform uint u_segments;    // card segments M
uniform float u_thickness;  // d

#include "tile_texel.glsl"
#include "turn.glsl"

vec3 strand_point(uint s, uint j) {
    uint o = 3u * (s * u_points + j);
    float u = uvd[o], v = uvd[o + 1u], delta = uvd[o + 2u];
    float m = float(u_segments);
    float sv = u * m;
    float k = clamp(floor(sv), 0.0, m - 1.0);
    float f = sv - k;
    uint base = strand_card[s] * 2u * (u_segments + 1u) + 2u * uint(k);  // L_k; R_k = +1, L_k+1 = +2
    uint i0, i1, i2;
    vec3 bary;
    if (f + v > 1.0) { i0 = base + 1u; i1 = base + 3u; i2 = base + 2u; bary = vec3(1.0 - f, f + v - 1.0, 1.0 - v); }
    else { i0 = base; i1 = base + 1u; i2 = base + 2u; bary = vec3(1.0 - f - v, v, f); }
    vec3 pos = bary.x * mesh_pos[i0].xyz + bary.y * mesh_pos[i1].xyz + bary.z * mesh_pos[i2].xyz;
    vec3 nrm = bary.x * mesh_nrm[i0].xyz + bary.y * mesh_nrm[i1].xyz + bary.z * mesh_nrm[i2].xyz;
    return pos + delta * nrm / max(length(nrm), 1e-30);
}

void main() {
    uint g = global_index();
    if (g >= u_count) return;
    uint segs = u_points - 1u;
    if (u_indexed) g = lod_strands[u_list_base + g / segs] * segs + g % segs;
    uint s = g / segs;
    uint i = g % segs;
    vec3 p0 = strand_point(s, i);
    vec3 p1 = strand_point(s, i + 1u);
    points[s * u_points + i] = vec4(p0, 1.0);
    if (i == segs - 1u) points[s * u_points + i + 1u] = vec4(p1, 1.0);
    vec3 seg = p1 - p0;
    float len = length(seg);
    vec3 d = len > 0.0 ? seg / max(len, 1e-30) : vec3(0.0, 0.0, 1.0);
    float w = 1.0 + d.z;
    vec4 q = w < 1e-12 ? vec4(0.0, 1.0, 0.0, 0.0) : vec4(w, -d.y, d.x, 0.0);
    ivec2 at = texel(int(g));
    imageStore(u_means, at, vec4(0.5 * (p0 + p1), opacity[g]));
    imageStore(u_rotations, at, q / length(q));
    imageStore(u_scales, at, vec4(u_thickness, u_thickness, 0.5 * len, 0.0));
    if (u_turn) {
        vec4 rest = texelFetch(u_rest, at, 0);
        vec4 card = texelFetch(u_card_turns, texel(int(strand_card[s] * (u_segments + 1u) + uint(rest.w))), 0);
        vec3 now = len > 0.0 ? d : vec3(0.0);  // as the CPU's: no bend for a segment of zero length
        imageStore(u_turns, at, quat_mul(smallest_turn(quat_rotate(card, rest.xyz), now), card));
    }
}
