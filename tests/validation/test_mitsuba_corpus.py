"""Mitsuba 3's own render-test scenes (``../shared/corpus/mitsuba-data/tests/scenes``), read
and rendered by drpt *as authored* and z-tested against the shipped references as Mitsuba's
``test_renders.py`` tests its own renders (:mod:`support.corpus`: XYZ, per pixel and channel,
Sidak-corrected level, 99.75% of the pixel channels must pass).

Every ``test_*.xml`` / ``scene_*.xml`` outside ``participating_media/`` (tested by
``tests/render/integrators/test_media.py``; the coverage test counts its lists,
:data:`support.corpus.MEDIA_SCENES` and ``MEDIA_NOT_YET``) and ``volprim_rf_basic/`` (volumetric
primitives, out of drpt's scope) and the scenes with ``sdfgrid`` shapes (:data:`EXCLUDED`)
is in :data:`SCENES` (rendered at the spp given, about a thousand: the z-test
uses drpt's spp with the reference's per-sample variance, so fewer samples make it weaker,
not flakier; at 512 spp a water IOR for BK7 passes) or in :data:`NOT_YET` (a strict xfail
whose reason names what drpt lacks); one scene per line in both. The ptracer scene is
rendered by drpt's light tracer, as authored (its reference is Mitsuba's ``path``, as the
file's comment says).

The negative controls render perturbed copies (a 10% brighter light, a wrong IOR, a bump map
of scale 0) written to ``tmp_path`` against the original's reference: the test must fail them.
"""

from __future__ import annotations

import re
import warnings

import pytest

from support.corpus import (
    CORPUS,
    MEDIA_NOT_YET,
    MEDIA_SCENES,
    cases,
    check_scene,
    corpus_scene,
    perturbed,
    reference_files,
    render_as_authored,
    z_test,
)

#: corpus scene -> spp drpt renders it with (all pass Mitsuba's z-test)
SCENES = {
    "bsdf_spheres/test_arealight_path.xml": 1024,
    "bsdf_spheres/test_bumpmap_path.xml": 1024,
    "bsdf_spheres/test_constant_path.xml": 1024,
    "bsdf_spheres/test_envmap_path.xml": 1024,
    "bsdf_spheres/test_normalmap_identity_roughconductor_path.xml": 1024,
    "bsdf_spheres/test_normalmap_path.xml": 1024,
    "bsdf_spheres/test_normalmap_roughconductor_path.xml": 1024,
    "bsdf_spheres/test_pointlight_path.xml": 1024,
    "bsdf_spheres/test_roughdielectric_path.xml": 1024,
    "bsdf_spheres/test_roughplastic_linear_path.xml": 1024,
    "bsdf_spheres/test_roughplastic_nonlinear_path.xml": 1024,
    "bsdf_spheres/test_textured_diffuse_path.xml": 1024,
    "bsdf_spheres/test_textured_roughconductor_path.xml": 1024,
    "bsdf_spheres/test_texturedprincipled1_path.xml": 1024,
    "bsdf_spheres/test_texturedprincipled2_path.xml": 1024,
    "bsdf_spheres/test_texturedprincipledthin_path.xml": 1024,
    "floating_sphere/test_directional_direct.xml": 1024,
    "infinite_mirrors/scene_path.xml": 1024,
    "instancing/test_instancing_path.xml": 1024,
    "mesh_attributes/test_mesh_attributes_1_face_direct.xml": 1024,
    "mesh_attributes/test_mesh_attributes_3_face_direct.xml": 1024,
    "mesh_attributes/test_mesh_attributes_3_vertex_direct.xml": 1024,
    "orthographic_sensor/test_orthographic_path.xml": 1024,
    "projector/test_projector_constant_direct.xml": 1024,
    "projector/test_projector_textured_direct.xml": 1024,
    "spot_light/test_spot_direct.xml": 1024,
    "texture_interp/test_texture_interp_direct.xml": 1024,
    "various_emitters/test_various_emitters_ptracer.xml": 256,  # 512 x 64 pixels
}

#: corpus scene -> what drpt lacks to render it (strict xfail)
NOT_YET: dict[str, str] = {}

#: corpus scene -> -D values, for a scene that cannot be rendered as authored (none)
DEFINES: dict[str, dict[str, str]] = {}

#: scenes out of drpt's scope: volumetric primitives, and sdfgrid shapes (participating_media/
#: is test_media.py's: support.corpus.MEDIA_SCENES and MEDIA_NOT_YET)
EXCLUDED_FOLDERS = ("volprim_rf_basic",)
EXCLUDED = {
    "various_shapes/test_various_shapes_path.xml": "sdfgrid shape (and ../../serialized meshes that are "
                                                   "not in the stored corpus)",
}


@pytest.mark.slow
@pytest.mark.parametrize("rel, spp", cases(SCENES, NOT_YET, 256))
def test_corpus_scene_passes_mitsubas_z_test(rel, spp):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        z = check_scene(rel, spp, **DEFINES.get(rel, {}))
    assert z.passed, f"{rel}: {z}"


def test_the_lists_cover_the_corpus():
    if not CORPUS.is_dir():
        pytest.skip("../shared/corpus/mitsuba-data is not present")
    found = {str(p.relative_to(CORPUS)) for p in CORPUS.rglob("*.xml")
             if re.match(r"(test|scene)_", p.name) and p.parent.name != "refs"
             and p.relative_to(CORPUS).parts[0] not in EXCLUDED_FOLDERS}
    media = set(MEDIA_SCENES) | set(MEDIA_NOT_YET)
    found = {rel for rel in found if rel not in media}
    assert media <= {str(p.relative_to(CORPUS)) for p in CORPUS.rglob("participating_media/test_*.xml")}
    listed = set(SCENES) | set(NOT_YET) | set(EXCLUDED)
    assert found == listed, (sorted(found - listed), sorted(listed - found))
    assert not set(SCENES) & set(NOT_YET)
    assert all(reference_files(CORPUS / rel)[0].is_file() for rel in [*SCENES, *NOT_YET])


# ------------------------------------------------------------ negative controls
@pytest.mark.slow
@pytest.mark.parametrize("rel, spp, old, new", [
    # the directional light 10% brighter
    ("floating_sphere/test_directional_direct.xml", 1024,
     '<rgb name="irradiance" value="1.0"/>', '<rgb name="irradiance" value="1.1"/>'),
    # a dielectric sphere with water's IOR instead of BK7's (1.33 for 1.5168)
    ("bsdf_spheres/test_roughdielectric_path.xml", 2048,
     '<string name="int_ior" value="bk7"/>', '<float name="int_ior" value="1.33"/>'),
    # the projector's image upside down (v -> 1 - v)
    ("projector/test_projector_textured_direct.xml", 1024,
     '<string name="filename" value="textures/carrot.png"/>',
     '<string name="filename" value="textures/carrot.png"/>'
     '<transform name="to_uv"><scale x="1" y="-1"/><translate y="1"/></transform>'),
    # one nearest-filtered (mirror-wrapped) texture read bilinear
    ("texture_interp/test_texture_interp_direct.xml", 1024,
     '<string name="wrap_mode" value="mirror"/>\n                <string name="filter_type" value="nearest"/>',
     '<string name="wrap_mode" value="mirror"/>\n                <string name="filter_type" value="bilinear"/>'),
    # the bump map flattened (scale 0: the sphere without its bumps)
    ("bsdf_spheres/test_bumpmap_path.xml", 1024,
     '<float name="scale" value="0.02"/>', '<float name="scale" value="0"/>'),
], ids=["brighter light", "wrong ior", "projector image flipped", "nearest read bilinear", "flat bump map"])
def test_negative_controls_fail_the_z_test(tmp_path, rel, spp, old, new):
    """The perturbed copy fails; the copy itself (``<path>`` and ``<include>`` made absolute,
    nothing else changed) passes, so the failure is the perturbation's."""
    from support.corpus import _read

    ref, var = (_read(p) for p in reference_files(corpus_scene(rel)))
    results = {}
    for name, value in (("copy", old), ("perturbed", new)):
        path = perturbed(tmp_path / name, rel, old, value)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            results[name] = z_test(render_as_authored(path, spp).image, spp, ref, var)
    assert results["copy"].passed, results["copy"]
    assert not results["perturbed"].passed, f"{rel} with {new}: {results['perturbed']}"


@pytest.mark.slow
def test_no_corpus_scene_has_parameters_drpt_calls_unread():
    """Mitsuba loads every corpus scene, so none has a parameter its plugin does not read:
    drpt's unread-parameter warning (which says Mitsuba refuses such parameters) must not
    name one in any scene it reads (with --ignore-unsupported, for the NOT_YET ones)."""
    from drpt.errors import SceneError
    from drpt.scene import load_scene

    if not CORPUS.is_dir():
        pytest.skip("../shared/corpus/mitsuba-data is not present")
    for rel in [*SCENES, *NOT_YET]:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                load_scene(CORPUS / rel, defines={"spp": "4", **DEFINES.get(rel, {})}, ignore_unsupported=True)
            except SceneError:
                assert rel in NOT_YET, rel
        unread = [str(w.message) for w in caught if "do not read" in str(w.message)]
        assert not unread, (rel, unread)
