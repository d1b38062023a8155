// Depth-in-colour encoding of the paper's Eqs 1-2 (DESIGN.md section 4) as a function, for the beam-native
// pass (the camera pass's encode.frag inlines the same arithmetic): bit for bit renderer_proc.codec.encode_depth.
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

uvec4 encode_range(float d_m) {
    float q = u_q_per_m * d_m;                                   // period count d / beta
    bool valid = q > 0.0 && q < u_q_max;
    uint r = codec_r(min(q * u_r_per_period, 255.0));
    return valid ? uvec4(r, r, codec_b(fract(q)), 255u) : uvec4(0u);
}
