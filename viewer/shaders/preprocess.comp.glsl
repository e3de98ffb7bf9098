#version 430
// Per frame, per Gaussian (rendering contract steps 1-4): camera-space depth, EWA 2D covariance
// with 0.3 px^2 dilation, its inverse (conic), the 3-sigma support radius, colour from SH in the
// direction camera -> mean, and the depth sort key (culled Gaussians get the largest key). The
// splat goes to the storage buffers the raster path gathers, or to the compute rasterizer's
// record image, whichever the frame's rasterizer reads.
// Dispatched once per SH chunk: Gaussians [u_base, u_base + u_count), each written to slot g; or,
// with level of detail (viewer/lod.py), the first u_count Gaussians of the chunk's strands in
// priority order (lod_strands[u_list_base...]), written to slots u_out_base + i, with opacity and
// thickness compensated for the strands left out.
layout(local_size_x = LOCAL_SIZE) in;
#include "common.glsl"

layout(std430, binding = 4) writeonly buffer Center { vec4 center[]; };      // mx, my, z, radius
layout(std430, binding = 5) writeonly buffer Conic { vec4 conic[]; };        // a, b, c, opacity
layout(std430, binding = 6) writeonly buffer Color { vec4 color[]; };        // rgb, 1
layout(std430, binding = 7) writeonly buffer Keys { uint keys[]; };
layout(std430, binding = 8) writeonly buffer Values { uint values[]; };
layout(std430, binding = 9) readonly buffer StrandCard { uint strand_card[]; };  // for group colours
layout(std430, binding = 10) readonly buffer CardGroup { uint card_group[]; };
layout(std430, binding = 11) writeonly buffer Axes { vec4 axes[]; };  // quad half-axes, see below
layout(std430, binding = 12) buffer Visible { uint visible; };  // number of Gaussians not culled
layout(std430, binding = 13) readonly buffer LodStrands { uint lod_strands[]; };  // per chunk, by priority
// The compute rasterizer's splat records, RECORD_VEC4S texels from texel RECORD_VEC4S * slot: llvmpipe
// fetches texels as vectors, but loads storage and shared memory one invocation at a time.
layout(rgba32f, binding = 1) uniform writeonly image2D u_records;
// The Gaussians, texel g (xyz and opacity; wxyz; scales), and this chunk's SH coefficients,
// Gaussian i's 3 C floats from texel i * u_sh_texels (viewer/decode.py): data images, which
// llvmpipe fetches as vectors, while it loads storage one invocation and component at a time.
uniform sampler2D u_means;
uniform sampler2D u_rotations;
uniform sampler2D u_scales;
uniform sampler2D u_sh;
// An animated frame's segment rotations from rest, texel g (wxyz, decode_geometry), where u_turn_sh:
// the SH turned by R give at view direction v the colour the rest SH give at R^T v (exact: each band
// turns within itself), so the view direction is turned back instead of the 16 coefficients forward.
uniform sampler2D u_turns;
uniform bool u_turn_sh;

uniform uint u_base;
uniform uint u_count;
uniform mat3 u_rot;          // world-to-camera rotation
uniform vec3 u_trans;        // world-to-camera translation
uniform vec3 u_cam_center;   // camera centre in world space
uniform vec4 u_intrinsics;   // fx, fy, cx, cy
uniform vec2 u_viewport;     // width, height in pixels
uniform uint u_sh_texels;    // texels per Gaussian in u_sh
uniform int u_degree;        // SH degree to evaluate, <= stored degree
uniform float u_scale;       // splat scale multiplier (1 = as stored)
uniform int u_color_mode;    // 0: SH colour, 1: colour by card group
uniform uint u_segments;     // Gaussians per strand, P - 1
uniform bool u_indexed;      // level of detail: Gaussians through lod_strands, compacted slots
uniform uint u_list_base;    // this chunk's first entry in lod_strands
uniform uint u_out_base;     // this chunk's first output slot
uniform float u_lod_opacity; // drawn strands' opacity o -> 1 - (1 - o)^u_lod_opacity (1: as stored)
uniform float u_lod_width;   // drawn strands' thickness (scales x, y) multiplier (1: as stored)
uniform bool u_write_records; // write u_records (compute rasterizer)
uniform bool u_write_buffers; // write center, conic, axes, color (raster path)

const float NEAR_PLANE = 0.01;
const float DILATION = 0.3;
const float SIGMA_SUPPORT = 3.0;
const float ALPHA_MIN = 1.0 / 255.0;
const float SH_C0 = 0.28209479177387814;
const float SH_C1 = 0.4886025119029199;
const float SH_C2[5] = float[](1.0925484305920792, -1.0925484305920792, 0.31539156525252005,
                               -1.0925484305920792, 0.5462742152960396);
const float SH_C3[7] = float[](-0.5900435899266435, 2.890611442640554, -0.4570457994644658,
                               0.3731763325901154, -0.4570457994644658, 1.445305721320277,
                               -0.5900435899266435);

#include "tile_texel.glsl"

// The coefficients' floats as texels: sh[k] holds floats 4k .. 4k + 3 of the Gaussian's 3 C.
vec4 sh[12];

vec3 coeff(uint j) {  // j is a constant once unrolled, so the selects below are resolved at compile time
    uint o = 3u * j, r = o % 4u;
    vec4 a = sh[o / 4u], b = sh[(o + 2u) / 4u];
    return r == 0u ? a.xyz : r == 1u ? a.yzw : r == 2u ? vec3(a.zw, b.x) : vec3(a.w, b.xy);
}

// Fetches texels [lo, hi) of the Gaussian's coefficients: each degree only the texels it reads.
void fetch_sh(int base, int lo, int hi) {
    for (int k = lo; k < hi; ++k) sh[k] = texelFetch(u_sh, texel(base + k), 0);
}

vec3 eval_sh(int base, vec3 dir) {
    fetch_sh(base, 0, 1);
    vec3 res = SH_C0 * coeff(0u);
    if (u_degree > 0) {
        fetch_sh(base, 1, 3);
        float x = dir.x, y = dir.y, z = dir.z;
        res = res - SH_C1 * y * coeff(1u) + SH_C1 * z * coeff(2u) - SH_C1 * x * coeff(3u);
        if (u_degree > 1) {
            fetch_sh(base, 3, 7);
            float xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
            res = res + SH_C2[0] * xy * coeff(4u) + SH_C2[1] * yz * coeff(5u)
                + SH_C2[2] * (2.0 * zz - xx - yy) * coeff(6u) + SH_C2[3] * xz * coeff(7u)
                + SH_C2[4] * (xx - yy) * coeff(8u);
            if (u_degree > 2) {
                fetch_sh(base, 7, 12);
                res = res + SH_C3[0] * y * (3.0 * xx - yy) * coeff(9u)
                    + SH_C3[1] * xy * z * coeff(10u)
                    + SH_C3[2] * y * (4.0 * zz - xx - yy) * coeff(11u)
                    + SH_C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy) * coeff(12u)
                    + SH_C3[4] * x * (4.0 * zz - xx - yy) * coeff(13u)
                    + SH_C3[5] * z * (xx - yy) * coeff(14u)
                    + SH_C3[6] * x * (xx - 3.0 * yy) * coeff(15u);
            }
        }
    }
    return max(res + 0.5, 0.0);
}

vec3 group_color(uint group) {
    // a hash that spreads consecutive groups over distinct hues
    uint h = group * 2654435761u;
    return vec3(float((h >> 8) & 255u), float((h >> 16) & 255u), float((h >> 24) & 255u)) / 255.0 * 0.8 + 0.2;
}

mat3 quat_to_mat(vec4 q) {
    q = q / max(length(q), 1e-12);
    float w = q.x, x = q.y, y = q.z, z = q.w;
    // GLSL matrices are column-major: each vec3 below is a column
    return mat3(
        1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y),
        2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + w * x),
        2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y));
}

void main() {
    uint local = global_index();
    if (local >= u_count) return;
    uint g = u_base + local, slot = g;
    if (u_indexed) {
        g = lod_strands[u_list_base + local / u_segments] * u_segments + local % u_segments;
        slot = u_out_base + local;
    }
    ivec2 at = texel(int(g));
    vec4 mo = texelFetch(u_means, at, 0);
    if (u_lod_opacity != 1.0) mo.w = 1.0 - pow(max(1.0 - mo.w, 0.0), u_lod_opacity);
    vec3 t = u_rot * mo.xyz + u_trans;
    values[slot] = slot;
    if (t.z <= NEAR_PLANE) {
        keys[slot] = 0xFFFFFFFFu;
        if (u_write_buffers) center[slot] = vec4(0.0);
        return;
    }
    float fx = u_intrinsics.x, fy = u_intrinsics.y;
    vec3 sc = texelFetch(u_scales, at, 0).xyz * u_scale * vec3(u_lod_width, u_lod_width, 1.0);
    mat3 m = quat_to_mat(texelFetch(u_rotations, at, 0)) * mat3(sc.x, 0.0, 0.0, 0.0, sc.y, 0.0, 0.0, 0.0, sc.z);
    // J as a 3x2 (3 columns, 2 rows) matrix
    mat3x2 jac = mat3x2(fx / t.z, 0.0, 0.0, fy / t.z, -fx * t.x / (t.z * t.z), -fy * t.y / (t.z * t.z));
    mat3x2 a = jac * u_rot * m;
    mat2 cov = a * transpose(a);
    float ca = cov[0][0] + DILATION, cb = cov[0][1], cc = cov[1][1] + DILATION;
    float det = ca * cc - cb * cb;
    float mid = 0.5 * (ca + cc);
    float lam = mid + sqrt(max(mid * mid - det, 0.0));
    float radius = ceil(SIGMA_SUPPORT * sqrt(lam));
    vec2 m2 = vec2(fx * t.x / t.z + u_intrinsics.z, fy * t.y / t.z + u_intrinsics.w);
    bool offscreen = m2.x + radius < 0.0 || m2.x - radius > u_viewport.x
        || m2.y + radius < 0.0 || m2.y - radius > u_viewport.y;
    if (offscreen || !(det > 0.0) || mo.w < ALPHA_MIN) {
        keys[slot] = 0xFFFFFFFFu;
        if (u_write_buffers) center[slot] = vec4(0.0);
        return;
    }
    keys[slot] = floatBitsToUint(t.z);  // positive floats order like their bit patterns
    atomicAdd(visible, 1u);
    // The primitive's half-axes (a triangle circumscribes the unit disc in these units; a quad
    // is the unit square): alpha >= 1/255 only inside the ellipse q <= 2 ln(255 o), whose
    // half-axes are sqrt(q lambda) along the eigenvectors; thin hair splats cover far fewer
    // pixels than the 3-sigma square. Otherwise the disc around the support square (half-axes
    // sqrt(2) (r + 1/2)). The fragment shader applies the exact square and alpha tests.
    // Cancellation-free forms: lambda1 - lambda2 from (ca - cc, cb), lambda2 = det / lambda1.
    float q = 2.0 * log(mo.w / ALPHA_MIN) * 1.0001 + 1e-4;
    float lam1 = mid + sqrt(0.25 * (ca - cc) * (ca - cc) + cb * cb);
    float lam2 = det / lam1;
    vec2 v1 = ca >= cc ? vec2(lam1 - cc, cb) : vec2(cb, lam1 - ca);
    v1 = dot(v1, v1) > 0.0 ? normalize(v1) : vec2(1.0, 0.0);
    float e1 = sqrt(q * lam1) * 1.0001 + 0.01, e2 = sqrt(q * lam2) * 1.0001 + 0.01;
    float disc = 1.41421357 * (radius + 0.5);
    vec4 ax = e1 * e2 < disc * disc ? vec4(v1 * e1, vec2(-v1.y, v1.x) * e2) : vec4(disc, 0.0, 0.0, disc);
    vec3 rgb;
    if (u_color_mode == 1) rgb = group_color(card_group[strand_card[g / u_segments]]);
    else {
        vec3 view = normalize(mo.xyz - u_cam_center);
        if (u_turn_sh) view = view * quat_to_mat(texelFetch(u_turns, at, 0));  // R^T v
        rgb = eval_sh(int((g - u_base) * u_sh_texels), view);
    }
    if (u_write_buffers) {
        center[slot] = vec4(m2, t.z, radius);
        conic[slot] = vec4(cc / det, -cb / det, ca / det, mo.w);
        axes[slot] = ax;
        color[slot] = vec4(rgb, 1.0);
    }
    if (u_write_records) {
        // (mx, my, radius, opacity), conic, the half-axes over their squared lengths (|dot(d, .)|
        // <= 1 inside the rectangle they span), colour
        int k = int(RECORD_VEC4S * slot);  // a record's texels share a row
        imageStore(u_records, texel(k), vec4(m2, radius, mo.w));
        imageStore(u_records, texel(k + 1), vec4(cc / det, -cb / det, ca / det, 0.0));
        imageStore(u_records, texel(k + 2), vec4(ax.xy / dot(ax.xy, ax.xy), ax.zw / dot(ax.zw, ax.zw)));
        imageStore(u_records, texel(k + 3), vec4(rgb, 0.0));
    }
}
