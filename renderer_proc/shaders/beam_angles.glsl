// Azimuth (from +Z towards -X, relative to the field's centre, wrapped into [-pi, pi)) and elevation (above
// the X-Z plane) of a LiDAR-frame point, rad: the beam-native target's angle coordinates.
const float PI = 3.14159265358979;
const float TWO_PI = 6.28318530717959;

float wrap(float a) { return a - TWO_PI * floor((a + PI) / TWO_PI); }

vec2 angles(vec3 p, float centre) {
    return vec2(wrap(atan(-p.x, p.z) - centre), atan(p.y, length(p.xz)));
}
