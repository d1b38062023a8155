#version 330
// Beam-native pass, grain surface: grid-frame (x, y) vertices with per-frame heights, into the LiDAR frame, m.
uniform mat4 u_sensor_from_local;
uniform mat4 u_model;               // local_from_grid
uniform vec3 u_colour;
in vec2 in_xy;                      // grid-frame position, m
in float in_h;                      // grain height above the floor, m
out vec3 v_p;
out vec3 v_colour;
void main() {
    v_p = (u_sensor_from_local * (u_model * vec4(in_xy, in_h, 1.0))).xyz;
    v_colour = u_colour;
}
