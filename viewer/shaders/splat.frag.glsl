#version 430
// The Gaussian's alpha at this pixel centre (contract step 3), premultiplied for front-to-back
// "under" blending: dst += (1 - dst.a) * (rgb * a, a).
in vec4 v_offset;
flat in vec4 v_color;
out vec4 frag;

const float ALPHA_MAX = 0.99;
const float ALPHA_MIN = 1.0 / 255.0;

void main() {
    if (max(abs(v_offset.z), abs(v_offset.w)) > 1.0) discard;
    float alpha = min(ALPHA_MAX, v_color.a * exp(-0.5 * dot(v_offset.xy, v_offset.xy)));
    if (alpha < ALPHA_MIN) discard;
    frag = vec4(v_color.rgb * alpha, alpha);
}
