#version 330
// Depth-in-colour encoding of the paper's Eqs 1-2 (docs/CONTRACTS.md), bit-for-bit the numpy reference
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
// covers, and it is about a quarter of a visible pixel's cost (bench/HISTORY.md, "Renderer").
// (the codec uniforms and encode_q: codec.glsl, inserted before this text)
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

const float AMBIENT = 0.35;   // shaded image only: ambient and diffuse shares (as renderer_proc.mock_backend)
const float DIFFUSE = 0.65;

void main() {
    // the period count q = d / beta (d = Z in cm) straight from 1/w: one division per pixel
    uvec4 enc = encode_q(u_q_per_m / gl_FragCoord.w);
    o_encoded = enc;
#ifdef OUT_RGB
    vec3 n = normalize(cross(dFdx(v_view), dFdy(v_view)));
    float lambert = abs(dot(n, u_light));
    o_rgb = vec4(v_colour * (AMBIENT + DIFFUSE * lambert), 1.0);
#endif
#ifdef OUT_ZF
    o_zf = enc.a != 0u ? 1.0 / gl_FragCoord.w : uintBitsToFloat(0x7fc00000u);   // planar Z, m; NaN invalid
#endif
}
