"""Width-constrained toolpaths on curved layers (paper sections 3.2, 4.2, 4.3).

Per-surface algorithms: ``lines`` (SurfaceLines), ``surface``, ``geodesic``, ``deform``,
``isolines``, ``contours``, ``stripes``, ``width_error``. Assembly around them: ``mapback``
(eqs. 15, 16), ``resample``, ``volume`` (volume matching of tau), ``ordering``, ``linking``;
``surface_geometry`` and ``line_source`` (a component surface's lines with the options
tried), ``component`` (its process fields and the path built from lines),
``width_measure``, ``strategy`` (how one component is printed), ``candidate_choice``
(the alternatives it tries and the one kept), ``layer_build`` (one layer), ``build``
(``compute_toolpath``: the whole model), ``results`` and ``report``; ``coverage``,
``export`` (toolpath.npz, layer text files) and ``figures``. The extrusion model lives in
``slicer.extrusion``.
"""
