#version 430
flat in vec3 v_color;
out vec4 frag;

uniform float u_alpha;

void main() {
    frag = vec4(v_color, u_alpha);
}
