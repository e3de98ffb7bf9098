#version 430
// Strand latents (cghair_format.gaussians.strand_latents): codebook weights of each strand
// (softmax of logits / temperature, or one-hot argmax) over its card group's codebook.
// One invocation per strand of the chunk [u_first, u_first + u_count).
layout(local_size_x = LATENT_LOCAL_SIZE) in;
#include "common.glsl"

layout(std430, binding = 0) readonly buffer Logits { float logits[]; };        // [S*K]
layout(std430, binding = 1) readonly buffer Codebooks { float codebooks[]; };  // [N_T*K*D]
layout(std430, binding = 2) readonly buffer StrandCard { uint strand_card[]; };
layout(std430, binding = 3) readonly buffer CardGroup { uint card_group[]; };
layout(std430, binding = 4) buffer Latents { float latents[]; };     // [chunk*D]

uniform uint u_first;
uniform uint u_count;
uniform uint u_k;
uniform uint u_d;
uniform float u_temperature;
uniform bool u_hard;

void main() {
    uint local = global_index();
    if (local >= u_count) return;
    uint s = u_first + local;
    uint group = card_group[strand_card[s]];
    uint lo = s * u_k;
    float mx = logits[lo];
    uint arg = 0u;
    for (uint k = 1u; k < u_k; ++k) {
        if (logits[lo + k] > mx) { mx = logits[lo + k]; arg = k; }
    }
    float total = 0.0;
    if (!u_hard) {
        for (uint k = 0u; k < u_k; ++k) total += exp((logits[lo + k] - mx) / u_temperature);
    }
    for (uint dd = 0u; dd < u_d; ++dd) latents[local * u_d + dd] = 0.0;
    for (uint k = 0u; k < u_k; ++k) {
        float w = u_hard ? (k == arg ? 1.0 : 0.0) : exp((logits[lo + k] - mx) / u_temperature) / total;
        if (w == 0.0) continue;
        uint cb = (group * u_k + k) * u_d;
        for (uint dd = 0u; dd < u_d; ++dd) latents[local * u_d + dd] += w * codebooks[cb + dd];
    }
}
