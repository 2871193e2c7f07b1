#version 330 core
// The posed body, unrolled per triangle corner (positions and normals change per pose).
uniform mat4 mvp;  // world -> clip (see app/gl/camera.py: gl_mvp)

in vec3 in_position;  // world, metres
in vec3 in_normal;
in vec2 in_uv;        // OBJ convention: origin bottom-left (the texture is uploaded to match)
in vec3 in_color;     // overlay colour (part colours / novelty heat), linear RGB
in vec3 in_bary;      // (1,0,0) / (0,1,0) / (0,0,1) per corner, for the wireframe

out vec3 v_world;
out vec3 v_normal;
out vec2 v_uv;
out vec3 v_color;
out vec3 v_bary;

void main() {
    v_world = in_position;
    v_normal = in_normal;
    v_uv = in_uv;
    v_color = in_color;
    v_bary = in_bary;
    gl_Position = mvp * vec4(in_position, 1.0);
}
