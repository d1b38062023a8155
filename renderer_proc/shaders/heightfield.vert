#version 330
// Grain surface: static (x, y) vertex grid in the cart grid frame, heights from a buffer updated per frame.
uniform mat4 u_view;
uniform mat4 u_proj;
uniform mat4 u_model;   // world_from_grid
uniform vec3 u_colour;
in vec2 in_xy;          // grid-frame position, m
in float in_h;          // grain height above the floor, m
out vec3 v_view;
out vec3 v_colour;
void main() {
    vec4 view = u_view * (u_model * vec4(in_xy, in_h, 1.0));
    v_view = view.xyz;
    v_colour = u_colour;
    gl_Position = u_proj * view;
}
