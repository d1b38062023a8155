#version 330
// Beam-native pass, convex solids: bound the instance's solid in angle space and emit the rectangle(s) of beam
// pixels it can cover; solid.frag clips each of those beams against the WHOLE solid exactly, so any set of
// rectangles whose union covers the solid's silhouette gives the same image (a beam covered twice writes the
// same range). The bound is that of the unit solid's hull box [-1, 1]^2 x [z0, 1] (a superset: exact for
// boxes), cut into slices along its longest edge where that shrinks the rectangles (a long thin box seen
// diagonally): per piece, the azimuths of its 8 corners (a piece subtends less than pi unless its XZ projection
// holds the origin, then every azimuth), the elevations of its corners and of its 12 edges' extreme points, and
// the pole(s) it holds; the whole target when the hull holds the origin. A box whose top face other parts cover
// (u_open_top, Boxes.hidden_top) seen from above its top plane is bounded by its front side faces alone: a beam
// that enters through the top meets the covering part first (or at the same range), one that enters otherwise
// enters through a side face the origin is outside of. The renderer prepends #defines: MAX_RECTS (rectangles
// one solid may emit: one per piece, two across the back seam; 2 = unsliced), MAX_VERTICES (4 per rectangle),
// SLICE_COST_PX (one more slice's cost in fragments), OUT_RGB. With MAX_RECTS 2 the slicing code is left out
// of the source: NVIDIA's GLSL compiler (driver 580) crashes on the slicing loop, even where MAX_RECTS makes it
// dead code.
layout(points) in;
layout(triangle_strip, max_vertices = MAX_VERTICES) out;
in mat4 v_sensor_from_unit[];
in mat3 v_unit_from_sensor[];
in vec3 v_origin[];
in vec3 v_colour[];
flat out mat3 f_unit_from_sensor;
flat out vec3 f_origin;
#ifdef OUT_RGB
flat out vec3 f_colour;
#endif
uniform float u_az_centre;         // azimuth of the field's centre, rad
uniform float u_z0;                 // bottom of the unit solid's hull: -1 (cube) or 0 (prism)
uniform vec2 u_pitch;               // (column, mean row) spacing of the beams, rad: one pixel of a rectangle
uniform bool u_open_top;            // the boxes' top faces are covered by other parts (cube only)

const ivec2 EDGES[12] = ivec2[12](ivec2(0, 1), ivec2(2, 3), ivec2(4, 5), ivec2(6, 7), ivec2(0, 2), ivec2(1, 3),
                                  ivec2(4, 6), ivec2(5, 7), ivec2(0, 4), ivec2(1, 5), ivec2(2, 6), ivec2(3, 7));
// the 6 faces of a piece as corner quads (corner k: axis 0 = bit 0, axis 1 = bit 1, axis 2 = bit 2)
const ivec4 FACES[6] = ivec4[6](ivec4(0, 2, 6, 4), ivec4(1, 3, 7, 5), ivec4(0, 1, 5, 4), ivec4(2, 3, 7, 6),
                                ivec4(0, 1, 3, 2), ivec4(4, 5, 7, 6));

// the (azimuth, elevation) bound [x, y] x [z, w] of the parallelepiped c + s u + t v + r w (s, t, r in [0, 1];
// sensor frame; w may be zero: a face), which must not hold the origin
vec4 piece_bound(vec3 c, vec3 u, vec3 v, vec3 w) {
    vec3 p[8];
    float a[8];
    float e_lo = 10.0, e_hi = -10.0, y_lo = 1e30, y_hi = -1e30;
    for (int k = 0; k < 8; ++k) {
        p[k] = c + ((k & 1) != 0 ? u : vec3(0.0)) + ((k & 2) != 0 ? v : vec3(0.0)) + ((k & 4) != 0 ? w : vec3(0.0));
        vec2 ae = angles(p[k], u_az_centre);
        a[k] = ae.x;
        e_lo = min(e_lo, ae.y);
        e_hi = max(e_hi, ae.y);
        y_lo = min(y_lo, p[k].y);
        y_hi = max(y_hi, p[k].y);
    }
    for (int i = 0; i < 12; ++i) edge_elevation(p[EDGES[i].x], p[EDGES[i].y], e_lo, e_hi);
    bool pole = false;
    for (int f = w == vec3(0.0) ? 4 : 0; f < 6; ++f) {        // a face (w = 0): its own quad, not the 4 collapsed
        ivec4 q = FACES[f];
        pole = pole || holds_pole(p[q.x], p[q.y], p[q.z]) || holds_pole(p[q.x], p[q.z], p[q.w]);
    }
    if (pole) {                                                 // a vertical line through the origin meets it
        if (y_hi >= 0.0) e_hi = 0.5 * PI;
        if (y_lo <= 0.0) e_lo = -0.5 * PI;
        return vec4(-PI, PI, e_lo, e_hi);
    }
    return vec4(azimuth_range(a, 8), e_lo, e_hi);
}

// slices along u that make the rectangles of the piece (c, u, v, w) with bound b smallest: its ends' centres
// are da, de apart in angle, its cross-section spans about wa x we (the rest of b, plus a pixel); n slices cover
// n (da / n + wa)(de / n + we), least at n = sqrt(da de / (wa we)). A piece around a pole: by the length ratio.
int slices(vec3 c, vec3 u, vec3 v, vec3 w, vec4 b, int most) {
    if (most <= 1) return 1;
    float n;
    if (b.y - b.x >= TWO_PI) {
        n = ceil(length(u) / max(max(length(v), length(w)), 1e-6));
    } else {
        vec3 mid = c + 0.5 * (v + w);
        vec2 e0 = angles(mid, u_az_centre), e1 = angles(mid + u, u_az_centre);
        float da = abs(wrap(e1.x - e0.x)), de = abs(e1.y - e0.y);
        float wa = max(b.y - b.x - da, 0.0) + u_pitch.x, we = max(b.w - b.z - de, 0.0) + u_pitch.y;
        n = floor(sqrt(da * de / (wa * we + SLICE_COST_PX * u_pitch.x * u_pitch.y)) + 0.5);
    }
    return int(clamp(n, 1.0, float(most)));
}

// rectangles emit_box makes of the bound b: two when it crosses the back seam
int rects(vec4 b) {
    return b.y + u_margin > PI || b.x - u_margin < -PI ? 2 : 1;
}

void emit_bound(vec4 b) {
    emit_box(b.x, b.y, b.z, b.w);
}

// the piece (c, u, v, w) in slices along u, each bounded and emitted on its own, in at most `budget` (>= 2)
// rectangles: when the next slice would leave fewer than 2, the rest goes as one piece
void emit_slices(vec3 c, vec3 u, vec3 v, vec3 w, int budget) {
    vec4 b = piece_bound(c, u, v, w);
#if MAX_RECTS <= 2                                          // unsliced: the loop below is not compiled at all
    emit_bound(b);
}
#else
    int n = slices(c, u, v, w, b, budget - 1);
    if (n == 1) {
        emit_bound(b);
        return;
    }
    vec3 step = u / float(n);
    int used = 0;
    for (int i = 0; i < n; ++i) {
        vec3 start = c + float(i) * step;
        b = piece_bound(start, step, v, w);
        if (i < n - 1 && used + rects(b) > budget - 2) {
            emit_bound(piece_bound(start, float(n - i) * step, v, w));
            return;
        }
        emit_bound(b);
        used += rects(b);
    }
}
#endif

void main() {
    f_unit_from_sensor = v_unit_from_sensor[0];
    f_origin = v_origin[0];
#ifdef OUT_RGB
    f_colour = v_colour[0];
#endif
    vec3 o = v_origin[0];
    mat4 m = v_sensor_from_unit[0];
#if MAX_RECTS >= 4                                          // 2 faces of at least 2 rectangles each
    if (u_open_top && o.z > 1.0) {
        // seen from above the covered top: only the side faces the origin is outside of can be entered
        vec3 ax = m[0].xyz, ay = m[1].xyz, az = m[2].xyz, c = m[3].xyz;
        if (abs(o.x) > 1.0) {                                   // the face x = sign(o.x)
            vec3 f = c + sign(o.x) * ax - ay - az;
            if (length(ay) >= length(az)) emit_slices(f, 2.0 * ay, 2.0 * az, vec3(0.0), MAX_RECTS / 2);
            else emit_slices(f, 2.0 * az, 2.0 * ay, vec3(0.0), MAX_RECTS / 2);
        }
        if (abs(o.y) > 1.0) {                                   // the face y = sign(o.y)
            vec3 f = c + sign(o.y) * ay - ax - az;
            if (length(ax) >= length(az)) emit_slices(f, 2.0 * ax, 2.0 * az, vec3(0.0), MAX_RECTS / 2);
            else emit_slices(f, 2.0 * az, 2.0 * ax, vec3(0.0), MAX_RECTS / 2);
        }
        return;
    }
#endif
    if (all(lessThanEqual(abs(o.xy), vec2(1.0))) && o.z >= u_z0 && o.z <= 1.0) {
        emit_box(-PI, PI, -0.5 * PI, 0.5 * PI);                 // the LiDAR inside the hull: every beam
        return;
    }
    // the hull: corner c, edges along the unit axes; sliced along its longest edge in the sensor frame
    vec3 c = (m * vec4(-1.0, -1.0, u_z0, 1.0)).xyz;
    vec3 e[3] = vec3[3](2.0 * m[0].xyz, 2.0 * m[1].xyz, (1.0 - u_z0) * m[2].xyz);
    int i = length(e[0]) >= length(e[1]) ? 0 : 1;
    if (length(e[2]) > length(e[i])) i = 2;
    emit_slices(c, e[i], e[(i + 1) % 3], e[(i + 2) % 3], MAX_RECTS);
}
