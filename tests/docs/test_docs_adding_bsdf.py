"""The worked example "Adding a BSDF" of docs/architecture.md runs as written: its lobe module
(the first code block) is loaded as ``drpt.render.bsdf.oren_nayar``, registered with the
registry line (the second block) and the ``PARAMS`` and ``TEXTURABLE`` entries the doc names,
and then

* its sampling matches its pdf (``drpt.testing.bsdf_chi2``, significance 1%),
* its albedo is at most 1 and, at ``kd = 1, sigma = 0``, equal to 1 (``drpt.testing.furnace``,
  5 standard errors),
* a scene whose materials are ``oren_nayar`` renders, and at ``sigma = 0`` like ``diffuse``
  (images equal to 1e-4: the two lobes are the same function then).

Negative controls: the example with ``A = 1`` (no energy lost to the facets' shadowing) fails
the furnace (albedo > 1), a scene naming the kind without the ``PARAMS`` entry is refused, and
without the ``TEXTURABLE`` entry (the fourth edit, for textures only) a texture on it is refused
while constants are still read."""

from __future__ import annotations

import importlib.util
import re
import sys
from dataclasses import replace

import numpy as np
import pytest
from drjit.auto import Array3f, Float

from drpt.materials import bsdf_kinds
from drpt.render import bsdf as bsdf_pkg
from drpt.testing import bsdf_chi2, furnace

NAME = "drpt.render.bsdf.oren_nayar"
WIS = [(0.0, 0.0, 1.0), (0.7, 0.0, 0.714), (0.98, 0.0, 0.199)]


@pytest.fixture(scope="module")
def section(repo) -> str:
    """The text of docs/architecture.md's "Adding a BSDF"."""
    return (repo / "docs" / "architecture.md").read_text().split("## Adding a BSDF", 1)[1].split("\n## ", 1)[0]


def _blocks(section: str) -> list[str]:
    return re.findall(r"```python\n(.*?)```", section, re.S)


def _load(tmp_path, source: str):
    path = tmp_path / "oren_nayar.py"
    path.write_text(source)
    spec = importlib.util.spec_from_file_location(NAME, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture
def oren_nayar(tmp_path, monkeypatch, section):
    """The doc's module, registered the way the doc says (the registry line and the
    ``PARAMS`` entry; ``LEAF_KINDS``/``ALL_KINDS`` are derived from ``PARAMS`` at import)."""
    module_src, registry_src = _blocks(section)[:2]
    assert module_src.startswith("# drpt/render/bsdf/oren_nayar.py")
    mod = _load(tmp_path, module_src)
    monkeypatch.setitem(sys.modules, NAME, mod)
    for kind, module in re.findall(r'"(\w+)": "(\w+)",', registry_src):
        monkeypatch.setitem(bsdf_pkg.REGISTRY, kind, module)
    entry = re.search(r'`("oren_nayar": \{.*?\})` to `PARAMS`', section, re.S).group(1)
    kind, params = eval("{" + entry + "}", {"GRAY": bsdf_kinds.GRAY}).popitem()
    monkeypatch.setitem(bsdf_kinds.PARAMS, kind, params)
    tex = re.search(r'`"oren_nayar": (frozenset\(.*?\))` to\s+`TEXTURABLE`', section, re.S).group(1)
    monkeypatch.setitem(bsdf_kinds.TEXTURABLE, kind, eval(tex))
    monkeypatch.setattr(bsdf_kinds, "LEAF_KINDS", tuple(bsdf_kinds.PARAMS))
    monkeypatch.setattr(bsdf_kinds, "ALL_KINDS", bsdf_kinds.LEAF_KINDS + tuple(bsdf_kinds.COMPOSITES))
    assert bsdf_pkg.lobe("oren_nayar") is mod
    return mod


def _sampler(mod, kd, sigma):
    p = mod.OrenNayarParams(Array3f(*kd), Float(sigma))
    return lambda wi, u1, u2: mod.sample(p, wi, u1, u2)


@pytest.mark.parametrize("sigma", [0.0, 0.3, 1.0])
def test_furnace(oren_nayar, sigma):
    r = furnace(_sampler(oren_nayar, (1.0, 1.0, 1.0), sigma), WIS, n=100_000, lossless=sigma == 0.0)
    assert r.passed, r.message
    assert np.all(r.albedo > 0.5)


def test_furnace_catches_a_lobe_without_its_a_loss(tmp_path, section):
    src = _blocks(section)[0].replace("a = 1.0 - s / (2.0 * (s + 0.33))", "a = 1.0")
    assert src != _blocks(section)[0]
    mod = _load(tmp_path, src)
    assert not furnace(_sampler(mod, (1.0, 1.0, 1.0), 1.0), WIS, n=100_000).passed


@pytest.mark.mitsuba
@pytest.mark.parametrize("sigma", [0.0, 0.5])
def test_sampling_matches_pdf(oren_nayar, sigma):
    p = oren_nayar.OrenNayarParams(Array3f(0.5), Float(sigma))
    ok, msg = bsdf_chi2(oren_nayar, p, WIS[1], sample_count=100_000, res=31)
    assert ok, msg


def _render(kind_of, cornell):
    from drpt.materials.spec import BSDFSpec
    from drpt.options import RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    scene = load_scene(cornell)
    mats = []
    for m in scene.materials:
        kd = tuple(float(c) for c in m.kd)
        mats.append(replace(m, bsdf=BSDFSpec("twosided", children=[kind_of(kd, BSDFSpec)])))
    scene.materials[:] = mats
    return Renderer(scene, RenderOptions(width=16, height=16, spp=8, seed=3, progress=False)).render()


def test_a_scene_renders_it_like_diffuse_at_sigma_zero(oren_nayar, cornell):
    on = _render(lambda kd, S: S("oren_nayar", {"kd": kd, "sigma": 0.0}), cornell)
    di = _render(lambda kd, S: S("diffuse", {"kd": kd}), cornell)
    assert on.nonfinite == 0 and np.all(np.isfinite(on.image)) and on.image.mean() > 0.01
    assert np.allclose(on.image, di.image, rtol=1e-4, atol=1e-5)
    rough = _render(lambda kd, S: S("oren_nayar", {"kd": kd, "sigma": 0.5}), cornell)
    assert np.all(np.isfinite(rough.image)) and not np.allclose(rough.image, di.image, rtol=1e-3)


def test_the_kind_needs_its_params_entry(oren_nayar, monkeypatch):
    from drpt.materials.spec import BSDFSpec, complete

    monkeypatch.delitem(bsdf_kinds.PARAMS, "oren_nayar")
    monkeypatch.setattr(bsdf_kinds, "ALL_KINDS", tuple(bsdf_kinds.PARAMS) + tuple(bsdf_kinds.COMPOSITES))
    with pytest.raises(ValueError, match="unknown BSDF kind"):
        complete(BSDFSpec("oren_nayar", {"sigma": 0.1}))


def test_textures_need_the_texturable_entry(oren_nayar, monkeypatch, tmp_path):
    from drpt.materials.spec import BSDFSpec, Texture, complete

    tex = Texture(tmp_path / "k.png", 0.5)
    assert complete(BSDFSpec("oren_nayar", {"kd": tex})).params["kd"] is tex
    monkeypatch.delitem(bsdf_kinds.TEXTURABLE, "oren_nayar")
    with pytest.raises(ValueError, match="cannot be a texture"):
        complete(BSDFSpec("oren_nayar", {"kd": tex}))
    assert complete(BSDFSpec("oren_nayar", {"sigma": 0.2})).params == {"kd": bsdf_kinds.GRAY, "sigma": 0.2}
