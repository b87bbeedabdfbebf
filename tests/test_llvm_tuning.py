"""drpt's tuning of Dr.Jit's LLVM backend (drpt/llvm_tuning.py)."""

import os
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from drpt import backend, llvm_tuning
from drpt.llvm_tuning import FEATURE, tuned_features

ROOT = Path(__file__).resolve().parents[1]
ZEN3 = "+avx,+avx2,+fma,-avx512f,+sse4.2"
AVX512 = "+avx,+avx2,+fma,+avx512f,+avx512vl"


@pytest.mark.parametrize("cpu, features, env, added", [
    ("znver3", ZEN3, None, True),  # measured: hardware gathers pay
    ("znver3", ZEN3, "0", False),  # the user keeps Dr.Jit's target
    ("znver2", ZEN3, None, False),  # not measured: Dr.Jit's choice stays
    ("znver2", ZEN3, "1", True),  # the user asks for it
    ("skylake-avx512", AVX512, "1", False),  # AVX-512: LLVM uses gathers already
    ("x86-64", "+sse4.2,-avx2", "1", False),  # no AVX2 gather instruction
])
def test_tuned_features(cpu, features, env, added):
    out = tuned_features(cpu, features, env)
    assert (out == features + "," + FEATURE) if added else (out == features)


def test_tuning_is_not_added_twice():
    once = tuned_features("znver3", ZEN3)
    assert tuned_features("znver3", once, "1") == once


def _llvm_or_skip():
    backend.ensure()
    if backend.name() != "llvm" or llvm_tuning.current() is None:
        pytest.skip("needs Dr.Jit's LLVM backend and its tuning functions")


def test_apply_tunes_once_and_dr_default_restores():
    _llvm_or_skip()
    tuned = llvm_tuning.apply()
    default = llvm_tuning._default
    expected = tuned_features(default.cpu, default.features, os.environ.get(llvm_tuning.ENV_VAR))
    assert tuned == replace(default, features=expected)  # the blocks are per launch
    assert llvm_tuning.fast_gather() == (FEATURE in expected.split(","))
    assert llvm_tuning.apply() == tuned == llvm_tuning.current()  # once: later calls keep it
    with llvm_tuning.dr_default():
        assert llvm_tuning.current() == default
    assert llvm_tuning.current() == tuned


@pytest.mark.parametrize("n, threads, size", [
    (65536, 2, 4096),  # 256x256 at one lane per pixel: 16 blocks
    (22500, 2, 1024),  # 150x150: 22 blocks (4096 would leave a short sixth block)
    (1 << 21, 2, 16384),  # a full pass: Dr.Jit's default block size
    (65536, 16, 512),
    (100, 2, 16),  # tiny: the smallest block Dr.Jit takes (a power of two above 8)
])
def test_block_size_for(n, threads, size):
    b = llvm_tuning.block_size_for(n, threads, 8)
    assert b == size and b & (b - 1) == 0 and b > 8
    assert b in (llvm_tuning.MAX_BLOCK, 16) or -(-n // b) >= llvm_tuning.BLOCKS_PER_THREAD * threads


def test_blocks_for_sets_and_restores_the_block_size():
    _llvm_or_skip()
    import drjit as dr

    before = llvm_tuning.current()
    with llvm_tuning.blocks_for(65536):
        want = llvm_tuning.block_size_for(65536, dr.thread_count(), llvm_tuning.core().vector_width())
        assert llvm_tuning.current() == replace(before, block_size=want)
    assert llvm_tuning.current() == before
    with pytest.raises(ValueError, match="power of two"):
        llvm_tuning._set(replace(before, block_size=3000))  # would abort in C++
    assert llvm_tuning.current() == before


def test_tuned_backend_renders_the_same_image_bit_for_bit(monkeypatch):
    """Only code generation and work splitting change: a render with AVX2
    gather instructions and small blocks equals one with scalarized gathers and
    Dr.Jit's blocks, bit for bit (a miscompile in either would show here)."""
    _llvm_or_skip()
    tuned = llvm_tuning.apply()
    flags = tuned.features.split(",")
    if "+avx2" not in flags or "+avx512f" in flags:
        pytest.skip("the gather tuning applies to AVX2 CPUs without AVX-512")
    from drpt.options import RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    scene = load_scene(ROOT / "scenes/cornellbox/cornellbox.txt")
    opts = RenderOptions(width=24, height=24, spp=4, bsdf="phong", progress=False).validate()
    renderer = Renderer(scene, opts)
    plain = ",".join(f for f in flags if f != FEATURE)
    images = []
    try:
        for features, block in ((plain, 16384), (plain + "," + FEATURE, 16)):
            llvm_tuning._set(replace(tuned, features=features))
            monkeypatch.setattr(llvm_tuning, "block_size_for", lambda n, t, w, b=block: b)
            images.append(renderer.render().image)
    finally:
        llvm_tuning._set(tuned)
    assert images[0].max() > 0
    assert np.array_equal(images[0], images[1])


def test_renderer_launches_its_path_kernel_in_sized_blocks(monkeypatch):
    """Each pass's path kernel runs inside ``blocks_for`` with the pass's lane count."""
    from drpt.options import RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    seen = []
    real = llvm_tuning.blocks_for

    def spy(n):
        seen.append(n)
        return real(n)

    monkeypatch.setattr(llvm_tuning, "blocks_for", spy)
    scene = load_scene(ROOT / "scenes/cornellbox/cornellbox.txt")
    opts = RenderOptions(width=16, height=8, spp=2, bsdf="phong", progress=False).validate()
    Renderer(scene, opts).render()
    assert seen and all(n % (16 * 8) == 0 for n in seen)  # whole pixels' lanes, every pass
