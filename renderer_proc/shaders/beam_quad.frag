#version 330
// Beam-native pass, grain surface as quads: this pixel's beam against the quad's two triangles that
// beam_quad.geom bounded, exactly (float32): per triangle the barycentric weights are the edge planes' dot
// products over dot(d, n), each at least -u_edge (the same inclusive slack as beam.frag's Moller-Trumbore), and
// the range along the beam is t = dot(n, p0) / dot(d, n); the nearer hit wins, a miss of both is discarded.
// The renderer prepends #defines: MISHANDLED_GAMMA, OUT_RGB (location of the shaded output).
uniform sampler2D u_dirs;       // (cols, rows) RGB32F: unit beam direction of each pixel, sensor frame
uniform float u_far;            // depth scale, m: hits at or beyond it are dropped
uniform float u_edge;           // inclusive slack of the inside test, barycentric (closes cracks between triangles)
uniform vec3 u_light;           // unit vector towards the light, sensor frame (shaded output only)
flat in vec3 f_m0;
flat in vec3 f_m1;
flat in vec3 f_m2;
flat in vec3 f_m3;
flat in vec3 f_md;
flat in vec4 f_na;
flat in vec4 f_nb;
flat in vec3 f_colour;
layout(location = 0) out uvec4 o_encoded;
#ifdef OUT_RGB
layout(location = OUT_RGB) out vec4 o_rgb;
#endif

const float AMBIENT = 0.35;
const float DIFFUSE = 0.65;

// encode_range(d_m) comes from codec.glsl, which the renderer puts before this text

// range along d to the triangle of normal and plane offset n (0: culled) with edge-plane products w0 w1 w2, or
// u_far on a miss
float hit(vec4 n, float w0, float w1, float w2, vec3 d) {
    float det = dot(d, n.xyz);
    if (det == 0.0 || n.w == 0.0) return u_far;
    float inv = 1.0 / det;
    float t = n.w * inv;
    bool inside = w0 * inv >= -u_edge && w1 * inv >= -u_edge && w2 * inv >= -u_edge;
    return inside && t > 0.0 ? t : u_far;
}

void main() {
    vec3 d = texelFetch(u_dirs, ivec2(gl_FragCoord.xy), 0).xyz;
    float w0 = dot(d, f_m0), w1 = dot(d, f_m1), w2 = dot(d, f_m2), w3 = dot(d, f_m3), wd = dot(d, f_md);
    // triangle 0 1 2: edges 0 -> 1, 1 -> 2, 2 -> 0; triangle 0 2 3: edges 0 -> 2, 2 -> 3, 3 -> 0
    float ta = hit(f_na, w0, w1, -wd, d);
    float tb = hit(f_nb, wd, -w2, -w3, d);
    float t = min(ta, tb);
    if (t >= u_far) discard;
    gl_FragDepth = t / u_far;
    o_encoded = encode_range(t);
#ifdef OUT_RGB
    vec3 n = normalize(tb < ta ? f_nb.xyz : f_na.xyz);
    o_rgb = vec4(f_colour * (AMBIENT + DIFFUSE * abs(dot(n, u_light))), 1.0);
#endif
}
