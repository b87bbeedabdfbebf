"""MIS compensation of the sky's next-event density in renders
(:func:`drpt.render.scene.env_compensated`, ``--env-compensation``, the XML's ``mis_compensation``).

A scene lit by an environment map (``tests/data/xml/sky.exr``, turned and scaled) with a
diffuse sphere, a glossy one (rough conductor) and a diffuse floor renders with and without
compensation; the two images agree per 4x4 block (:func:`drpt.testing.block_z`, |z| < 4.5,
the bound of :func:`drpt.testing.assert_agree`; different seeds, so the images are
independent; max |z| 2.4 measured). Negative control: compensation without its MIS
complement (Whitted's direct light, next-event estimation alone, made to use the compensated
density) darkens the image where the sky below its mean lit it (its mean by 3%), and the same
test reads |z| > 8 there (36.6 measured). The integrators
that sample the sky on their own (whitted, ptracer, bdpt) keep the uncompensated density:
their images are the same bit for bit with compensation on or off. So does volpath in a
medium that reaches beyond the shapes (the sky has no MIS complement there).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from drpt.options import RenderOptions, with_scene_settings
from drpt.render import scene as scene_module
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


@pytest.mark.slow
def test_compensated_image_agrees_with_uncompensated(tmp_path):
    scene = load(tmp_path)
    on = render(scene, 1024, 1, env_compensation="on")
    off = render(scene, 1024, 2, env_compensation="off")
    assert on.nonfinite == 0 and off.nonfinite == 0
    z = block_z(on.image, on.variance, off.image, off.variance, block=4)
    assert np.abs(z).max() < ZMAX, np.abs(z).max()
    # and compensation did change the estimator (a different noise, not the same image)
    assert not np.array_equal(on.image, render(scene, 1024, 1, env_compensation="off").image)


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
