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
uniform float u_az_first;      // azimuth of column 0 relative to the centre, rad
uniform float u_daz;           // azimuth step from one column to the next (> 0, azimuth falls), rad
uniform ivec2 u_size;          // (cols, rows)
uniform sampler2D u_rows;      // (bins, 1) RG32F: per elevation bin, the first row at or below its top edge and
                               // the last row at or above its bottom edge (renderer_proc.beam_gl.row_bounds)
uniform vec2 u_bins;           // (elevation of bin 0's bottom edge, bins per rad)
uniform float u_margin;        // angular slack of every bound, rad (covers float32 round-off)
uniform bool u_cull;           // closed, outward-wound solids: skip the faces turned away from the origin
uniform float u_front;         // +1 or -1: the sign of det(sensor_from_local), which flips cross products


// rows r0..r1 whose elevations can lie in [e_lo, e_hi] (conservative: from the elevation bins' tables)
ivec2 row_range(float e_lo, float e_hi) {
    int bins = textureSize(u_rows, 0).x;
    float k_hi = floor((e_hi - u_bins.x) * u_bins.y), k_lo = floor((e_lo - u_bins.x) * u_bins.y);
    if (k_hi < 0.0 || k_lo >= float(bins)) return ivec2(1, 0);          // below or above every row
    int r0 = k_hi >= float(bins) ? 0 : int(texelFetch(u_rows, ivec2(int(k_hi), 0), 0).r);
    int r1 = k_lo < 0.0 ? u_size.y - 1 : int(texelFetch(u_rows, ivec2(int(k_lo), 0), 0).g);
    return ivec2(r0, r1);
}

// widen [e_lo, e_hi] by the extreme elevations of the great-circle arc a -> b where they lie inside it
void edge_elevation(vec3 a, vec3 b, inout float e_lo, inout float e_hi) {
    vec3 n = cross(a, b);
    float len = length(n);
    if (len < 1e-12 * length(a) * length(b)) return;          // degenerate: the ends bound it
    n /= len;
    float s = 1.0 - n.y * n.y;
    if (s <= 0.0) return;                                       // the arc is horizontal: constant elevation 0
    vec3 top = (vec3(0.0, 1.0, 0.0) - n.y * n) / sqrt(s);       // highest point of the great circle
    for (int k = 0; k < 2; ++k) {
        vec3 p = k == 0 ? top : -top;
        if (dot(cross(a, p), n) >= 0.0 && dot(cross(p, b), n) >= 0.0) {
            float e = asin(clamp(p.y, -1.0, 1.0));
            e_lo = min(e_lo, e);
            e_hi = max(e_hi, e);
        }
    }
}

void emit_rect(float a_lo, float a_hi, int r0, int r1) {
    // columns whose azimuth lies in [a_lo, a_hi]: col = (u_az_first - a) / u_daz
    int c0 = max(int(ceil((u_az_first - a_hi) / u_daz)), 0);
    int c1 = min(int(floor((u_az_first - a_lo) / u_daz)), u_size.x - 1);
    if (c0 > c1) return;
    // window rectangle over pixels c0..c1, r0..r1 (pixel centres at +0.5, strictly inside); NDC, row r at y = r
    vec2 lo = 2.0 * vec2(c0, r0) / vec2(u_size) - 1.0;
    vec2 hi = 2.0 * vec2(c1 + 1, r1 + 1) / vec2(u_size) - 1.0;
    gl_Position = vec4(lo.x, lo.y, 0.0, 1.0); EmitVertex();
    gl_Position = vec4(hi.x, lo.y, 0.0, 1.0); EmitVertex();
    gl_Position = vec4(lo.x, hi.y, 0.0, 1.0); EmitVertex();
    gl_Position = vec4(hi.x, hi.y, 0.0, 1.0); EmitVertex();
    EndPrimitive();
}

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
    // does the XZ projection hold the XZ origin? (then a pole lies inside the triangle, seen from the origin)
    vec2 q0 = p0.xz, q1 = p1.xz, q2 = p2.xz;
    float w0 = q1.x * q2.y - q1.y * q2.x, w1 = q2.x * q0.y - q2.y * q0.x, w2 = q0.x * q1.y - q0.y * q1.x;
    float tol = 1e-6 * (abs(w0) + abs(w1) + abs(w2));
    bool pole = (w0 >= -tol && w1 >= -tol && w2 >= -tol) || (w0 <= tol && w1 <= tol && w2 <= tol);
    float a_lo, a_hi;
    if (pole) {
        // the pole the triangle holds: the sign of y where the triangle meets the Y axis (both, when unsure)
        vec3 n = cross(e1, e2);
        float y = n.y != 0.0 ? dot(n, p0) / n.y : 0.0;
        float ytol = 1e-6 * (length(p0) + length(p1) + length(p2));
        if (y >= -ytol || n.y == 0.0) e_hi = 0.5 * PI;
        if (y <= ytol || n.y == 0.0) e_lo = -0.5 * PI;
        a_lo = -PI; a_hi = PI;
    } else {
        float a0 = v_ae[0].x, a1 = v_ae[1].x, a2 = v_ae[2].x;
        a_lo = min(min(a0, a1), a2);
        a_hi = max(max(a0, a1), a2);
        if (a_hi - a_lo > PI) {                                 // across the back seam: unwrap the negative side
            a0 += a0 < 0.0 ? TWO_PI : 0.0;
            a1 += a1 < 0.0 ? TWO_PI : 0.0;
            a2 += a2 < 0.0 ? TWO_PI : 0.0;
            a_lo = min(min(a0, a1), a2);
            a_hi = max(max(a0, a1), a2);
        }
    }
    ivec2 rr = row_range(e_lo - u_margin, e_hi + u_margin);
    int r0 = rr.x, r1 = rr.y;
    if (r0 > r1) return;
    a_lo -= u_margin;
    a_hi += u_margin;
    emit_rect(a_lo, a_hi, r0, r1);
    if (a_hi > PI) emit_rect(a_lo - TWO_PI, a_hi - TWO_PI, r0, r1);         // the part beyond the seam
    else if (a_lo < -PI) emit_rect(a_lo + TWO_PI, a_hi + TWO_PI, r0, r1);
}
