#version 430
// Adds the background behind the accumulated splats: rgb + (1 - alpha) * background.
// u_flip_y presents the image (row 0 at the top) on a window, whose row 0 is at the bottom.
in vec2 v_uv;
out vec4 frag;

uniform sampler2D u_accum;
uniform vec3 u_background;
uniform bool u_flip_y;

void main() {
    vec2 uv = u_flip_y ? vec2(v_uv.x, 1.0 - v_uv.y) : v_uv;
    vec4 acc = texture(u_accum, uv);
    frag = vec4(acc.rgb + (1.0 - acc.a) * u_background, acc.a);
}
