"""Reading materials, backend-free (numpy, no Dr.Jit): what a scene's materials mean
before anything is uploaded.

* :mod:`.bsdf_kinds`: the BSDF vocabulary (every kind drpt renders, its parameters
  and defaults, the composites);
* :mod:`.spec`: a material as a :class:`~.spec.BSDFSpec` tree of that vocabulary,
  its texture-valued parameters, and :func:`~.spec.complete`;
* :mod:`.interpret`: the rules that turn MTL (and 6.837) statements into one tree
  per material (``--bsdf`` modes);
* :mod:`.iors` and :mod:`.conductors`: Mitsuba 3's named indices of refraction and
  conductors;
* :mod:`.layout`: a scene's trees flattened into the host-side material layout
  (lobe rows, per-material slots, parameter arrays, texture references) that
  :mod:`drpt.render.material` uploads.

Reading the files themselves is the scene readers' part (:mod:`drpt.scene.mtl`,
:mod:`drpt.scene.mitsuba.materials`).
"""
