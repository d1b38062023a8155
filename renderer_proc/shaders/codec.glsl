// Depth-in-colour encoding of the paper's Eqs 1-2 (docs/CONTRACTS.md), bit for bit renderer_proc.codec.encode_depth,
// shared by the camera pass (encode.frag, planar depth) and the beam-native passes (range along the beam). The
// renderer inserts it after the #defines (MISHANDLED_GAMMA: compile-time, so the linear pipeline pays for no pow).
uniform float u_q_per_m;        // periods of B per metre: 100 / beta_cm
uniform float u_q_max;          // alpha / beta: period count at the codec's range (valid: 0 < q < u_q_max)
uniform float u_r_per_period;   // 255 beta / alpha
uniform float u_gamma;

uint codec_quantise(float x) { return uint(x * 255.0 + 0.5); }          // round half up, x >= 0
#ifdef MISHANDLED_GAMMA
uint codec_r(float r255) { return codec_quantise(pow(r255 / 255.0, u_gamma)); }
uint codec_b(float x_b) { return codec_quantise(pow(x_b, u_gamma)); }
#else
uint codec_r(float r255) { return uint(r255 + 0.5); }
uint codec_b(float x_b) { return codec_quantise(x_b); }
#endif

// the bytes of period count q = d / beta: one quantity feeds both channels, x_B = frac(q) and
// 255 x_R = q * 255 beta / alpha; out of range or behind: A = 0 and no depth bytes
uvec4 encode_q(float q) {
    bool valid = q > 0.0 && q < u_q_max;
    uint r = codec_r(min(q * u_r_per_period, 255.0));
    return valid ? uvec4(r, r, codec_b(fract(q)), 255u) : uvec4(0u);
}

uvec4 encode_range(float d_m) { return encode_q(u_q_per_m * d_m); }
