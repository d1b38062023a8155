// Angle-space bounds of the beam-native target, shared by beam.geom (triangles) and solid.geom (convex
// solids): the target's column and row coordinates, the extreme elevations of a great-circle arc, and the
// emission of the rectangle of beam pixels an (azimuth, elevation) box holds. Needs beam_angles.glsl first.
uniform float u_az_first;      // azimuth of column 0 relative to the centre, rad
uniform float u_daz;           // azimuth step from one column to the next (> 0, azimuth falls), rad
uniform ivec2 u_size;          // (cols, rows)
uniform sampler2D u_rows;      // (bins, 1) RG32F: per elevation bin, the first row at or below its top edge and
                               // the last row at or above its bottom edge (renderer_proc.beam_gl.row_bounds)
uniform vec2 u_bins;           // (elevation of bin 0's bottom edge, bins per rad)
uniform float u_margin;        // angular slack of every bound, rad (covers float32 round-off)

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
            float e = atan(p.y, length(p.xz));       // not asin: llvmpipe's is off by up to 3.9e-4 rad
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

// the (azimuth, elevation) box [a_lo, a_hi] x [e_lo, e_hi] as 1-2 rectangles of beam pixels, widened by
// u_margin; the part across the back seam (a = +-pi) is emitted again 2 pi away
void emit_box(float a_lo, float a_hi, float e_lo, float e_hi) {
    ivec2 rr = row_range(e_lo - u_margin, e_hi + u_margin);
    if (rr.x > rr.y) return;
    a_lo -= u_margin;
    a_hi += u_margin;
    emit_rect(a_lo, a_hi, rr.x, rr.y);
    if (a_hi > PI) emit_rect(a_lo - TWO_PI, a_hi - TWO_PI, rr.x, rr.y);
    else if (a_lo < -PI) emit_rect(a_lo + TWO_PI, a_hi + TWO_PI, rr.x, rr.y);
}

// azimuth range of the first n of a[8] (each in [-pi, pi)), points that together subtend less than pi seen from
// the origin: unwrapped across the back seam when the plain range exceeds pi
vec2 azimuth_range(float a[8], int n) {
    float lo = a[0], hi = a[0];
    for (int i = 1; i < n; ++i) { lo = min(lo, a[i]); hi = max(hi, a[i]); }
    if (hi - lo > PI) {
        lo = TWO_PI; hi = -TWO_PI;
        for (int i = 0; i < n; ++i) {
            float x = a[i] < 0.0 ? a[i] + TWO_PI : a[i];
            lo = min(lo, x); hi = max(hi, x);
        }
    }
    return vec2(lo, hi);
}

// whether the XZ projection of triangle p0 p1 p2 holds the XZ origin (a pole, +-Y, lies inside it seen from
// the origin), with a relative tolerance that only ever says yes
bool holds_pole(vec3 p0, vec3 p1, vec3 p2) {
    vec2 q0 = p0.xz, q1 = p1.xz, q2 = p2.xz;
    float w0 = q1.x * q2.y - q1.y * q2.x, w1 = q2.x * q0.y - q2.y * q0.x, w2 = q0.x * q1.y - q0.y * q1.x;
    float tol = 1e-6 * (abs(w0) + abs(w1) + abs(w2));
    return (w0 >= -tol && w1 >= -tol && w2 >= -tol) || (w0 <= tol && w1 <= tol && w2 <= tol);
}
