#version 430
// Baseline for benchmarks: the same primitives with a constant colour, no Gaussian.
out vec4 frag;

void main() {
    frag = vec4(0.25, 0.25, 0.25, 0.5);
}
