#version 330
// Beam-native pass, convex solids (boxes, cylinders as prisms), one point per instance: the instance's unit
// solid (cube [-1, 1]^3, or the prism of renderer_proc.beam_gl.PRISM_SIDES sides on the unit circle, z in [0, 1])
// and the LiDAR origin and frame seen from it. solid.geom bounds it, solid.frag clips each beam against it.
uniform mat4 u_sensor_from_local;
in mat4 in_model;                   // local_from_unit
in vec3 in_colour;
out mat4 v_sensor_from_unit;
out mat3 v_unit_from_sensor;        // directions, sensor frame -> unit frame
out vec3 v_origin;                  // the LiDAR origin in the unit frame
out vec3 v_colour;
void main() {
    mat4 m = u_sensor_from_local * in_model;
    mat4 inv = inverse(m);
    v_sensor_from_unit = m;
    v_unit_from_sensor = mat3(inv);
    v_origin = inv[3].xyz;
    v_colour = in_colour;
}
