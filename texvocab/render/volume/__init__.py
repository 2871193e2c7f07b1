"""Volume rendering's math, shared by every marcher: samples along rays and the NeRF
quadrature (:mod:`.samples`), VolSDF's closed forms for a piecewise-linear SDF
(:mod:`.volsdf`), and calling the field in chunks (:mod:`.field`)."""
