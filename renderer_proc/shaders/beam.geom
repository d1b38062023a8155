#version 330
// Beam-native pass: bound each triangle in angle space and emit the pixel rectangle(s) that hold every beam it
// can cover (conservative); beam.frag then tests each of those beams against the triangle exactly.
// Target: pixel (col, row) is the beam of azimuth column col (azimuth falling with col, step u_daz) and
// elevation row row (elevation falling with row, bounds from the bin table u_rows). Azimuth a is measured from +Z towards -X
// (atan(-x, z)), relative to the field's centre u_az_centre; elevation e = atan(y, |xz|).
// Bounds (docs/lidar.md): a triangle that does not hold the origin spans, seen from it, the azimuths of its
// edges (each edge sweeps monotonically the shorter way between its ends, unless its XZ projection passes
// the Y axis), all azimuths when its XZ projection holds the XZ origin (a pole, +-Y, lies inside it), and the
// elevations of its corners, of each edge's extreme point of elevation where that lies inside the edge, and
// of the pole it holds. A rectangle crossing the back seam (a = +-pi) is emitted twice, 2 pi apart.
layout(triangles) in;
layout(triangle_strip, max_vertices = 8) out;     // one rectangle, two across the seam
in vec3 v_p[];
in vec3 v_colour[];
in vec2 v_ae[];                // (azimuth, elevation) of each corner, from the vertex shader
flat out vec3 f_v0;
flat out vec3 f_e1;
flat out vec3 f_e2;
flat out vec3 f_colour;
// (the target's uniforms and the bound functions: beam_bounds.glsl, inserted before this text)
uniform bool u_cull;           // closed, outward-wound solids: skip the faces turned away from the origin
uniform float u_front;         // +1 or -1: the sign of det(sensor_from_local), which flips cross products


void main() {
    vec3 p0 = v_p[0], p1 = v_p[1], p2 = v_p[2];
    vec3 e1 = p1 - p0, e2 = p2 - p0;
    float facing = dot(cross(e1, e2), p0) * u_front;            // < 0: the outward side faces the origin
    if (facing == 0.0 || (u_cull && facing > 0.0)) return;      // edge-on (or degenerate), or a back face
    f_v0 = p0; f_e1 = e1; f_e2 = e2;
    f_colour = v_colour[0];
    // elevation
    float e_lo = min(min(v_ae[0].y, v_ae[1].y), v_ae[2].y);
    float e_hi = max(max(v_ae[0].y, v_ae[1].y), v_ae[2].y);
    edge_elevation(p0, p1, e_lo, e_hi);
    edge_elevation(p1, p2, e_lo, e_hi);
    edge_elevation(p2, p0, e_lo, e_hi);
    float a_lo, a_hi;
    if (holds_pole(p0, p1, p2)) {
        // the pole the triangle holds: the sign of y where the triangle meets the Y axis (both, when unsure)
        vec3 n = cross(e1, e2);
        float y = n.y != 0.0 ? dot(n, p0) / n.y : 0.0;
        float ytol = 1e-6 * (length(p0) + length(p1) + length(p2));
        if (y >= -ytol || n.y == 0.0) e_hi = 0.5 * PI;
        if (y <= ytol || n.y == 0.0) e_lo = -0.5 * PI;
        a_lo = -PI; a_hi = PI;
    } else {
        float a[8];
        for (int i = 0; i < 3; ++i) a[i] = v_ae[i].x;
        vec2 ar = azimuth_range(a, 3);
        a_lo = ar.x;
        a_hi = ar.y;
    }
    emit_box(a_lo, a_hi, e_lo, e_hi);
}
