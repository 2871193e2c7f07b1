#version 330 core
// Skeleton joints as round points of `size` pixels.
uniform mat4 mvp;
uniform float size;

in vec3 in_position;  // joint, world

void main() {
    gl_Position = mvp * vec4(in_position, 1.0);
    gl_PointSize = size;
}
