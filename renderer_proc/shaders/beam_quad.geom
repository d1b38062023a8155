#version 330
// Beam-native pass, grain surface as quads (renderer_proc.hfmesh.SurfaceMesh.quads): bound a quad's two triangles
// (corners 0 1 2 and 0 2 3; a grid quad is split along its 0-2 diagonal as the ray caster's height field) at once
// in angle space and emit the pixel rectangle(s) of every beam either can cover (conservative, as beam.geom:
// corners, each outer edge's and the diagonal's extreme elevation, a pole either holds, the back seam);
// beam_quad.frag tests each beam against both exactly.
// Per beam the fragment needs only dot products: for an edge i -> j the plane through the origin and the edge has
// normal cross(p_i, p_j - p_i), and dot(d, that) / dot(d, n) is the barycentric weight of the corner opposite the
// edge (n the triangle's normal). A grid quad's outer edge's plane is made from its lower grid vertex, so the two
// grid quads that share it test it with the same numbers, up to sign (no crack between them); elsewhere the
// fragment's edge slack closes float32 cracks, as beam.frag's.
layout(lines_adjacency) in;
layout(triangle_strip, max_vertices = 8) out;     // one rectangle, two across the seam
in vec3 v_p[];
in vec3 v_colour[];
in vec2 v_ae[];                // (azimuth, elevation) of each corner, from the vertex shader
flat out vec3 f_m0;            // edge planes: 0 -> 1 (along a), 1 -> 2 (along b), 3 -> 2 (along a), 0 -> 3 (along b)
flat out vec3 f_m1;
flat out vec3 f_m2;
flat out vec3 f_m3;
flat out vec3 f_md;            // the diagonal 0 -> 2
flat out vec4 f_na;            // triangle 0 1 2: normal cross(p1 - p0, p2 - p0) and dot(normal, p0) (0: culled)
flat out vec4 f_nb;            // triangle 0 2 3: normal cross(p2 - p0, p3 - p0) and dot(normal, p0) (0: culled)
flat out vec3 f_colour;
// (the target's uniforms and the bound functions: beam_bounds.glsl, inserted before this text)
uniform bool u_cull;           // skip the triangles turned away from the origin
uniform float u_front;         // +1 or -1: the sign of det(sensor_from_local), which flips cross products

// the triangle's plane offset dot(n, p0), or 0 where beam.geom would skip it (edge-on, degenerate, back face)
float plane(vec3 n, vec3 p0) {
    float h = dot(n, p0);
    float facing = h * u_front;
    return (facing == 0.0 || (u_cull && facing > 0.0)) ? 0.0 : h;
}

// widen the bound by the pole triangle p0 p1 p2 (normal n) holds; whether it holds one
bool pole(vec3 p0, vec3 p1, vec3 p2, vec3 n, inout float e_lo, inout float e_hi) {
    if (!holds_pole(p0, p1, p2)) return false;
    float y = n.y != 0.0 ? dot(n, p0) / n.y : 0.0;
    float ytol = 1e-6 * (length(p0) + length(p1) + length(p2));
    if (y >= -ytol || n.y == 0.0) e_hi = 0.5 * PI;
    if (y <= ytol || n.y == 0.0) e_lo = -0.5 * PI;
    return true;
}

void main() {
    vec3 p0 = v_p[0], p1 = v_p[1], p2 = v_p[2], p3 = v_p[3];
    vec3 na = cross(p1 - p0, p2 - p0), nb = cross(p2 - p0, p3 - p0);
    float ha = plane(na, p0), hb = plane(nb, p0);
    if (ha == 0.0 && hb == 0.0) return;
    f_m0 = cross(p0, p1 - p0);
    f_m1 = cross(p1, p2 - p1);
    f_m2 = cross(p3, p2 - p3);
    f_m3 = cross(p0, p3 - p0);
    f_md = cross(p0, p2 - p0);
    f_na = vec4(na, ha);
    f_nb = vec4(nb, hb);
    f_colour = v_colour[0];
    // elevation: the corners, the four outer edges' and the diagonal's extremes
    float e_lo = min(min(v_ae[0].y, v_ae[1].y), min(v_ae[2].y, v_ae[3].y));
    float e_hi = max(max(v_ae[0].y, v_ae[1].y), max(v_ae[2].y, v_ae[3].y));
    edge_elevation(p0, p1, e_lo, e_hi);
    edge_elevation(p1, p2, e_lo, e_hi);
    edge_elevation(p2, p3, e_lo, e_hi);
    edge_elevation(p3, p0, e_lo, e_hi);
    edge_elevation(p0, p2, e_lo, e_hi);
    bool pole_a = ha != 0.0 && pole(p0, p1, p2, na, e_lo, e_hi);       // a culled triangle needs no bound
    bool pole_b = hb != 0.0 && pole(p0, p2, p3, nb, e_lo, e_hi);
    float a_lo = -PI, a_hi = PI;
    if (!pole_a && !pole_b) {
        // each triangle subtends less than pi and they share the diagonal: where the four corners' range is at
        // most pi it is the union's range, else (a quad beside the Y axis) every azimuth
        float a[8];
        for (int i = 0; i < 4; ++i) a[i] = v_ae[i].x;
        vec2 ar = azimuth_range(a, 4);
        if (ar.y - ar.x <= PI) { a_lo = ar.x; a_hi = ar.y; }
    }
    emit_box(a_lo, a_hi, e_lo, e_hi);
}
