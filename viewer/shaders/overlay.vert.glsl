#version 430
// Overlays (strands as lines, card strips as triangles): world points from a storage buffer,
// projected with the same pinhole camera as the splats. u_mode 0: strand lines (gl_VertexID
// enumerates segment end points); 1: card mesh vertices (indexed draw).
layout(std430, binding = 0) readonly buffer Points { vec4 points[]; };
layout(std430, binding = 1) readonly buffer Groups { uint groups[]; };  // per strand or per card

uniform mat4 u_view;         // world-to-camera
uniform mat4 u_projection;   // camera (OpenCV) to clip, image row j at framebuffer row j
uniform int u_mode;
uniform uint u_points;       // P (mode 0) or 2(M+1) (mode 1): points per strand or per card
uniform bool u_by_group;

flat out vec3 v_color;

vec3 group_color(uint group) {
    uint h = group * 2654435761u;
    return vec3(float((h >> 8) & 255u), float((h >> 16) & 255u), float((h >> 24) & 255u)) / 255.0 * 0.8 + 0.2;
}

void main() {
    uint index;
    if (u_mode == 0) {
        uint seg = uint(gl_VertexID) >> 1;
        uint segs = u_points - 1u;
        index = seg + seg / segs + (uint(gl_VertexID) & 1u);
    } else {
        index = uint(gl_VertexID);
    }
    uint owner = index / u_points;
    v_color = u_by_group ? group_color(groups[owner]) : (u_mode == 0 ? vec3(0.9, 0.8, 0.3) : vec3(0.3, 0.7, 1.0));
    gl_Position = u_projection * u_view * vec4(points[index].xyz, 1.0);
}
