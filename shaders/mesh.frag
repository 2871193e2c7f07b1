#version 330 core
// Base colour by mode, headlight shading, optional single-pass wireframe.
uniform int mode;          // 0: neutral grey checker, 1: texture, 2: per-vertex colour
uniform sampler2D tex;     // blended vocabulary texture
uniform bool lighting;
uniform vec3 eye;          // camera centre, world
uniform bool wireframe;
uniform vec3 wire_color;
uniform float wire_width;  // pixels

in vec3 v_world;
in vec3 v_normal;
in vec2 v_uv;
in vec3 v_color;
in vec3 v_bary;

out vec4 frag_color;

void main() {
    vec3 base;
    if (mode == 1) {
        base = texture(tex, v_uv).rgb;
    } else if (mode == 2) {
        base = v_color;
    } else {
        vec2 cell = floor(v_uv * 16.0);
        base = mod(cell.x + cell.y, 2.0) < 1.0 ? vec3(0.62) : vec3(0.56);
    }
    vec3 color = base;
    if (lighting) {
        vec3 n = normalize(v_normal);
        vec3 to_eye = normalize(eye - v_world);
        float diffuse = abs(dot(n, to_eye));  // two-sided headlight
        color = base * (0.35 + 0.65 * diffuse);
    }
    if (wireframe) {
        vec3 w = fwidth(v_bary);  // barycentric change per pixel: ~1 / triangle size
        vec3 d = v_bary / max(w, vec3(1e-6));
        float edge = min(min(d.x, d.y), d.z);
        float on = 1.0 - smoothstep(0.0, wire_width, edge);
        // fade lines out where triangles are only a few pixels wide (they would cover all)
        float dense = smoothstep(0.12, 0.4, max(max(w.x, w.y), w.z));
        color = mix(color, wire_color, 0.8 * on * (1.0 - dense));
    }
    frag_color = vec4(color, 1.0);
}
