#version 330 core
// A uniform colour; points (round_points) are cut to discs.
uniform vec3 color;
uniform bool round_points;

out vec4 frag_color;

void main() {
    if (round_points && length(gl_PointCoord - vec2(0.5)) > 0.5) {
        discard;
    }
    frag_color = vec4(color, 1.0);
}
