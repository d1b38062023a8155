#version 330
// Beam-native pass, grain surface: grid-frame (x, y) vertices with per-frame heights, into the LiDAR frame, m.
uniform mat4 u_sensor_from_local;
uniform float u_az_centre;          // azimuth of the field's centre, rad
uniform mat4 u_model;               // local_from_grid
uniform vec3 u_colour;
in vec2 in_xy;                      // grid-frame position, m
in float in_h;                      // grain height above the floor, m
out vec3 v_p;
out vec3 v_colour;
out vec2 v_ae;                      // (azimuth from the field's centre in [-pi, pi), elevation), rad
vec2 angles(vec3 p, float centre);   // beam_angles.glsl

void main() {
    v_p = (u_sensor_from_local * (u_model * vec4(in_xy, in_h, 1.0))).xyz;
    v_ae = angles(v_p, u_az_centre);
    v_colour = u_colour;
}
