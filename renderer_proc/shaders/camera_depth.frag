#version 330
// Camera sensors that read no colour (a depth camera): the planar depth and, when read, the label of each
// pixel, nothing textured or lit (docs/cameras.md). The same vertex shaders as camera.frag's, so the depth is
// camera.frag's to the bit. Outputs: o_depth (planar Z, m) at attachment 0, o_label (the part's label) at 1.
in vec3 v_view;
flat in vec2 v_tag;
layout(location = 0) out float o_depth;
layout(location = 1) out uint o_label;

void main() {
    o_depth = 1.0 / gl_FragCoord.w;                               // planar Z, m (w_clip = -z_view)
    o_label = uint(v_tag.x + 0.5);
}
