"""The viewer's GLSL, loaded by texvocab_viewer.gl.glsl; installed as the package
``texvocab_viewer.shaders``."""
