"""The host-side material layout (drpt/materials/layout.py), with numpy only: rows and
their explicit material and slot, slots, fields (constants, texture references,
derived values), sidedness, emission, delta materials, the errors it raises; and
that no module of drpt/materials imports Dr.Jit (with a negative control).

The lobes are stand-ins (``FIELDS``, ``DELTA``, ``derive``), as the layout takes
them as an argument; nothing here traces or uploads anything."""

from __future__ import annotations

import ast
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from drpt.errors import Loc, SceneError
from drpt.materials.layout import NONE, MaterialLayout
from drpt.materials.spec import BSDFSpec, Texture, complete
from drpt.scene.model import Background, Material, PerspectiveCamera, Planes, Scene, Spheres, Triangles


def _derive_scaled(params):
    kd = params["kd"]
    if kd == (9.0, 9.0, 9.0):
        raise ValueError("kd 9 refused")
    return {"kd_sum": float(np.sum(kd.fallback if isinstance(kd, Texture) else kd))}


#: stand-in lobes: the layout reads FIELDS, DELTA and derive
LOBES = {
    "diffuse": SimpleNamespace(FIELDS={"kd": "rgb", "kd_sum": "float"}, DELTA=False, derive=_derive_scaled),
    "mirror": SimpleNamespace(FIELDS={"ks": "rgb"}, DELTA=True),
    "null": SimpleNamespace(FIELDS={}, DELTA=True),
    "roughplastic": SimpleNamespace(FIELDS={"tab": ("table", 4)}, DELTA=False,
                                    derive=lambda p: {"tab": np.arange(4.0) * p["alpha"]}),
}


def lobe(kind):
    return LOBES[kind]


def two(spec):
    return BSDFSpec("twosided", children=[spec])


def diffuse(c=(0.5, 0.5, 0.5)):
    return BSDFSpec("diffuse", {"kd": c})


def scene_with(*specs, used=None, emission=None, uvs=True):
    """One triangle per used material (all by default); material ``i`` is ``m<i>``."""
    cam = PerspectiveCamera((0, 0, 5), (0, 0, -1), (0, 1, 0), 40.0)
    mats = [Material(f"m{i}", bsdf=s, loc=Loc("t.txt", i + 1)) for i, s in enumerate(specs)]
    for i, e in (emission or {}).items():
        mats[i].emission = e
    used = list(range(len(specs))) if used is None else used
    pos = np.array([[[-1.0, -1, 0], [1, -1, 0], [1, 1, 0]]] * len(used))
    return Scene(Path("t.txt"), cam, mats,
                 Triangles(pos, np.array(used, np.int32), uvs=np.zeros((len(used), 3, 2)) if uvs else None),
                 Spheres.empty(), Planes.empty(), [], Background())


def build(*specs, **kw):
    return MaterialLayout.build(scene_with(*specs, **kw), "auto", lobe)


def test_single_component_materials_are_their_own_rows():
    lay = build(two(diffuse((0.1, 0.2, 0.3))), two(BSDFSpec("mirror")))
    assert lay.K == 1 and lay.slots == []
    assert lay.row_material.tolist() == [0, 1] and lay.row_slot.tolist() == [0, 0]
    assert lay.kinds == ["diffuse", "mirror"] and lay.kind.tolist() == [0, 1]
    assert lay.material_kinds == [("diffuse",), ("mirror",)]
    np.testing.assert_array_equal(lay.fields["kd"].values[0], [0.1, 0.2, 0.3])
    assert lay.fields["kd"].values[1].tolist() == [0.0, 0.0, 0.0]  # not a diffuse row
    assert lay.fields["kd_sum"].values.dtype == np.float32
    assert lay.fields["kd_sum"].values[0] == pytest.approx(0.6)  # derived on the host
    assert lay.fields["kd"].texture is None and lay.textures == []
    assert lay.two_sided == {"diffuse": True, "mirror": True}
    assert lay.material_delta.tolist() == [False, True]


def test_blend_and_mask_fill_slots_with_explicit_rows():
    blend = complete(BSDFSpec("blendbsdf", {"weight": 0.25}, [diffuse(), BSDFSpec("mirror")]))
    mask = complete(BSDFSpec("mask", {"opacity": 0.75}, [two(diffuse())]))
    lay = build(two(diffuse()), blend, mask)
    assert lay.K == 2
    # rows material by material: m0 one, m1 two (diffuse, mirror), m2 two (null, diffuse)
    assert lay.row_material.tolist() == [0, 1, 1, 2, 2]
    assert lay.row_slot.tolist() == [0, 0, 1, 0, 1]
    assert [lay.rows[i].leaf.kind for i in range(5)] == ["diffuse", "diffuse", "mirror", "null", "diffuse"]
    s0, s1 = lay.slots
    assert s0.row.tolist() == [0, 1, 3] and s1.row.tolist() == [NONE, 2, 4]
    np.testing.assert_allclose(s0.weight, [1.0, 0.75, 0.25])
    np.testing.assert_allclose(s1.weight, [0.0, 0.25, 0.75])
    assert not s0.partial and s1.partial
    assert s0.kinds == ["diffuse", "null"] and s1.kinds == ["diffuse", "mirror"]
    # sidedness: the blend's diffuse is one-sided, the others two-sided: per row
    np.testing.assert_array_equal(lay.two_sided["diffuse"], [True, False, False, False, True])
    assert lay.material_delta.tolist() == [False, False, False]
    # each row's slot is where its material's slot table points back to it
    for i, (m, j) in enumerate(zip(lay.row_material, lay.row_slot)):
        assert lay.slots[j].row[m] == i


def test_textures_are_referenced_by_id_and_shared_by_file(tmp_path):
    png = tmp_path / "a.png"
    a = Texture(png, (0.2, 0.2, 0.2))
    opts = Texture(png, 0.5, filter_type="nearest")
    weight = complete(BSDFSpec("blendbsdf", {"weight": opts}, [diffuse(), diffuse()]))
    lay = build(two(diffuse(a)), two(diffuse(Texture(png, (0.7, 0.7, 0.7)))), weight,
                emission={0: (1.0, 1.0, 1.0)})
    kd = lay.fields["kd"]
    # one plain image file is one texture; the textured rows keep their fallback as constant
    assert kd.texture.tolist() == [0, 0, NONE, NONE]
    np.testing.assert_allclose(kd.values[:2], [[0.2] * 3, [0.7] * 3])
    # the same file with other options is a texture of its own, referenced by the slot weights
    assert lay.textures == [png, opts]
    assert lay.slots[0].texture.tolist() == [NONE, NONE, 1]
    assert lay.emission.shape == (3, 3) and lay.has_emission and lay.emission_texture is None


def test_tables_are_row_major_and_derived():
    lay = build(complete(BSDFSpec("roughplastic", {"alpha": 0.5})), complete(BSDFSpec("roughplastic", {"alpha": 1.0})))
    f = lay.fields["tab"]
    assert f.type == ("table", 4) and f.texture is None
    np.testing.assert_allclose(f.values, [0, 0.5, 1.0, 1.5, 0, 1, 2, 3])


def test_unused_materials_are_black_and_silent():
    lay = build(two(diffuse((0.9, 0.9, 0.9))), two(diffuse()), used=[1])
    assert lay.specs[0].kind == "diffuse" and lay.specs[0].params["kd"] == (0.0, 0.0, 0.0)
    assert lay.specs[1].kind == "twosided"
    assert lay.fields["kd"].values[0].tolist() == [0.0, 0.0, 0.0]


def test_texture_dropped_without_uvs_is_a_note(tmp_path):
    lay = build(two(diffuse(Texture(tmp_path / "a.png", (0.3, 0.3, 0.3)))), uvs=False)
    assert lay.textures == [] and lay.fields["kd"].texture is None
    assert len(lay.notes) == 1 and "texture coordinates" in lay.notes[0]


def test_refused_trees_and_parameters_name_the_material():
    with pytest.raises(SceneError, match="m0.*twosided with a different BSDF"):
        build(BSDFSpec("twosided", children=[diffuse(), diffuse()]))
    # a parameter derive refuses: the leaf's Loc, else the scene file
    with pytest.raises(SceneError, match="^t.txt: kd 9 refused$"):
        build(two(diffuse()), two(diffuse((9.0, 9.0, 9.0))))


def test_no_module_of_the_package_imports_drjit():
    root = Path(__file__).resolve().parents[2] / "drpt" / "materials"
    offenders = [p.name for p in root.glob("*.py") if _imports_drjit(p.read_text())]
    assert offenders == []
    # negative control: the check sees both import forms
    assert _imports_drjit("import drjit as dr\n") and _imports_drjit("from drjit.auto import Float\n")
    assert not _imports_drjit("import numpy as np\n")


def _imports_drjit(source: str) -> bool:
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import) and any(a.name.split(".")[0] == "drjit" for a in node.names):
            return True
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "drjit":
            return True
    return False
