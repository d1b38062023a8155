#version 330
// Instanced solids (unit cube, unit cylinder, meshes): world_from_unit per instance.
// v_view is the GL view-space position (right-handed, -z forward): planar camera depth Z = -v_view.z.
uniform mat4 u_view;   // world -> GL view
uniform mat4 u_proj;   // GL view -> clip, image flipped vertically (renderer_proc.projection)
in vec3 in_pos;        // unit-mesh vertex, m
in mat4 in_model;      // per instance: world_from_unit
in vec3 in_colour;     // per instance: linear RGB
out vec3 v_view;
out vec3 v_colour;
void main() {
    vec4 view = u_view * (in_model * vec4(in_pos, 1.0));
    v_view = view.xyz;
    v_colour = in_colour;
    gl_Position = u_proj * view;
}
