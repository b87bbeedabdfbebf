"""MIS compensation of the sky's next-event density in renders
(:func:`drpt.render.scene.env_compensated`, ``--env-compensation``, the XML's ``mis_compensation``).

A scene lit by an environment map (``tests/data/xml/sky.exr``, turned and scaled) with a
diffuse sphere, a glossy one (rough conductor) and a diffuse floor renders with and without
compensation, in each of :data:`VARIANTS`: the megakernel's unrolled straight paths (depth
3) and its bounce loop (depth 6), the wavefront, volpath with a ball of fog inside a closed
``null`` sphere (media bounded by closed shapes, where volpath compensates), a ``mask``, a
``blendbsdf``, a ``twosided`` rough plastic seen from behind, a ``normalmap`` on the floor,
and ``hide_emitters``. The two images agree per 4x4 block (:func:`drpt.testing.block_z`,
|z| < 4.5, the bound of :func:`drpt.testing.assert_agree`; 2048 spp, different seeds, so the
images are independent; max |z| 3.0 measured over the variants). Negative controls: (1) with
compensated sampling, the MIS weight of a BSDF or phase sample that reaches the sky computed
from the map's uncompensated density (the two techniques' weights no longer sum to 1) fails
the same test in every variant (max |z| 7.5 to 14.1 measured); (2) compensation without its
MIS complement (Whitted's direct light, next-event estimation alone, made to use the
compensated density) darkens the image where the sky below its mean lit it (its mean by 3%),
and the same test reads |z| > 8 there (36.6 measured at 1024 spp). The integrators that
sample the sky on their own (whitted, ptracer, bdpt) keep the uncompensated density: their
images are the same bit for bit with compensation on or off. So does volpath in a medium
that reaches beyond the shapes (the sky has no MIS complement there).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from drpt.options import RenderOptions, with_scene_settings
from drpt.render import scene as scene_module
from drpt.render.lights.envmap import EnvironmentLight
from drpt.render.renderer import Renderer
from drpt.scene import load_scene
from drpt.testing import block_z

SKY = Path(__file__).resolve().parents[1] / "data" / "xml" / "sky.exr"

SCENE = """<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 1.5, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="16"/></sampler>
        <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="24"/>
            <rfilter type="box"/></film>
    </sensor>
    <integrator type="path"><integer name="max_depth" value="3"/></integrator>
    <shape type="sphere"><float name="radius" value="0.6"/><point name="center" x="-0.7" y="0" z="0"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.8"/></bsdf></shape>
    <shape type="sphere"><float name="radius" value="0.6"/><point name="center" x="0.7" y="0" z="0"/>
        <bsdf type="roughconductor"><float name="alpha" value="0.15"/></bsdf></shape>
    <shape type="rectangle">
        <transform name="to_world"><scale value="3"/><rotate x="1" angle="-90"/><translate y="-0.6"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.5"/></bsdf>
    </shape>
    <emitter type="envmap">
        <string name="filename" value="{sky}"/>
        <float name="scale" value="1.5"/>
        {comp}
        <transform name="to_world"><rotate y="1" angle="90"/></transform>
    </emitter>
</scene>
"""

ZMAX = 4.5
#: samples per pixel of the agreement tests
SPP = 2048


def load(tmp_path, comp: str = ""):
    """The scene, with ``comp`` inside its envmap (a ``mis_compensation`` element or nothing)."""
    path = tmp_path / "env.xml"
    path.write_text(SCENE.format(sky=SKY, comp=comp))
    return load_scene(path)


def render(scene, spp: int, seed: int, **kw):
    opts, scene = with_scene_settings(RenderOptions(progress=False, seed=seed), scene)
    opts = replace(opts, spp=spp, **kw)
    return Renderer(scene, opts.validate()).render()


def nee_environment(scene, **kw):
    """The map next-event estimation samples (``DeviceScene.sky``); the light tracers' own
    (``DeviceScene.environment``, :meth:`~drpt.render.scene.DeviceScene.sample_environment`)
    is never compensated."""
    opts, scene = with_scene_settings(RenderOptions(progress=False), scene)
    r = Renderer(scene, replace(opts, **kw).validate())
    assert r.scene.environment.env.offset == 0.0
    return r.scene.sky.env.env  # (through the map's rotation)


def test_xml_and_option_decide(tmp_path):
    """The file's ``mis_compensation`` wins over ``env_compensation``; without it the option
    decides; the light tracers and Whitted never compensate."""
    plain = load(tmp_path)
    assert plain.lights[0].mis_compensation is None
    assert nee_environment(plain, env_compensation="on").offset > 0.0
    assert nee_environment(plain, env_compensation="off").offset == 0.0
    on = load(tmp_path, '<boolean name="mis_compensation" value="true"/>')
    off = load(tmp_path, '<boolean name="mis_compensation" value="false"/>')
    assert on.lights[0].mis_compensation is True and off.lights[0].mis_compensation is False
    assert nee_environment(on, env_compensation="off").offset > 0.0
    assert nee_environment(off, env_compensation="on").offset == 0.0
    assert nee_environment(on, integrator="volpath").offset > 0.0
    for integrator in ("whitted", "ptracer", "bdpt"):
        assert nee_environment(on, integrator=integrator).offset == 0.0


def test_not_in_a_medium_beyond_the_shapes(tmp_path):
    """In a medium that reaches beyond every shape (here the camera's) a sampled ray scatters
    before it reaches the sky, so the sky has no MIS complement there: volpath keeps the
    uncompensated density. Inside a closed ``null`` sphere the medium is bounded: compensated."""
    medium = ('<medium id="fog" type="homogeneous"><rgb name="sigma_t" value="0.05"/>'
              '<rgb name="albedo" value="0.5"/></medium>')
    camera = SCENE.replace("<sampler", '<ref name="medium" id="fog"/><sampler').replace(
        "<emitter type=\"envmap\">", medium + "<emitter type=\"envmap\">")
    (tmp_path / "fog.xml").write_text(camera.format(sky=SKY, comp=""))
    assert nee_environment(load_scene(tmp_path / "fog.xml"), integrator="volpath").offset == 0.0
    ball = ('<shape type="sphere"><float name="radius" value="2.5"/><bsdf type="null"/>'
            '<ref name="interior" id="fog"/></shape>')
    inside = SCENE.replace("<emitter type=\"envmap\">", medium + ball + "<emitter type=\"envmap\">")
    (tmp_path / "ball.xml").write_text(inside.format(sky=SKY, comp=""))
    assert nee_environment(load_scene(tmp_path / "ball.xml"), integrator="volpath").offset > 0.0


DIFFUSE_SPHERE = '<bsdf type="diffuse"><rgb name="reflectance" value="0.8"/></bsdf></shape>'
CONDUCTOR_SPHERE = '<bsdf type="roughconductor"><float name="alpha" value="0.15"/></bsdf></shape>'
FLOOR = '<bsdf type="diffuse"><rgb name="reflectance" value="0.5"/></bsdf>\n    </shape>'
ENVMAP = '<emitter type="envmap">'
DEPTH = '<integer name="max_depth" value="3"/>'
NORMALS = SKY.parent / "normals.png"

#: a ball of fog (radius 0.45) in front of the spheres, inside a closed ``null`` sphere that
#: passes shadow rays: the media lie inside closed shapes
#: (:func:`~drpt.render.integrators.enclosure.media_bounded`), so volpath compensates
FOG_BALL = ('<medium id="fog" type="homogeneous"><rgb name="sigma_t" value="2"/>'
            '<rgb name="albedo" value="0.8"/></medium>'
            '<shape type="sphere"><float name="radius" value="0.45"/><point name="center" x="0" y="0.1" z="1"/>'
            '<bsdf type="null"/><ref name="interior" id="fog"/></shape>' + ENVMAP)

#: a rough plastic square behind the spheres that shows the camera and the sky its back
BACK_PLASTIC = ('<shape type="rectangle"><transform name="to_world"><scale value="0.7"/>'
                '<rotate y="1" angle="160"/><translate y="0.4" z="-1.3"/></transform>'
                '<bsdf type="twosided"><bsdf type="roughplastic"><float name="alpha" value="0.2"/>'
                '<rgb name="diffuse_reflectance" value="0.3, 0.5, 0.7"/></bsdf></bsdf></shape>' + ENVMAP)

#: name: (replacements in :data:`SCENE`, render options)
VARIANTS = {
    "path depth 3": ({}, {}),  # the megakernel's unrolled straight paths
    "path loop": ({DEPTH: DEPTH.replace("3", "6")}, {}),  # depth 6: the megakernel's bounce loop
    "wavefront": ({DEPTH: DEPTH.replace("3", "6")}, {"mode": "wavefront"}),
    "volpath bounded fog": ({'type="path"': 'type="volpath"', ENVMAP: FOG_BALL}, {}),
    "mask": ({DIFFUSE_SPHERE: '<bsdf type="mask"><float name="opacity" value="0.6"/><bsdf type="twosided">'
              + DIFFUSE_SPHERE.replace("</shape>", "</bsdf></bsdf></shape>")}, {}),
    "blend": ({CONDUCTOR_SPHERE: '<bsdf type="blendbsdf"><float name="weight" value="0.4"/>'
               '<bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.4, 0.2"/></bsdf>'
               + CONDUCTOR_SPHERE.replace("</shape>", "</bsdf></shape>")}, {}),
    "twosided rough plastic": ({ENVMAP: BACK_PLASTIC}, {}),
    "normal map": ({FLOOR: '<bsdf type="normalmap"><texture name="normalmap" type="bitmap">'
                    f'<boolean name="raw" value="true"/><string name="filename" value="{NORMALS}"/>'
                    '</texture>' + FLOOR.replace("\n    </shape>", "</bsdf></shape>")}, {}),
    "hide_emitters": ({DEPTH: DEPTH + '<boolean name="hide_emitters" value="true"/>'}, {}),
}


def load_variant(tmp_path, variant: str):
    """The scene of :data:`VARIANTS` ``variant`` and its render options."""
    edits, options = VARIANTS[variant]
    xml = SCENE
    for old, new in edits.items():
        assert old in xml, old
        xml = xml.replace(old, new)
    path = tmp_path / "variant.xml"
    path.write_text(xml.format(sky=SKY, comp=""))
    return load_scene(path), options


def on_off_z(tmp_path, variant: str) -> float:
    """The largest |block z| between the compensated and the uncompensated image of
    ``variant`` (:data:`SPP`, seeds 1 and 2)."""
    scene, kw = load_variant(tmp_path, variant)
    on = render(scene, SPP, 1, env_compensation="on", **kw)
    off = render(scene, SPP, 2, env_compensation="off", **kw)
    assert on.nonfinite == 0 and off.nonfinite == 0
    return float(np.abs(block_z(on.image, on.variance, off.image, off.variance, block=4)).max())


@pytest.mark.slow
@pytest.mark.parametrize("variant", list(VARIANTS))
def test_compensated_image_agrees_with_uncompensated(tmp_path, variant):
    """On and off agree (|block z| < :data:`ZMAX`) in each of :data:`VARIANTS`, where
    compensation is in use (the map next-event estimation samples has an offset) and
    changes the estimator (the same seed gives another image)."""
    scene, kw = load_variant(tmp_path, variant)
    assert nee_environment(scene, env_compensation="on", **kw).offset > 0.0
    z = on_off_z(tmp_path, variant)
    assert z < ZMAX, z
    # and compensation did change the estimator (a different noise, not the same image)
    on = render(scene, 64, 1, env_compensation="on", **kw)
    assert not np.array_equal(on.image, render(scene, 64, 1, env_compensation="off", **kw).image)


def mis_blind_to_compensation(monkeypatch):
    """Next-event estimation samples the compensated map, but every other query of its
    density (the MIS weight of a BSDF or phase sample that reaches the sky) reads the
    uncompensated one: the weights of the two techniques no longer sum to 1."""
    real_compensated, real_eval_pdf, real_sample = (
        EnvironmentLight.compensated, EnvironmentLight._eval_pdf, EnvironmentLight.sample)
    sampling = []  # (while a kernel is traced: Python runs once per trace)

    def compensated(self):
        out = real_compensated(self)
        if out is not self:
            out.plain = self
        return out

    def eval_pdf(self, d, active, want_pdf=True):
        le, pdf = real_eval_pdf(self, d, active, want_pdf)
        plain = getattr(self, "plain", None)
        if plain is not None and want_pdf and not sampling:
            pdf = real_eval_pdf(plain, d, active)[1]
        return le, pdf

    def sample(self, u, active=True):
        sampling.append(True)
        try:
            return real_sample(self, u, active)
        finally:
            sampling.pop()

    monkeypatch.setattr(EnvironmentLight, "compensated", compensated)
    monkeypatch.setattr(EnvironmentLight, "_eval_pdf", eval_pdf)
    monkeypatch.setattr(EnvironmentLight, "sample", sample)


@pytest.mark.slow
@pytest.mark.parametrize("variant", list(VARIANTS))
def test_negative_control_mis_weights_that_ignore_compensation(tmp_path, monkeypatch, variant):
    """The agreement test above fails in every variant when the MIS weights of the sky's
    hits ignore compensation (:func:`mis_blind_to_compensation`)."""
    mis_blind_to_compensation(monkeypatch)
    z = on_off_z(tmp_path, variant)
    assert z > ZMAX, z


@pytest.mark.slow
def test_negative_control_compensation_without_mis_is_biased(tmp_path, monkeypatch):
    """Whitted's direct light is next-event estimation alone: with the compensated density it
    never samples the sky below its mean, and the z-test above sees it."""
    scene = load(tmp_path)
    off = render(scene, 1024, 2, integrator="whitted")
    monkeypatch.setattr(scene_module, "COMPENSATED_INTEGRATORS", ("path", "volpath", "whitted"))
    biased = render(scene, 1024, 1, integrator="whitted", env_compensation="on")
    z = block_z(biased.image, biased.variance, off.image, off.variance, block=4)
    assert np.abs(z).max() > 8.0, np.abs(z).max()
    assert biased.image.mean() < off.image.mean()


@pytest.mark.slow
@pytest.mark.parametrize("integrator", ["whitted", "ptracer", "bdpt"])
def test_integrators_without_mis_complement_ignore_compensation(tmp_path, integrator):
    scene = load(tmp_path, '<boolean name="mis_compensation" value="true"/>')
    a = render(scene, 4, 1, integrator=integrator, env_compensation="on")
    b = render(load(tmp_path), 4, 1, integrator=integrator, env_compensation="off")
    np.testing.assert_array_equal(a.image, b.image)


def _sky_z(tmp_path) -> float:
    """The largest |block z| between the sky scene rendered with the map's importance
    sampling (its alias tables, :func:`drpt.render.lights.envmap.alias_tables`; compensation
    off) and with uniform sphere sampling (no tables), :data:`SPP`, seeds 3 and 4."""
    scene = load(tmp_path)
    tables = render(scene, SPP, 3, env_compensation="off")
    sphere = render(scene, SPP, 4, env_compensation="off", env_sampling="uniform")
    return float(np.abs(block_z(tables.image, tables.variance, sphere.image, sphere.variance, block=4)).max())


@pytest.mark.slow
def test_sky_sampled_by_its_tables_agrees_with_uniform_sphere_sampling(tmp_path, monkeypatch):
    """Next-event estimation of the sky by its alias tables is unbiased: the image agrees with
    the one whose sky is sampled uniformly over the sphere (|block z| < :data:`ZMAX`; the
    measured values are in docs/performance.md). Negative control: a pick that ignores the
    alias (each cell kept with its threshold alone, the table's density unchanged) samples
    other cells than the density says, and the image disagrees."""
    from drjit.auto import UInt32

    from drpt.render.lights import envmap

    z = _sky_z(tmp_path)
    assert z < ZMAX, z

    def no_alias(table, base, n, u):
        x = u * n
        i = envmap.dr.minimum(UInt32(x), n - 1)
        return i, x - envmap.Float(i)

    monkeypatch.setattr(envmap, "_pick", no_alias)
    z_control = _sky_z(tmp_path)
    assert z_control > 2 * ZMAX, z_control
