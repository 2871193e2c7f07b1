"""The viewer's GLSL, loaded by app.glsl; installed as the package ``app.shaders``."""
