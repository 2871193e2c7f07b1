"""The viewer's GL side: the orbit and capture cameras and their GL matrices
(:mod:`.camera`), the 3D view's scene (:mod:`.scene`, colours in :mod:`.colors`), GLSL
programs (:mod:`.glsl`), copies into the window's framebuffer (:mod:`.view_blit`) and the
headless OSMesa context (:mod:`.headless`)."""
