// Tile binning, shared by tile_count and tile_emit (included after their u_records sampler, the
// splat records written by preprocess.comp.glsl, and the u_viewport, u_tiles_x uniforms). A splat touches tile (tx, ty) when some pixel centre of the
// tile lies in both its 3-sigma support square and the oriented rectangle spanned by its
// half-axes (preprocess.comp.glsl), which contains every pixel where alpha >= 1/255: the tiles
// found by the separating-axis test below are a superset of the tiles with a visible pixel.
const uint TILE = 16u;
const uint ITEMS = 16u;  // consecutive sorted splats per invocation (a run; viewer/tiles.py RUN)

struct Footprint { ivec2 lo; ivec2 hi; vec2 m; vec2 a1; vec2 a2; };

// The tiles of the splat's bounding box (hi < lo: none) and what the per-tile test needs.
#include "tile_texel.glsl"

Footprint footprint(uint slot) {
    ivec2 at = texel(4 * int(slot));
    vec4 c = texelFetch(u_records, at, 0);  // mx, my, radius, opacity
    vec4 ax = texelFetch(u_records, at + ivec2(2, 0), 0);  // the half-axes over their squared lengths
    Footprint f;
    f.m = c.xy;
    f.a1 = ax.xy / dot(ax.xy, ax.xy);
    f.a2 = ax.zw / dot(ax.zw, ax.zw);
    vec2 ext = min(abs(f.a1) + abs(f.a2), vec2(c.z));
    // pixels k with k + 0.5 in [m - ext, m + ext], clipped to the image
    vec2 k0 = max(ceil(c.xy - ext - 0.5), vec2(0.0));
    vec2 k1 = min(floor(c.xy + ext - 0.5), u_viewport - 1.0);
    if (any(greaterThan(k0, k1))) {
        f.lo = ivec2(1);
        f.hi = ivec2(0);
    } else {
        f.lo = ivec2(k0) / int(TILE);
        f.hi = ivec2(k1) / int(TILE);
    }
    return f;
}

// Separating-axis test of the tile's pixel-centre rectangle against the oriented rectangle.
bool touches(Footprint f, ivec2 tile) {
    vec2 lo = vec2(tile * int(TILE)) + 0.5;
    vec2 hi = min(lo + float(TILE - 1u), u_viewport - 0.5);
    vec2 h = 0.5 * (hi - lo);
    vec2 d = 0.5 * (lo + hi) - f.m;
    float l1 = length(f.a1), l2 = length(f.a2);
    vec2 u1 = f.a1 / l1, u2 = f.a2 / l2;
    return abs(dot(d, u1)) <= l1 + dot(h, abs(u1)) + 1e-3 && abs(dot(d, u2)) <= l2 + dot(h, abs(u2)) + 1e-3;
}

uint tiles_touched(Footprint f) {
    uint n = 0u;
    for (int ty = f.lo.y; ty <= f.hi.y; ++ty)
        for (int tx = f.lo.x; tx <= f.hi.x; ++tx)
            if (touches(f, ivec2(tx, ty))) n += 1u;
    return n;
}
