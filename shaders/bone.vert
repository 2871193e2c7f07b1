#version 330 core
// One skeleton bone per instance, drawn as a screen-space quad of `width` pixels
// (core profile has no wide lines). gl_VertexID 0..3 walks the quad as a strip.
uniform mat4 mvp;
uniform vec2 viewport;  // pixels
uniform float width;    // pixels

in vec3 in_a;  // parent joint, world
in vec3 in_b;  // child joint, world

void main() {
    vec4 a = mvp * vec4(in_a, 1.0);
    vec4 b = mvp * vec4(in_b, 1.0);
    vec2 sa = a.xy / a.w * viewport * 0.5;
    vec2 sb = b.xy / b.w * viewport * 0.5;
    vec2 dir = sb - sa;
    dir = length(dir) > 1e-6 ? normalize(dir) : vec2(1.0, 0.0);
    vec2 side = vec2(-dir.y, dir.x) * width * 0.5 / (viewport * 0.5);
    bool at_b = gl_VertexID >= 2;
    float sgn = (gl_VertexID == 0 || gl_VertexID == 2) ? -1.0 : 1.0;
    vec4 p = at_b ? b : a;
    gl_Position = vec4(p.xy + sgn * side * p.w, p.z, p.w);
}
