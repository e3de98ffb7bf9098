#version 430
// Rails and normals of every card strip vertex (cghair_format.geometry.card_mesh).
// One invocation per spine point (card c, point k): writes vertices 2(c(M+1)+k) (left) and +1 (right);
// with u_turn (an animated scene turning its SH), also the card frame's turn from rest at the point,
// F_now F_rest^T (cghair_format.animation.shading.segment_rotations), as a quaternion.
layout(local_size_x = LOCAL_SIZE) in;
#include "common.glsl"

layout(std430, binding = 0) readonly buffer Spine { vec4 spine[]; };      // [C*(M+1)] xyz
layout(std430, binding = 1) readonly buffer Normal { vec4 normal[]; };    // [C*(M+1)] xyz
layout(std430, binding = 2) readonly buffer HalfWidth { float half_width[]; };  // [C*(M+1)]
layout(std430, binding = 3) writeonly buffer MeshPos { vec4 mesh_pos[]; };  // [C*2(M+1)]
layout(std430, binding = 4) writeonly buffer MeshNrm { vec4 mesh_nrm[]; };  // [C*2(M+1)]
layout(std430, binding = 5) readonly buffer RestFrame { vec4 rest_frame[]; };  // [C*(M+1)*3] t, n, n x t
// The card frames' turns, texel i (wxyz): a data image, which decode_geometry fetches as vectors.
layout(rgba32f, binding = 0) uniform writeonly image2D u_card_turns;

uniform uint u_count;     // C * (M+1)
uniform uint u_points;    // M + 1
uniform bool u_turn;      // write u_card_turns (else it and RestFrame are bound to nothing: not used)

#include "tile_texel.glsl"
#include "turn.glsl"

vec3 safe_normalize(vec3 v) { return v / max(length(v), 1e-30); }

void main() {
    uint i = global_index();
    if (i >= u_count) return;
    uint k = i % u_points;
    uint first = i - k;
    uint last = first + u_points - 1u;
    vec3 d;
    if (k == 0u) d = spine[first + 1u].xyz - spine[first].xyz;
    else if (i == last) d = spine[last].xyz - spine[last - 1u].xyz;
    else d = spine[i + 1u].xyz - spine[i - 1u].xyz;
    vec3 t = safe_normalize(d);
    vec3 n = normal[i].xyz;
    vec3 b = safe_normalize(cross(n, t));
    vec3 c = spine[i].xyz;
    float w = half_width[i];
    mesh_pos[2u * i] = vec4(c - w * b, 1.0);
    mesh_pos[2u * i + 1u] = vec4(c + w * b, 1.0);
    mesh_nrm[2u * i] = vec4(n, 0.0);
    mesh_nrm[2u * i + 1u] = vec4(n, 0.0);
    if (u_turn) {  // the frame [t, n, n x t] of shading.spine_frames, n made normal to t
        vec3 nt = safe_normalize(n - t * dot(n, t));
        mat3 now = mat3(t, nt, cross(nt, t));
        mat3 rest = mat3(rest_frame[3u * i].xyz, rest_frame[3u * i + 1u].xyz, rest_frame[3u * i + 2u].xyz);
        imageStore(u_card_turns, texel(int(i)), mat_to_quat(now * transpose(rest)));
    }
}
