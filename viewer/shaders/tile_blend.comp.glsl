#version 430
// One work group per 16 x 16 tile: the tile's splats, front to back, are loaded BATCH at a time
// into shared memory and blended with the rendering contract's formula (alpha = min(0.99,
// o exp(-q/2)) at the pixel centre, skipped below 1/255 or outside the 3-sigma square):
// C += T alpha c, T *= 1 - alpha. Each invocation owns a column of ROWS pixels, so one read of
// a splat from shared memory serves ROWS pixels. A pixel stops once T < 1e-4 (its remaining
// splats could add at most 1e-4 x colour); the group stops when all its pixels have. Writes
// (C, 1 - T) to the accumulation image, row j = image row j.
layout(local_size_x = 16, local_size_y = 4) in;

layout(std430, binding = 0) readonly buffer TileValues { uint tile_values[]; };
layout(std430, binding = 1) readonly buffer Ranges { uvec2 ranges[]; };
layout(std430, binding = 2) readonly buffer Center { vec4 center[]; };  // mx, my, z, radius
layout(std430, binding = 3) readonly buffer Conic { vec4 conic[]; };    // a, b, c, opacity
layout(std430, binding = 4) readonly buffer Color { vec4 color[]; };
layout(std430, binding = 5) readonly buffer Axes { vec4 axes[]; };
layout(rgba32f, binding = 0) uniform writeonly image2D u_image;

uniform uvec2 u_size;  // image width, height
uniform uint u_tiles_x;

const float ALPHA_MAX = 0.99;
const float ALPHA_MIN = 1.0 / 255.0;
const float T_MIN = 1e-4;
const uint THREADS = 64u;
const uint ROWS = 4u;          // pixels per invocation: rows y, y + 4, y + 8, y + 12 of the tile
const uint BATCH = THREADS;

shared vec4 s_center[BATCH];  // mx, my, radius, opacity
shared vec4 s_conic[BATCH];   // a, b, c
shared vec4 s_axes[BATCH];    // half-axes a1 / |a1|^2, a2 / |a2|^2: |dot(d, .)| <= 1 inside
shared vec4 s_color[BATCH];
shared uint s_done;

void main() {
    uint t = gl_LocalInvocationIndex;
    uvec2 tile = gl_WorkGroupID.xy;
    uvec2 range = ranges[tile.y * u_tiles_x + tile.x];
    uint x = tile.x * 16u + gl_LocalInvocationID.x;
    vec3 rgb[ROWS];
    float T[ROWS];
    bool live[ROWS];
    uint left = 0u;  // this invocation's pixels still blending
    for (uint r = 0u; r < ROWS; ++r) {
        rgb[r] = vec3(0.0);
        T[r] = 1.0;
        live[r] = x < u_size.x && tile.y * 16u + gl_LocalInvocationID.y + 4u * r < u_size.y;
        if (live[r]) left += 1u;
    }
    if (t == 0u) s_done = 0u;
    barrier();
    if (left == 0u) atomicAdd(s_done, 1u);
    float px = float(x) + 0.5;
    float py0 = float(tile.y * 16u + gl_LocalInvocationID.y) + 0.5;
    for (uint base = range.x; base < range.y; base += BATCH) {
        barrier();
        if (s_done == THREADS) break;  // read by all after the barrier: a uniform decision
        if (base + t < range.y) {
            uint slot = tile_values[base + t];
            vec4 c = center[slot];
            vec4 con = conic[slot];
            vec4 ax = axes[slot];
            s_center[t] = vec4(c.xy, c.w, con.w);
            s_conic[t] = con;
            s_axes[t] = vec4(ax.xy / dot(ax.xy, ax.xy), ax.zw / dot(ax.zw, ax.zw));
            s_color[t] = color[slot];
        }
        barrier();
        uint n = min(BATCH, range.y - base);
        for (uint j = 0u; j < n && left > 0u; ++j) {
            vec4 c = s_center[j];
            vec4 ax = s_axes[j];
            vec4 con = s_conic[j];
            vec3 col = s_color[j].rgb;
            float dx = px - c.x;
            for (uint r = 0u; r < ROWS; ++r) {
                float dy = py0 + 4.0 * float(r) - c.y;
                // inside the oriented rectangle around the alpha >= 1/255 ellipse and the square
                bool hit = live[r] && abs(dx * ax.x + dy * ax.y) <= 1.0 && abs(dx * ax.z + dy * ax.w) <= 1.0
                    && max(abs(dx), abs(dy)) <= c.z;
                if (!hit) continue;
                float power = -0.5 * (con.x * dx * dx + con.z * dy * dy) - con.y * dx * dy;
                float alpha = min(ALPHA_MAX, c.w * exp(power));
                if (alpha < ALPHA_MIN) continue;
                rgb[r] += T[r] * alpha * col;
                T[r] *= 1.0 - alpha;
                if (T[r] < T_MIN) {
                    live[r] = false;
                    left -= 1u;
                    if (left == 0u) atomicAdd(s_done, 1u);
                }
            }
        }
    }
    for (uint r = 0u; r < ROWS; ++r) {
        uint y = tile.y * 16u + gl_LocalInvocationID.y + 4u * r;
        if (x < u_size.x && y < u_size.y) imageStore(u_image, ivec2(x, y), vec4(rgb[r], 1.0 - T[r]));
    }
}
