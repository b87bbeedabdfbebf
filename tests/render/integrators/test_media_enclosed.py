"""Next-event estimation left out where it cannot see a light, and one-channel free flight in
gray media (:mod:`drpt.render.integrators.enclosure`, ``MediumTable.gray``).

* Decisions, from small Mitsuba XML scenes (nothing rendered): a medium inside a closed
  dielectric (or rough dielectric, or diffuse) sphere or cube lit from outside is blind; an
  open boundary (a rectangle, a disk, a cylinder), an inside-out cube (``flip_normals``), a ``null``
  or ``thindielectric`` boundary, a light inside the boundary's box (point light, area
  emitter), a medium that is also some shape's exterior or the camera's are not.
  Every medium blind (medium events trace no next-event estimation) or one of two.
* Images: with ``SHADOW_TAU = 0`` (shadow rays draw no random numbers in homogeneous media)
  a render that skips the blind medium's next-event estimation uses the same random numbers
  as one that traces it, so the two images agree to float rounding (relative 1e-4): the
  shadow rays left out carried exactly 0. Negative control: skipping it for the same
  medium behind a ``thindielectric`` sheet (not blind: light passes) darkens the image by
  far more (the mean by more than 5%).
* No next-event estimation anywhere (a blind medium in a glass sphere under an environment
  map): the emitter a sampled ray reaches counts in full without its density, the image the
  one with the lookup bit for bit; negative control: the same shortcut forced beside a
  diffuse floor counts the sky twice (the mean more than 2% up).
* Gray media: the one-channel free flight renders the same image as the spectral MIS
  (same random numbers, relative 1e-4); negative control: a chromatic medium rendered as
  gray (its first channel's extinction for all three) has a channel mean more than 10% off.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

SCENE = """<scene version="3.0.0">
    <default name="bsdf" value="dielectric"/>
    <default name="sigma" value="1, 1, 1"/>
    <integrator type="volpath"><integer name="max_depth" value="12"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 1, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/>
            <rfilter type="box"/></film>
        <sampler type="independent"><integer name="sample_count" value="32"/></sampler>
    </sensor>
    <emitter type="point"><point name="position" x="2" y="3" z="2"/>
        <rgb name="intensity" value="30"/></emitter>
    <medium id="m" type="homogeneous">
        <rgb name="albedo" value="0.9, 0.6, 0.3"/>
        <rgb name="sigma_t" value="$sigma"/>
    </medium>
    <shape type="sphere"><bsdf type="$bsdf"/><ref name="interior" id="m"/></shape>
    <shape type="rectangle">
        <transform name="to_world"><scale value="4"/><rotate x="1" angle="-90"/><translate y="-1"/></transform>
        <bsdf type="diffuse"/>
    </shape>
    <!-- inner -->
</scene>
"""


def _scene(tmp_path, body: str | None = None, inner: str = "", **defines):
    """:data:`SCENE` (or ``body``) with ``inner`` (XML elements) added, loaded."""
    from drpt.scene import load_scene

    path = tmp_path / "scene.xml"
    path.write_text((SCENE if body is None else body).replace("<!-- inner -->", inner))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_scene(path, defines={k: str(v) for k, v in defines.items()})


def _blind(tmp_path, **defines) -> set[int]:
    from drpt.render.integrators.enclosure import blind_media

    return set(blind_media(_scene(tmp_path, **defines)))


# ------------------------------------------------------------------ decisions
@pytest.mark.parametrize("bsdf", ["dielectric", "roughdielectric", "diffuse"])
def test_a_closed_blocking_boundary_lit_from_outside_is_blind(tmp_path, bsdf):
    assert _blind(tmp_path, bsdf=bsdf) == {0}


@pytest.mark.parametrize("bsdf", ["null", "thindielectric"])
def test_a_boundary_that_passes_shadow_rays_is_not_blind(tmp_path, bsdf):
    assert _blind(tmp_path, bsdf=bsdf) == set()


CUBE = '<shape type="cube"><bsdf type="dielectric"/><ref name="interior" id="m"/>{}</shape>'


@pytest.mark.parametrize("extra, blind", [
    ("", {0}),  # a closed mesh (negative control of the next ones)
    ('<boolean name="flip_normals" value="true"/>', set()),  # inside out: the medium is outside the cube
])
def test_a_mesh_boundary_must_be_closed_and_point_out(tmp_path, extra, blind):
    body = SCENE.replace('<shape type="sphere"><bsdf type="$bsdf"/><ref name="interior" id="m"/></shape>',
                         CUBE.format(extra))
    assert _blind(tmp_path, body=body) == blind


@pytest.mark.parametrize("shape", ["rectangle", "cylinder", "disk"])
def test_an_open_boundary_is_not_blind(tmp_path, shape):
    body = SCENE.replace('<shape type="sphere">', f'<shape type="{shape}">')
    assert _blind(tmp_path, body=body) == set()


@pytest.mark.parametrize("inner", [
    '<emitter type="point"><point name="position" x="0.5" y="0.5" z="0.5"/></emitter>',
    # an area emitter in the sphere's box (here inside the sphere)
    '<shape type="sphere"><float name="radius" value="0.1"/><bsdf type="diffuse"/>'
    '<emitter type="area"><rgb name="radiance" value="5"/></emitter></shape>',
])
def test_an_emitter_inside_the_boundary_box_is_not_blind(tmp_path, inner):
    assert _blind(tmp_path, inner=inner) == set()


def test_a_medium_outside_some_shape_or_around_the_camera_is_not_blind(tmp_path):
    outer = ('<shape type="sphere"><float name="radius" value="0.2"/><point name="center" x="2" y="0" z="0"/>'
             '<bsdf type="null"/><ref name="exterior" id="m"/></shape>')
    assert _blind(tmp_path, inner=outer) == set()
    body = SCENE.replace("<sampler", '<ref name="medium" id="m"/><sampler')
    assert _blind(tmp_path, body=body) == set()


def test_media_bounded_inside_closed_shapes_only(tmp_path):
    """``media_bounded`` (MIS compensation of the sky is used only then): a medium inside a
    closed sphere, blocking or not (``null``), is bounded; an open boundary, a medium that
    is some shape's exterior or the camera's is not."""
    from drpt.render.integrators.enclosure import media_bounded

    assert media_bounded(_scene(tmp_path))
    assert media_bounded(_scene(tmp_path, bsdf="null"))
    assert not media_bounded(_scene(tmp_path, body=SCENE.replace('<shape type="sphere">', '<shape type="disk">')))
    outer = ('<shape type="sphere"><float name="radius" value="0.2"/><point name="center" x="2" y="0" z="0"/>'
             '<bsdf type="null"/><ref name="exterior" id="m"/></shape>')
    assert not media_bounded(_scene(tmp_path, inner=outer))
    assert not media_bounded(_scene(tmp_path, body=SCENE.replace("<sampler", '<ref name="medium" id="m"/><sampler')))


def test_closed_outward_on_triangles():
    from drpt.render.integrators.enclosure import closed_outward

    # a tetrahedron, counter-clockwise seen from outside
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    tet = v[faces]
    assert closed_outward(tet)
    assert not closed_outward(tet[:, ::-1])  # inside out
    assert not closed_outward(tet[:3])  # a face missing: open
    assert not closed_outward(np.concatenate([tet, tet]))  # every edge four times
    assert not closed_outward(tet[:0])


def test_gray_and_blind_flags_of_the_medium_table(tmp_path):
    from drpt.render.integrators.volpath import MediumTable

    t = MediumTable(_scene(tmp_path))
    assert t.gray and t.has_blind and t.all_blind
    t = MediumTable(_scene(tmp_path, sigma="1, 2, 3", bsdf="null"))
    assert not t.gray and not t.has_blind and not t.all_blind


# ------------------------------------------------------------------ images
def _render(scene, configure=None) -> np.ndarray:
    from drpt.options import RenderOptions, with_scene_settings
    from drpt.render.renderer import Renderer

    opts, scene = with_scene_settings(RenderOptions(progress=False, seed=3), scene)
    r = Renderer(scene, opts)
    if configure is not None:
        configure(r.integrator.media)
    return np.asarray(r.render().image, np.float64)


def _no_skip(media):
    media.has_blind = media.all_blind = False


def _skip_all(media):
    from drjit.auto import Bool

    media.blind = Bool(np.array([False] + [True] * media.count))
    media.has_blind = media.all_blind = True


#: a second medium, in a null-bounded sphere beside the first (not blind)
FOG = ('<medium id="fog" type="homogeneous"><rgb name="sigma_t" value="0.5"/></medium>'
       '<shape type="sphere"><point name="center" x="-1.6" y="0" z="0"/><float name="radius" value="0.5"/>'
       '<bsdf type="null"/><ref name="interior" id="fog"/></shape>')


@pytest.mark.parametrize("inner, all_blind", [("", True), (FOG, False)])
def test_skipping_blind_next_event_estimation_changes_nothing_but_the_work(tmp_path, monkeypatch, inner,
                                                                          all_blind):
    """Every medium blind (medium events trace no next-event estimation at all), or one of two
    (a lookup of the shadow ray's medium)."""
    from drpt.render.integrators import volpath

    monkeypatch.setattr(volpath, "SHADOW_TAU", 0.0)  # (shadow rays draw nothing: the same stream)
    scene = _scene(tmp_path, inner=inner)
    assert volpath.MediumTable(scene).all_blind == all_blind
    skipped = _render(scene)
    traced = _render(scene, _no_skip)
    assert skipped.mean() > 0.0 and np.isfinite(skipped).all()
    assert np.allclose(skipped, traced, rtol=1e-4, atol=1e-6 * traced.max())
    # negative control: the same skip where shadow rays do pass (a thindielectric sheet)
    thin = _scene(tmp_path, bsdf="thindielectric")
    seen, dropped = _render(thin), _render(thin, _skip_all)
    assert dropped.mean() < 0.95 * seen.mean(), (dropped.mean(), seen.mean())


def test_gray_free_flight_renders_like_spectral_mis(tmp_path):
    def spectral(media):
        media.gray = False

    def forced_gray(media):
        media.gray = True

    scene = _scene(tmp_path, bsdf="null")
    gray, mis = _render(scene), _render(scene, spectral)
    assert gray.mean() > 0.0
    assert np.allclose(gray, mis, rtol=1e-4, atol=1e-6 * mis.max())
    # negative control: a chromatic medium taken for gray (channel 0's extinction everywhere)
    chroma = _scene(tmp_path, bsdf="null", sigma="0.2, 3, 9")
    right, wrong = _render(chroma), _render(chroma, forced_gray)
    off = np.abs(wrong.mean((0, 1)) - right.mean((0, 1))) / right.mean((0, 1))
    assert off.max() > 0.1, off  # (0.19 in the green channel)


#: a medium in a glass sphere under an environment map, nothing else: no vertex can take a
#: next-event estimate (a delta surface, a blind medium)
GLASS_UNDER_SKY = """<scene version="3.0.0">
    <integrator type="volpath"><integer name="max_depth" value="12"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 1, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/>
            <rfilter type="box"/></film>
        <sampler type="independent"><integer name="sample_count" value="32"/></sampler>
    </sensor>
    <emitter type="envmap"><string name="filename" value="sky.exr"/></emitter>
    <medium id="m" type="homogeneous">
        <rgb name="albedo" value="0.9, 0.6, 0.3"/>
        <rgb name="sigma_t" value="1, 1, 1"/>
    </medium>
    <shape type="sphere"><bsdf type="dielectric"/><ref name="interior" id="m"/></shape>
    <!-- inner -->
</scene>
"""


def test_without_next_event_estimation_no_emitter_density_is_looked_up(tmp_path, monkeypatch):
    """``VolPathIntegrator.traces_nee``: where no vertex can take a next-event estimate (delta
    surfaces, every medium blind), an emitter a sampled ray reaches counts in full and its
    density is not looked up; the image is the one with the lookup, bit for bit. Negative
    control: the same shortcut forced in a scene with a diffuse floor (next-event estimation
    there) counts the sky twice where both techniques reach it (the mean more than 2% up)."""
    from drpt.imageio import write_image
    from drpt.options import RenderOptions, with_scene_settings
    from drpt.render.integrators import volpath
    from drpt.render.renderer import Renderer

    sky = np.ones((8, 16, 3), np.float32) * np.linspace(3.0, 0.2, 8, dtype=np.float32)[:, None, None]
    write_image(tmp_path / "sky.exr", sky)

    def render(scene, nee=None):
        if nee is not None:
            monkeypatch.setattr(volpath.VolPathIntegrator, "traces_nee", property(lambda self: nee))
        opts, scene = with_scene_settings(RenderOptions(progress=False, seed=3), scene)
        r = Renderer(scene, opts)
        img = np.asarray(r.render().image, np.float64)
        monkeypatch.undo()
        return r.integrator, img

    glass = _scene(tmp_path, body=GLASS_UNDER_SKY)
    integrator, skipped = render(glass)
    assert not integrator.traces_nee
    _, looked_up = render(glass, True)
    assert skipped.mean() > 0.0 and np.array_equal(skipped, looked_up)
    floor = ('<shape type="rectangle"><transform name="to_world"><scale value="4"/><rotate x="1" angle="-90"/>'
             '<translate y="-1"/></transform><bsdf type="diffuse"/></shape>')
    lit = _scene(tmp_path, body=GLASS_UNDER_SKY, inner=floor)
    integrator, right = render(lit)
    assert integrator.traces_nee
    _, wrong = render(lit, False)
    assert wrong.mean() > 1.02 * right.mean(), (wrong.mean(), right.mean())
