#version 330
// Camera sensors, the grain surface: static (x, y) grid in the cart grid frame, heights per frame
// (renderer_proc.surface_gl). Its texture is fixed to the cart grid (the grain moves with the cart).
uniform mat4 u_view;
uniform mat4 u_proj;
uniform mat4 u_model;       // local_from_grid
uniform vec3 u_origin;
uniform vec3 u_colour;
uniform vec2 u_tag;         // (label GRAIN, material grain)
in vec2 in_xy;
in float in_h;
out vec3 v_view;
out vec3 v_world;
out vec3 v_obj;
out vec3 v_colour;
flat out vec2 v_tag;
void main() {
    vec4 local = u_model * vec4(in_xy, in_h, 1.0);
    v_world = local.xyz + u_origin;
    v_obj = vec3(in_xy, in_h);
    vec4 view = u_view * local;
    v_view = view.xyz;
    v_colour = u_colour;
    v_tag = u_tag;
    gl_Position = u_proj * view;
}
