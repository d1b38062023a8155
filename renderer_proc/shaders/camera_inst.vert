#version 330
// Camera sensors, instanced solids (unit cube, unit cylinder, meshes): world_from_unit per instance, plus the
// part's label and material (cosim.world.labels). GL view space is right-handed with -z forward: planar camera
// depth Z = -v_view.z (renderer_proc.projection).
uniform mat4 u_view;        // the GPU's local frame (world shifted to u_origin) -> GL view
uniform mat4 u_proj;        // GL view -> clip, image flipped vertically
uniform vec3 u_origin;      // world position of the local frame's origin, m
in vec3 in_pos;             // unit-mesh vertex
in mat4 in_model;           // per instance: local_from_unit
in vec3 in_colour;          // per instance: linear RGB base colour
in vec2 in_tag;             // per instance: (label, material)
out vec3 v_view;
out vec3 v_world;           // world position, m (textures fixed to the ground)
out vec3 v_obj;             // position in the part's own frame, m (textures fixed to the part)
out vec3 v_colour;
flat out vec2 v_tag;
void main() {
    vec4 local = in_model * vec4(in_pos, 1.0);
    v_world = local.xyz + u_origin;
    v_obj = in_pos * vec3(length(in_model[0].xyz), length(in_model[1].xyz), length(in_model[2].xyz));
    vec4 view = u_view * local;
    v_view = view.xyz;
    v_colour = in_colour;
    v_tag = in_tag;
    gl_Position = u_proj * view;
}
