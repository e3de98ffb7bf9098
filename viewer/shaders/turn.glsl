// Quaternions (w, x, y, z) for turning an animated frame's SH with its segments
// (cghair_format.animation.shading.segment_rotations): the card frames' turns at the spine samples
// (card_mesh), each segment's turn from rest (decode_geometry).

vec4 quat_mul(vec4 a, vec4 b) {
    return vec4(a.x * b.x - dot(a.yzw, b.yzw), a.x * b.yzw + b.x * a.yzw + cross(a.yzw, b.yzw));
}

vec3 quat_rotate(vec4 q, vec3 v) {  // q unit
    vec3 t = 2.0 * cross(q.yzw, v);
    return v + q.x * t + cross(q.yzw, t);
}

// The smallest rotation taking unit a onto unit b; the identity where they are opposite or either is
// zero (as shading._smallest_rotation; its float64 threshold is 1e-9, float32 needs a wider one).
vec4 smallest_turn(vec3 a, vec3 b) {
    float c = dot(a, b);
    if (c <= -1.0 + 1e-6) return vec4(1.0, 0.0, 0.0, 0.0);
    vec4 q = vec4(1.0 + c, cross(a, b));
    return q / length(q);
}

// The unit quaternion of a rotation matrix (m[column][row]), from its largest diagonal term.
vec4 mat_to_quat(mat3 m) {
    float tr = m[0][0] + m[1][1] + m[2][2];
    vec4 q;
    if (tr > 0.0) {
        float s = 2.0 * sqrt(tr + 1.0);
        q = vec4(0.25 * s, (m[1][2] - m[2][1]) / s, (m[2][0] - m[0][2]) / s, (m[0][1] - m[1][0]) / s);
    } else if (m[0][0] > m[1][1] && m[0][0] > m[2][2]) {
        float s = 2.0 * sqrt(1.0 + m[0][0] - m[1][1] - m[2][2]);
        q = vec4((m[1][2] - m[2][1]) / s, 0.25 * s, (m[1][0] + m[0][1]) / s, (m[2][0] + m[0][2]) / s);
    } else if (m[1][1] > m[2][2]) {
        float s = 2.0 * sqrt(1.0 + m[1][1] - m[0][0] - m[2][2]);
        q = vec4((m[2][0] - m[0][2]) / s, (m[1][0] + m[0][1]) / s, 0.25 * s, (m[2][1] + m[1][2]) / s);
    } else {
        float s = 2.0 * sqrt(1.0 + m[2][2] - m[0][0] - m[1][1]);
        q = vec4((m[0][1] - m[1][0]) / s, (m[2][0] + m[0][2]) / s, (m[2][1] + m[1][2]) / s, 0.25 * s);
    }
    return q / length(q);
}
