"""Procedural generators of the bundled scenes, one module per scene.

Each module's ``main(out)`` writes its scene into folder ``out`` (default
``scenes/<name>/`` of this checkout, :data:`SCENES`) and ``cli()`` is its
command line, which ``scenes/make_<name>.py`` runs:

* :mod:`.cornellbox` (``scenes/cornellbox/``), :mod:`.newscene`
  (``scenes/newscene/``): small hand-built scenes, committed;
* :mod:`.showcase` (``scenes/showcase/``): a car under a day and a dusk sky,
  committed;
* :mod:`.diningroom` (``scenes/diningroom/``, 510k triangles, git-ignored):
  generated on demand (:func:`drpt.tools.reference.scene_path`);
* :mod:`.materials_cornell` and :mod:`.veach_mis`: small test scenes of mixed
  PBR materials for ``tests/validation/test_materials_mitsuba.py``, not committed: their
  ``main(out)`` and ``scenes/make_<name>.py OUT_DIR`` need the folder
  (:mod:`.meshes` holds the mesh builders and OBJ writer they share).
* :mod:`.living_room`: a textured living room with several area lights and a sky
  through a window, written as Mitsuba XML (``scenes/make_living_room.py OUT_DIR``),
  not committed: ``benchmarks/equal_time_vs_mitsuba.py`` generates it.
"""

from pathlib import Path

SCENES = Path(__file__).resolve().parents[3] / "scenes"
