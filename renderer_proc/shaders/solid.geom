#version 330
// Beam-native pass, convex solids: bound the instance's solid in angle space and emit the rectangle(s) of beam
// pixels it can cover; solid.frag intersects each of those beams with the solid exactly. The bound is that of the
// unit solid's hull box [-1, 1]^2 x [z0, 1] (a superset: exact for boxes): the azimuths of its 8 corners (it
// subtends less than pi unless its XZ projection holds the origin, then every azimuth), the elevations of its
// corners and of its 12 edges' extreme points, and the pole(s) it holds; the whole target when it holds the
// origin.
layout(points) in;
layout(triangle_strip, max_vertices = 8) out;
in mat4 v_sensor_from_unit[];
in mat3 v_unit_from_sensor[];
in vec3 v_origin[];
in vec3 v_colour[];
flat out mat3 f_unit_from_sensor;
flat out vec3 f_origin;
flat out vec3 f_colour;
uniform float u_az_centre;         // azimuth of the field's centre, rad
uniform float u_z0;                 // bottom of the unit solid's hull: -1 (cube) or 0 (prism)

const ivec2 EDGES[12] = ivec2[12](ivec2(0, 1), ivec2(2, 3), ivec2(4, 5), ivec2(6, 7), ivec2(0, 2), ivec2(1, 3),
                                  ivec2(4, 6), ivec2(5, 7), ivec2(0, 4), ivec2(1, 5), ivec2(2, 6), ivec2(3, 7));
// the 6 faces of the hull box as corner quads (corner k: x = bit 0, y = bit 1, z = bit 2)
const ivec4 FACES[6] = ivec4[6](ivec4(0, 2, 6, 4), ivec4(1, 3, 7, 5), ivec4(0, 1, 5, 4), ivec4(2, 3, 7, 6),
                                ivec4(0, 1, 3, 2), ivec4(4, 5, 7, 6));

void main() {
    f_unit_from_sensor = v_unit_from_sensor[0];
    f_origin = v_origin[0];
    f_colour = v_colour[0];
    vec3 o = v_origin[0];
    if (all(lessThanEqual(abs(o.xy), vec2(1.0))) && o.z >= u_z0 && o.z <= 1.0) {
        emit_box(-PI, PI, -0.5 * PI, 0.5 * PI);                 // the LiDAR inside the hull: every beam
        return;
    }
    vec3 p[8];
    float a[8];
    float e_lo = 10.0, e_hi = -10.0, y_lo = 1e30, y_hi = -1e30;
    for (int k = 0; k < 8; ++k) {
        vec3 u = vec3((k & 1) != 0 ? 1.0 : -1.0, (k & 2) != 0 ? 1.0 : -1.0, (k & 4) != 0 ? 1.0 : u_z0);
        p[k] = (v_sensor_from_unit[0] * vec4(u, 1.0)).xyz;
        vec2 ae = angles(p[k], u_az_centre);
        a[k] = ae.x;
        e_lo = min(e_lo, ae.y);
        e_hi = max(e_hi, ae.y);
        y_lo = min(y_lo, p[k].y);
        y_hi = max(y_hi, p[k].y);
    }
    for (int i = 0; i < 12; ++i) edge_elevation(p[EDGES[i].x], p[EDGES[i].y], e_lo, e_hi);
    bool pole = false;
    for (int f = 0; f < 6; ++f) {
        ivec4 q = FACES[f];
        pole = pole || holds_pole(p[q.x], p[q.y], p[q.z]) || holds_pole(p[q.x], p[q.z], p[q.w]);
    }
    if (pole) {                                                 // a vertical line through the origin meets it
        if (y_hi >= 0.0) e_hi = 0.5 * PI;
        if (y_lo <= 0.0) e_lo = -0.5 * PI;
        emit_box(-PI, PI, e_lo, e_hi);
    } else {
        vec2 ar = azimuth_range(a, 8);
        emit_box(ar.x, ar.y, e_lo, e_hi);
    }
}
