#version 330
// Beam-native pass, instanced solids (unit cube, unit cylinder, meshes): each vertex in the LiDAR (sensor) frame
// relative to its origin, m (X right, Y up, Z forward). No projection here: beam.geom maps triangles to angles.
uniform mat4 u_sensor_from_local;
uniform float u_az_centre;          // azimuth of the field's centre, rad   // sensor frame <- the GPU's local frame (world shifted to the cart grid origin)
in vec3 in_pos;                     // unit-mesh vertex, m
in mat4 in_model;                   // per instance: local_from_unit
in vec3 in_colour;                  // per instance: linear RGB
out vec3 v_p;
out vec3 v_colour;
out vec2 v_ae;                      // (azimuth from the field's centre in [-pi, pi), elevation), rad
vec2 angles(vec3 p, float centre);   // beam_angles.glsl

void main() {
    v_p = (u_sensor_from_local * (in_model * vec4(in_pos, 1.0))).xyz;
    v_ae = angles(v_p, u_az_centre);
    v_colour = in_colour;
}
