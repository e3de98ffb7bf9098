#version 430
// Baseline for benchmarks: the same instanced quads with a constant colour, no Gaussian.
flat in vec3 v_center;
flat in vec4 v_conic;
flat in vec3 v_color;
out vec4 frag;

void main() {
    frag = vec4(v_color * 0.5, 0.5);
}
