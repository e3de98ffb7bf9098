// Tile binning, shared by tile_count and tile_emit (included after their u_records sampler, the
// splat records written by preprocess.comp.glsl, and the u_viewport, u_tiles_x uniforms). A
// splat touches tile (tx, ty) when some pixel centre of the tile may lie in both its 3-sigma
// support square (its bounding box) and the oriented rectangle spanned by its half-axes
// (preprocess.comp.glsl), which contains every pixel where alpha >= 1/255: the tiles found below
// are a superset of the tiles with a visible pixel. TILE, RUN and RECORD_VEC4S are #defined by the
// shader loader from viewer/shader_constants.py.

struct Footprint { ivec2 lo; ivec2 hi; vec2 m; vec2 u1; vec2 u2; float l1; float l2; };

// The tiles of the splat's bounding box (hi < lo: none) and its half-axes as unit vectors and lengths.
#include "tile_texel.glsl"

Footprint footprint(uint slot) {
    ivec2 at = texel(RECORD_VEC4S * int(slot));
    vec4 c = texelFetch(u_records, at, 0);  // mx, my, radius, opacity
    vec4 ax = texelFetch(u_records, at + ivec2(2, 0), 0);  // the half-axes over their squared lengths
    Footprint f;
    f.m = c.xy;
    vec2 a1 = ax.xy / dot(ax.xy, ax.xy), a2 = ax.zw / dot(ax.zw, ax.zw);
    f.l1 = length(a1);
    f.l2 = length(a2);
    f.u1 = a1 / f.l1;
    f.u2 = a2 / f.l2;
    vec2 ext = min(abs(a1) + abs(a2), vec2(c.z));
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

// Narrows [lo, hi], the offsets x of tile centres from the splat's centre, to those whose tile
// (half-sizes HALF, hy; centre dy below the splat's) is not separated along the axis u of length l.
void axis_span(vec2 u, float l, float dy, float hy, inout float lo, inout float hi) {
    const float HALF = 0.5 * float(TILE - 1u);
    float reach = l + HALF * abs(u.x) + hy * abs(u.y) + 1e-3;
    float e = dy * u.y;
    if (abs(u.x) > 1e-6) {
        float a = (-reach - e) / u.x, b = (reach - e) / u.x;
        lo = max(lo, min(a, b));
        hi = min(hi, max(a, b));
    } else if (abs(e) > reach) {
        hi = -1e30;
    }
}

// The tiles [x, y] of row ty that the splat touches: a separating-axis test of each tile's
// pixel-centre rectangle against the oriented rectangle, solved for the whole row at once (the
// tiles of a row whose centres lie in an interval). The partial last column is tested as a whole
// tile, a superset.
ivec2 row_span(Footprint f, int ty) {
    float top = float(ty * int(TILE)) + 0.5;
    float hy = 0.5 * (min(top + float(TILE - 1u), u_viewport.y - 0.5) - top);
    float dy = top + hy - f.m.y;
    float lo = -1e30, hi = 1e30;
    axis_span(f.u1, f.l1, dy, hy, lo, hi);
    axis_span(f.u2, f.l2, dy, hy, lo, hi);
    float centre0 = 0.5 * float(TILE);  // x of the first tile's centre, in pixels (as its pixel centres')
    float x0 = clamp(ceil((f.m.x + lo - centre0) / float(TILE)), float(f.lo.x), float(f.hi.x) + 1.0);
    float x1 = clamp(floor((f.m.x + hi - centre0) / float(TILE)), float(f.lo.x) - 1.0, float(f.hi.x));
    return ivec2(int(x0), int(x1));
}

uint tiles_touched(Footprint f) {
    uint n = 0u;
    for (int ty = f.lo.y; ty <= f.hi.y; ++ty) {
        ivec2 span = row_span(f, ty);
        n += uint(max(span.y - span.x + 1, 0));
    }
    return n;
}
