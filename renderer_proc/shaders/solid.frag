#version 330
// Beam-native pass, convex solids: this pixel's beam clipped against the instance's unit solid (slabs of the
// cube, or the prism's side planes and caps, as cosim.world.raycast does), exactly: a miss is discarded, a hit
// writes the range along the beam with the codec (codec.glsl) and depth t / u_far. The ray parameter is the
// same in the unit frame (an affine map of the sensor frame), so t is the range in m.
// The renderer prepends #defines: PRISM_SIDES (prism program), MISHANDLED_GAMMA, OUT_RGB.
uniform sampler2D u_dirs;       // (cols, rows) RGB32F: unit beam direction of each pixel, sensor frame
uniform float u_far;            // depth scale, m: hits at or beyond it are dropped
uniform vec3 u_light;           // unit vector towards the light, sensor frame (shaded output only)
flat in mat3 f_unit_from_sensor;
flat in vec3 f_origin;
flat in vec3 f_colour;
layout(location = 0) out uvec4 o_encoded;
#ifdef OUT_RGB
layout(location = OUT_RGB) out vec4 o_rgb;
#endif

const float AMBIENT = 0.35;
const float DIFFUSE = 0.65;

float t_lo = -1e30, t_hi = 1e30;
vec3 n_lo = vec3(0.0);
bool missed = false;

// clip the ray o + t d against the half-space dot(n, p) <= c
void clip(vec3 n, float c, vec3 o, vec3 d) {
    float num = c - dot(n, o), den = dot(n, d);
    if (den < 0.0) {
        float t = num / den;
        if (t > t_lo) { t_lo = t; n_lo = n; }
    } else if (den > 0.0) {
        t_hi = min(t_hi, num / den);
    } else if (num < 0.0) {
        missed = true;
    }
}

void main() {
    vec3 d = f_unit_from_sensor * texelFetch(u_dirs, ivec2(gl_FragCoord.xy), 0).xyz;
    vec3 o = f_origin;
#ifdef PRISM_SIDES
    const float STEP = 6.28318530717959 / float(PRISM_SIDES);
    float c = cos(0.5 * STEP);
    for (int k = 0; k < PRISM_SIDES; ++k) {
        float phi = STEP * (float(k) + 0.5);
        clip(vec3(cos(phi), sin(phi), 0.0), c, o, d);
    }
    clip(vec3(0.0, 0.0, 1.0), 1.0, o, d);
    clip(vec3(0.0, 0.0, -1.0), 0.0, o, d);
#else
    for (int i = 0; i < 3; ++i) {
        vec3 n = vec3(0.0);
        n[i] = 1.0;
        clip(n, 1.0, o, d);
        clip(-n, 1.0, o, d);
    }
#endif
    if (missed || t_hi < t_lo) discard;
    float t = t_lo > 0.0 ? t_lo : t_hi;          // entry, or exit when the origin is inside
    if (t <= 0.0 || t >= u_far) discard;
    gl_FragDepth = t / u_far;
    o_encoded = encode_range(t);
#ifdef OUT_RGB
    vec3 n = normalize(transpose(f_unit_from_sensor) * n_lo);
    o_rgb = vec4(f_colour * (AMBIENT + DIFFUSE * abs(dot(n, u_light))), 1.0);
#endif
}
