#version 330
// Camera sensors: the textured, lit colour image, the planar depth and the label of each pixel
// (docs/cameras.md). Outputs: o_rgb (linear RGB as bytes), o_depth (planar Z, m), o_label (the part's label).
// (textures.glsl, inserted before this text, gives albedo())
uniform vec3 u_sun;            // unit vector towards the sun, GL view space
uniform float u_sun_share;     // the sun's share of the light on a surface facing it (0 at night)
uniform float u_ambient;       // the sky's light
uniform vec3 u_lamp;           // work light position, GL view space
uniform float u_lamp_intensity;  // its irradiance at 1 m (0: none)
in vec3 v_view;
in vec3 v_world;
in vec3 v_obj;
in vec3 v_colour;
flat in vec2 v_tag;
layout(location = 0) out vec4 o_rgb;
layout(location = 1) out float o_depth;
layout(location = 2) out uint o_label;

const float SPECULAR = 0.12;   // painted steel's highlight
const float SHININESS = 24.0;

void main() {
    vec3 n = normalize(cross(dFdx(v_view), dFdy(v_view)));      // flat normal, view space
    vec3 to_eye = normalize(-v_view);
    if (dot(n, to_eye) < 0.0) n = -n;                           // the side the camera sees
    float footprint = max(length(fwidth(v_obj)), 1e-5);         // m of surface per pixel
    int material = int(v_tag.y + 0.5);
    vec3 base = albedo(material, v_colour, v_obj, v_world, footprint);
    float light = u_ambient + u_sun_share * max(dot(n, u_sun), 0.0);
    float spec = 0.0;
    if (u_sun_share > 0.0 && material == MAT_STEEL) {
        spec = u_sun_share * SPECULAR * pow(max(dot(n, normalize(u_sun + to_eye)), 0.0), SHININESS);
    }
    if (u_lamp_intensity > 0.0) {
        vec3 to_lamp = u_lamp - v_view;
        float r2 = max(dot(to_lamp, to_lamp), 1e-6);
        light += u_lamp_intensity * max(dot(n, to_lamp), 0.0) / (r2 * sqrt(r2));
    }
    o_rgb = vec4(clamp(base * light + spec, 0.0, 1.0), 1.0);
    o_depth = 1.0 / gl_FragCoord.w;                               // planar Z, m (w_clip = -z_view)
    o_label = uint(v_tag.x + 0.5);
}
