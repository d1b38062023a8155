// Procedural textures of the camera sensors' colour images (docs/cameras.md): value noise on an integer hash,
// summed over octaves, each octave faded to its mean where its wavelength falls below PIXELS_PER_WAVE pixels
// of the surface's footprint (fwidth), so no octave aliases into noise that differs between the two eyes of a
// stereo pair. Albedos are linear RGB.
const float PIXELS_PER_WAVE = 2.0;

uint hash3(uvec3 v) {                     // a 3D integer hash (PCG-style mixing)
    v = v * 1664525u + 1013904223u;
    v.x += v.y * v.z; v.y += v.z * v.x; v.z += v.x * v.y;
    v ^= v >> 16u;
    v.x += v.y * v.z; v.y += v.z * v.x; v.z += v.x * v.y;
    return v.x ^ v.y ^ v.z;
}

float rand3(vec3 cell) {                  // uniform in [0, 1) per integer cell
    return float(hash3(uvec3(ivec3(cell) + 1048576)) & 0xffffffu) / 16777216.0;
}

float value_noise_reference(vec3 p) {     // smooth value noise, [0, 1), one cell per unit: the readable form
    vec3 i = floor(p);
    vec3 f = p - i;
    vec3 u = f * f * (3.0 - 2.0 * f);
    float n000 = rand3(i), n100 = rand3(i + vec3(1, 0, 0)), n010 = rand3(i + vec3(0, 1, 0));
    float n110 = rand3(i + vec3(1, 1, 0)), n001 = rand3(i + vec3(0, 0, 1)), n101 = rand3(i + vec3(1, 0, 1));
    float n011 = rand3(i + vec3(0, 1, 1)), n111 = rand3(i + vec3(1, 1, 1));
    return mix(mix(mix(n000, n100, u.x), mix(n010, n110, u.x), u.y),
               mix(mix(n001, n101, u.x), mix(n011, n111, u.x), u.y), u.z);
}

// value_noise_reference's corners, the same bits for less work: hash3's first step v * HASH_MUL + HASH_ADD is
// made once for the cell and its neighbour (a cell one step along an axis differs by HASH_MUL there), and its
// first product y * z is shared by the two corners that differ in x only
const uint HASH_MUL = 1664525u;
const uint HASH_ADD = 1013904223u;

float rand3_mixed(uint x, uint y, uint z, uint yz) {   // rand3 of the cell whose first step gave (x, y, z), yz = y * z
    uvec3 v = uvec3(x + yz, y, z);
    v.y += v.z * v.x; v.z += v.x * v.y;
    v ^= v >> 16u;
    v.x += v.y * v.z; v.y += v.z * v.x; v.z += v.x * v.y;
    return float((v.x ^ v.y ^ v.z) & 0xffffffu) / 16777216.0;
}

float value_noise(vec3 p) {               // smooth value noise, [0, 1), one cell per unit (value_noise_reference)
    vec3 i = floor(p);
    vec3 f = p - i;
    vec3 u = f * f * (3.0 - 2.0 * f);
    uvec3 m = uvec3(ivec3(i) + 1048576) * HASH_MUL + HASH_ADD;   // the cell's first step
    uvec3 s = m + HASH_MUL;                                        // its neighbour's along each axis
    uint mm = m.y * m.z, sm = s.y * m.z, ms = m.y * s.z, ss = s.y * s.z;
    float n000 = rand3_mixed(m.x, m.y, m.z, mm), n100 = rand3_mixed(s.x, m.y, m.z, mm);
    float n010 = rand3_mixed(m.x, s.y, m.z, sm), n110 = rand3_mixed(s.x, s.y, m.z, sm);
    float n001 = rand3_mixed(m.x, m.y, s.z, ms), n101 = rand3_mixed(s.x, m.y, s.z, ms);
    float n011 = rand3_mixed(m.x, s.y, s.z, ss), n111 = rand3_mixed(s.x, s.y, s.z, ss);
    return mix(mix(mix(n000, n100, u.x), mix(n010, n110, u.x), u.y),
               mix(mix(n001, n101, u.x), mix(n011, n111, u.x), u.y), u.z);
}

// octaves of value noise from wavelength w0 (m) down by halves, n of them, amplitude ratio gain; returns a
// zero-mean value; footprint: the surface's size of one pixel, m. The readable form of fbm.
float fbm_reference(vec3 p, float w0, int n, float gain, float footprint) {
    float sum = 0.0, amp = 1.0, w = w0;
    for (int k = 0; k < n; ++k) {
        float fade = clamp(w / (PIXELS_PER_WAVE * footprint) - 1.0, 0.0, 1.0);
        sum += amp * fade * (value_noise_reference(p / w + float(k) * 17.0) - 0.5);
        amp *= gain;
        w *= 0.5;
    }
    return sum;
}

// fbm_reference with its bits and without its divisions per octave: w = w0 / 2^k, so p / w is (p / w0) * 2^k
// and w / (PIXELS_PER_WAVE footprint) is its first octave's value / 2^k, exactly (scaling by a power of two
// rounds alike); the octaves after the first one faded whole are not evaluated (each adds amp * 0 * (v - 0.5),
// a zero that leaves the sum's bits as they are)
float fbm(vec3 p, float w0, int n, float gain, float footprint) {
    float sum = 0.0, amp = 1.0;
    vec3 q = p / w0;
    float waves = w0 / (PIXELS_PER_WAVE * footprint);
    for (int k = 0; k < n && waves > 1.0; ++k) {
        float fade = clamp(waves - 1.0, 0.0, 1.0);
        sum += amp * fade * (value_noise(q + float(k) * 17.0) - 0.5);
        amp *= gain;
        q *= 2.0;
        waves *= 0.5;
    }
    return sum;
}

// cellular pattern: per cell of size w a random value, with a dark seam at the cell border (kernels, clods)
float cells(vec3 p, float w, float footprint, out float border) {
    vec3 q = p / w;
    vec3 f = fract(q) - 0.5;
    float edge = max(max(abs(f.x), abs(f.y)), abs(f.z));
    float fade = clamp(w / (PIXELS_PER_WAVE * footprint) - 1.0, 0.0, 1.0);
    border = fade * smoothstep(0.38, 0.5, edge);
    return 0.5 + fade * (rand3(floor(q)) - 0.5);
}

const int MAT_STEEL = 0;
const int MAT_TYRE = 1;
const int MAT_GRAIN = 2;
const int MAT_STUBBLE = 3;

// the albedo of a surface point: material, base colour, the part's own frame (obj) and the world (world), m
vec3 albedo(int material, vec3 base, vec3 obj, vec3 world, float footprint) {
    if (material == MAT_GRAIN) {                        // corn kernels ~9 mm, clumps and shading at 2-16 cm
        float seam;
        float kernel = cells(obj, 0.009, footprint, seam);
        float clump = fbm(obj, 0.16, 4, 0.6, footprint);
        vec3 c = base * (0.78 + 0.45 * kernel + 0.9 * clump) * (1.0 - 0.45 * seam);
        return c * vec3(1.0, 0.97 + 0.06 * kernel, 0.85 + 0.3 * kernel);
    }
    if (material == MAT_STUBBLE) {                      // soil and straw; stubble rows 0.76 m apart along x
        float straw = fbm(world, 0.08, 4, 0.7, footprint);
        float soil = fbm(world * vec3(1.0, 1.0, 0.0), 1.2, 4, 0.55, footprint);
        float row = smoothstep(0.0, 0.3, abs(fract(world.y / 0.76) - 0.5) * 2.0);
        vec3 straw_c = vec3(0.62, 0.52, 0.30), soil_c = vec3(0.30, 0.24, 0.15);
        float t = clamp(0.45 + 1.6 * straw + 0.25 * row, 0.0, 1.0);
        return mix(soil_c, straw_c, t) * (0.85 + 0.6 * soil);
    }
    if (material == MAT_TYRE) {                         // black rubber with lugs around the circumference
        float a = atan(obj.y, obj.x);
        float lug = step(0.5, fract(a * 16.0 / 6.2831853 + 2.0 * obj.z));
        return vec3(0.05) * (0.7 + 0.6 * lug) * (1.0 + fbm(obj, 0.05, 3, 0.5, footprint));
    }
    // painted steel: the part's colour, mottled by dust and wear at 3-60 cm, darker streaks of dirt
    float dust = fbm(obj, 0.6, 5, 0.55, footprint);
    float streak = fbm(obj * vec3(4.0, 4.0, 0.5), 0.4, 3, 0.5, footprint);
    return base * (0.9 + 0.5 * dust) * (1.0 - 0.35 * clamp(streak * 2.0, 0.0, 1.0))
        + vec3(0.06, 0.05, 0.03) * clamp(dust + 0.2, 0.0, 1.0);
}
