#version 330
// Depth-in-colour encoding of the paper's Eqs 1-2 (DESIGN.md section 4), bit-for-bit the numpy reference
// renderer_proc.codec.encode_depth. The encoded target is an integer RGBA8 (RGBA8UI) renderbuffer: the shader
// writes the bytes themselves, so no float->unorm conversion, filtering or blending can touch them.
// Linear mode: the paper's x^gamma followed by the engine's inverse gamma cancel exactly, the stored bytes are
// round(255 x). Mishandled mode: nothing undoes the gamma, bytes are round(255 x^gamma).
// The renderer prepends #defines: MISHANDLED_GAMMA (compile-time, so the linear pipeline pays for no pow),
// and the optional outputs OUT_RGB, OUT_ZF with their locations.
// Planar depth comes from gl_FragCoord.w = 1 / w_clip, and w_clip = -z_view exactly (the projection's last row
// is (0, 0, -1, 0), renderer_proc.projection): the view-space z itself, interpolated with the rasteriser's own
// perspective-correct 1/w, not the depth buffer. The depth-only pass therefore reads no varying at all; the
// shaded image alone needs v_view and v_colour. The encoding is branch-free with one division per pixel (the
// period count q = Z / beta straight from 1/w): llvmpipe runs it for every 4 x 4 block a visible triangle
// covers, and it is about a quarter of a visible pixel's cost (bench/README.md, "Renderer").
uniform float u_q_per_m;        // periods of B per metre of depth: 100 / beta_cm
uniform float u_q_max;          // alpha / beta: period count at the codec's range (valid: 0 < q < u_q_max)
uniform float u_r_per_period;   // 255 beta / alpha: R counts per period of B (exactly 1.0 at alpha / beta = 255)
uniform float u_gamma;
uniform vec3 u_light;      // unit vector towards the light, GL view space
#ifdef OUT_RGB
in vec3 v_view;            // GL view-space position, m (for the face normal)
in vec3 v_colour;
#endif
layout(location = 0) out uvec4 o_encoded;
#ifdef OUT_RGB
layout(location = OUT_RGB) out vec4 o_rgb;
#endif
#ifdef OUT_ZF
layout(location = OUT_ZF) out float o_zf;
#endif

const float BYTE_MAX = 255.0;
const float AMBIENT = 0.35;   // shaded image only: ambient and diffuse shares (as renderer_proc.mock_backend)
const float DIFFUSE = 0.65;

// round half up, as codec.encode_depth's floor(x + 0.5): the conversion truncates, which is floor for x >= 0
uint quantise(float x) {          // x in [0, 1] -> round(255 x)
    return uint(x * BYTE_MAX + 0.5);
}
#ifdef MISHANDLED_GAMMA
uint r_byte(float r255) { return quantise(pow(r255 / BYTE_MAX, u_gamma)); }
uint b_byte(float x_b) { return quantise(pow(x_b, u_gamma)); }
#else
uint r_byte(float r255) { return uint(r255 + 0.5); }
uint b_byte(float x_b) { return quantise(x_b); }
#endif

void main() {
    // one quantity feeds both channels: the period count q = d / beta (d = Z in cm); x_B = frac(q),
    // 255 x_R = q * 255 beta / alpha
    float q = u_q_per_m / gl_FragCoord.w;
    bool valid = q > 0.0 && q < u_q_max;
    uint r = r_byte(min(q * u_r_per_period, BYTE_MAX));
    uvec4 enc = uvec4(r, r, b_byte(fract(q)), 255u);
    o_encoded = valid ? enc : uvec4(0u);     // out of range or behind: A = 0 and no depth bytes
#ifdef OUT_RGB
    vec3 n = normalize(cross(dFdx(v_view), dFdy(v_view)));
    float lambert = abs(dot(n, u_light));
    o_rgb = vec4(v_colour * (AMBIENT + DIFFUSE * lambert), 1.0);
#endif
#ifdef OUT_ZF
    o_zf = valid ? 1.0 / gl_FragCoord.w : uintBitsToFloat(0x7fc00000u);   // planar Z, m; NaN invalid
#endif
}
