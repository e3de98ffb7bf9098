#version 430
// The Gaussian's alpha at this pixel centre (contract step 3, same formula as the reference),
// premultiplied for front-to-back "under" blending: dst += (1 - dst.a) * (rgb * a, a).
flat in vec4 v_center;  // mean2d.xy, 1 / radius, opacity
flat in vec3 v_conic;
flat in vec3 v_color;
out vec4 frag;

const float ALPHA_MAX = 0.99;
const float ALPHA_MIN = 1.0 / 255.0;

void main() {
    vec2 d = gl_FragCoord.xy - v_center.xy;
    if (max(abs(d.x), abs(d.y)) * v_center.z > 1.0) discard;  // outside the 3-sigma square
    float power = -0.5 * (v_conic.x * d.x * d.x + v_conic.z * d.y * d.y) - v_conic.y * d.x * d.y;
    float alpha = min(ALPHA_MAX, v_center.w * exp(power));
    if (alpha < ALPHA_MIN) discard;
    frag = vec4(v_color * alpha, alpha);
}
