#version 330
// Beam-native pass: this pixel's beam against the triangle beam.geom bounded, exactly (Moller-Trumbore from the
// LiDAR origin, float32): a miss is discarded, a hit writes the range along the beam with the paper's codec
// (Eqs 1-2, as encode.frag) and its depth t / u_far for the nearest-hit test.
// The renderer prepends #defines: MISHANDLED_GAMMA, OUT_RGB (location of the shaded output).
uniform sampler2D u_dirs;       // (cols, rows) RGB32F: unit beam direction of each pixel, sensor frame
uniform float u_far;            // depth scale, m: hits at or beyond it are dropped
uniform float u_edge;           // inclusive slack of the inside test, barycentric (closes cracks between triangles)
uniform vec3 u_light;           // unit vector towards the light, sensor frame (shaded output only)
flat in vec3 f_v0;
flat in vec3 f_e1;
flat in vec3 f_e2;
flat in vec3 f_colour;
layout(location = 0) out uvec4 o_encoded;
#ifdef OUT_RGB
layout(location = OUT_RGB) out vec4 o_rgb;
#endif

const float AMBIENT = 0.35;
const float DIFFUSE = 0.65;

// encode_range(d_m) comes from codec.glsl, which the renderer puts before this text

void main() {
    vec3 d = texelFetch(u_dirs, ivec2(gl_FragCoord.xy), 0).xyz;
    vec3 pv = cross(d, f_e2);
    float det = dot(f_e1, pv);
    if (det == 0.0) discard;
    float inv = 1.0 / det;
    vec3 tv = -f_v0;
    float u = dot(tv, pv) * inv;
    vec3 qv = cross(tv, f_e1);
    float v = dot(d, qv) * inv;
    float t = dot(f_e2, qv) * inv;
    if (u < -u_edge || v < -u_edge || u + v > 1.0 + u_edge || t <= 0.0 || t >= u_far) discard;
    gl_FragDepth = t / u_far;
    o_encoded = encode_range(t);
#ifdef OUT_RGB
    vec3 n = normalize(cross(f_e1, f_e2));
    o_rgb = vec4(f_colour * (AMBIENT + DIFFUSE * abs(dot(n, u_light))), 1.0);
#endif
}
