#version 330
// Depth-in-colour encoding of the paper's Eqs 1-2 (DESIGN.md section 4), bit-for-bit the numpy reference
// renderer_proc.codec.encode_depth. The encoded target is an integer RGBA8 (RGBA8UI) renderbuffer: the shader
// writes the bytes themselves, so no float->unorm conversion, filtering or blending can touch them.
// Linear mode: the paper's x^gamma followed by the engine's inverse gamma cancel exactly, the stored bytes are
// round(255 x). Mishandled mode: nothing undoes the gamma, bytes are round(255 x^gamma).
// The renderer prepends #defines: MISHANDLED_GAMMA (compile-time, so the linear pipeline pays for no pow),
// and the optional outputs OUT_RGB, OUT_ZF with their locations.
uniform float u_alpha_cm;
uniform float u_beta_cm;
uniform float u_r_per_period;   // 255 beta / alpha: R counts per period of B (exactly 1.0 at alpha / beta = 255)
uniform float u_gamma;
uniform vec3 u_light;      // unit vector towards the light, GL view space
in vec3 v_view;
in vec3 v_colour;
layout(location = 0) out uvec4 o_encoded;
#ifdef OUT_RGB
layout(location = OUT_RGB) out vec4 o_rgb;
#endif
#ifdef OUT_ZF
layout(location = OUT_ZF) out float o_zf;
#endif

const float CM_PER_M = 100.0;
const float BYTE_MAX = 255.0;
const float AMBIENT = 0.35;   // shaded image only: ambient and diffuse shares (as renderer_proc.mock_backend)
const float DIFFUSE = 0.65;

uint quantise(float x) {          // x in [0, 1] -> round(255 x), half up as codec.encode_depth
    return uint(floor(x * BYTE_MAX + 0.5));
}
#ifdef MISHANDLED_GAMMA
uint r_byte(float r255) { return quantise(pow(r255 / BYTE_MAX, u_gamma)); }
uint b_byte(float x_b) { return quantise(pow(x_b, u_gamma)); }
#else
uint r_byte(float r255) { return uint(floor(r255 + 0.5)); }
uint b_byte(float x_b) { return quantise(x_b); }
#endif

void main() {
    float z_m = -v_view.z;            // planar camera Z, m
    float d = z_m * CM_PER_M;         // cm
    bool valid = d > 0.0 && d < u_alpha_cm;
    if (valid) {
        // one quantity feeds both channels: q = d / beta; x_B = frac(q), 255 x_R = q * 255 beta / alpha
        float q = d / u_beta_cm;
        float x_b = q - floor(q);
        uint r = r_byte(min(q * u_r_per_period, BYTE_MAX));
        o_encoded = uvec4(r, r, b_byte(x_b), 255u);
    } else {
        o_encoded = uvec4(0u);
    }
#ifdef OUT_RGB
    vec3 n = normalize(cross(dFdx(v_view), dFdy(v_view)));
    float lambert = abs(dot(n, u_light));
    o_rgb = vec4(v_colour * (AMBIENT + DIFFUSE * lambert), 1.0);
#endif
#ifdef OUT_ZF
    o_zf = valid ? z_m : uintBitsToFloat(0x7fc00000u);
#endif
}
