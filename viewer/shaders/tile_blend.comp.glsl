#version 430
// One work group per TILE x TILE tile, of BLEND_GROUP_X (= TILE) x BLEND_GROUP_Y invocations, each
// owning BLEND_ROWS pixels of a column (viewer/shader_constants.py, per driver): on llvmpipe 16
// invocations of a 16-pixel column, so one fetch of a splat serves 16 pixels (quicker there than 4
// rows per invocation; docs/viewer.md); on GPUs 256 invocations of one pixel (whole warps).
// The tile's splats, front to back, are blended with the rendering contract's formula
// (alpha = min(0.99, o exp(-q/2)) at the pixel centre, zero below 1/255, outside the 3-sigma
// square or outside the rectangle spanned by the half-axes, which holds every alpha >= 1/255):
// C += T alpha c, T *= 1 - alpha. Each invocation first finds the rows of its column inside both
// (an interval), so the per-pixel test is two compares. A pixel stops once T < 1e-4 (its
// remaining splats could add at most 1e-4 x colour), an invocation once all its pixels have
// (T alone marks a pixel still blending: no separate flags, fewer registers to spill).
// Splat data come as texels (u_entries: the tile-sorted slots; u_records: 4 texels per slot,
// preprocess.comp.glsl): llvmpipe fetches texels as vectors but loads storage and shared memory
// one invocation at a time, which made a shared-memory batch loop many times slower there.
// Writes (C, 1 - T) to the accumulation image, row j = image row j.
// One dispatch blends at most BLEND_CHUNK entries of each tile, those after the first u_skip: Mesa's
// llvmpipe ends an invocation after 65,535 loop iterations (all its loops together), which dropped
// the back splats of denser tiles. A tile with more entries is finished by further dispatches
// (viewer/tiles.py), each resuming from the image: C as stored, T = 1 - alpha (float32 rounding of
// 1 - T adds at most 6e-8 to T, far below the early termination's 1e-4).
layout(local_size_x = BLEND_GROUP_X, local_size_y = BLEND_GROUP_Y) in;

layout(std430, binding = 1) readonly buffer Ranges { uvec2 ranges[]; };
layout(rgba32f, binding = 0) uniform image2D u_image;
uniform usampler2D u_entries;
uniform sampler2D u_records;

uniform uvec2 u_size;  // image width, height
uniform uint u_tiles_x;
uniform uint u_skip;  // entries of each tile blended by earlier dispatches

const float ALPHA_MAX = 0.99;
const float ALPHA_MIN = 1.0 / 255.0;
const float T_MIN = 1e-4;

#include "tile_texel.glsl"

// Narrows [lo, hi] to the dy with |u + dy v| <= 1 (one slab of the half-axes' rectangle).
void slab(float u, float v, inout float lo, inout float hi) {
    if (abs(v) > 1e-20) {
        float a = (-1.0 - u) / v, b = (1.0 - u) / v;
        lo = max(lo, min(a, b));
        hi = min(hi, max(a, b));
    } else if (abs(u) > 1.0) {
        hi = -1e30;
    }
}

void main() {
    uvec2 tile = gl_WorkGroupID.xy;
    uvec2 range = ranges[tile.y * u_tiles_x + tile.x];
    uint first = range.x + u_skip;
    if (u_skip > 0u && first >= range.y) return;  // finished by an earlier dispatch
    uint end = min(range.y, first + uint(BLEND_CHUNK));
    uint x = tile.x * TILE + gl_LocalInvocationID.x;
    uint y0 = tile.y * TILE;  // rows are numbered within the tile, whatever the layout: same arithmetic
    uint r0 = gl_LocalInvocationID.y * BLEND_ROWS;  // this invocation's first row
    vec3 rgb[BLEND_ROWS];
    float T[BLEND_ROWS];  // pixels outside the image start at 0: T >= T_MIN marks the pixels still blending
    float t_max = 0.0;
    for (uint k = 0u; k < BLEND_ROWS; ++k) {
        bool inside = x < u_size.x && y0 + r0 + k < u_size.y;
        vec4 was = u_skip > 0u && inside ? imageLoad(u_image, ivec2(x, y0 + r0 + k)) : vec4(0.0);
        rgb[k] = was.rgb;
        T[k] = inside ? 1.0 - was.a : 0.0;
        t_max = max(t_max, T[k]);
    }
    float px = float(x) + 0.5;
    float py0 = float(y0) + 0.5;
    for (uint i = first; i < end && t_max >= T_MIN; ++i) {
        int slot = int(texelFetch(u_entries, texel(int(i)), 0).r);
        ivec2 at = texel(RECORD_VEC4S * slot);  // a record's texels share a row
        vec4 c = texelFetch(u_records, at, 0);                   // mx, my, radius, opacity
        vec4 con = texelFetch(u_records, at + ivec2(1, 0), 0);   // conic a, b, c
        vec4 ax = texelFetch(u_records, at + ivec2(2, 0), 0);
        vec3 col = texelFetch(u_records, at + ivec2(3, 0), 0).rgb;
        float dx = px - c.x;
        // dy = py0 + r - my of this column's pixels inside the square and the rectangle
        float lo = -c.z, hi = abs(dx) <= c.z ? c.z : -1e30;
        slab(dx * ax.x, ax.y, lo, hi);
        slab(dx * ax.z, ax.w, lo, hi);
        float r_lo = lo + c.y - py0, r_hi = hi + c.y - py0;
        t_max = 0.0;
        for (uint k = 0u; k < BLEND_ROWS; ++k) {
            float r = float(r0 + k);
            float dy = py0 + r - c.y;
            bool hit = T[k] >= T_MIN && r >= r_lo && r <= r_hi;
            float power = -0.5 * (con.x * dx * dx + con.z * dy * dy) - con.y * dx * dy;
            float alpha = min(ALPHA_MAX, c.w * exp(power));
            alpha = hit && alpha >= ALPHA_MIN ? alpha : 0.0;  // selects, not branches: SIMD-friendly
            rgb[k] += T[k] * alpha * col;
            T[k] *= 1.0 - alpha;
            t_max = max(t_max, T[k]);
        }
    }
    for (uint k = 0u; k < BLEND_ROWS; ++k) {
        uint y = y0 + r0 + k;
        if (x < u_size.x && y < u_size.y) imageStore(u_image, ivec2(x, y), vec4(rgb[k], 1.0 - T[k]));
    }
}
