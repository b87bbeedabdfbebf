"""Operation count of the largest traced kernels of one render: a timing-free
check that a change leaves a scene's kernels as they were.

    PYTHONPATH=. .venv/bin/python benchmarks/kernel_ops.py SCENE [MODE] [ACCEL] [SAMPLER] [INTEGRATOR] [LIGHTS] \
        [TRIANGLES]

``MODE`` is the material mode (``--bsdf``, default ``auto``), ``ACCEL`` the
accelerator (default ``auto``), ``SAMPLER`` the ``--sampler`` (default
``independent``), ``INTEGRATOR`` the ``--integrator`` (default ``path``), ``LIGHTS`` the
``--light-sampler`` (default ``mixed``, the renderer's), ``TRIANGLES`` the ``--triangle-sampling``
(default ``auto``, the renderer's).
Renders 32x32 at 4 spp with Dr.Jit's kernel history on and prints the
operation counts of the three largest JIT kernels (the fused path kernel is
the largest). Run it from each checkout's root with
``PYTHONPATH=.`` to compare two commits: equal counts mean the same code was
traced (hashes may still differ with evaluation order). ``--all-textures`` (first
argument) makes every texture lookup and gradient trace every texture of the scene
(their ``among`` ignored), to count what ``among`` saves.
"""

import sys

import drjit as dr

from drpt.options import RenderOptions
from drpt.render.renderer import Renderer
from drpt.scene import load_scene


def main(argv: list[str]) -> int:
    if argv and argv[0] == "--all-textures":
        argv = argv[1:]
        from drpt.render.texture import TextureSet

        lookup, gradient = TextureSet.lookup, TextureSet.gradient
        TextureSet.lookup = lambda self, *a, among=None, **k: lookup(self, *a, **k)
        TextureSet.gradient = lambda self, *a, among=None, **k: gradient(self, *a, **k)
    scene_file = argv[0]
    mode = argv[1] if len(argv) > 1 else "auto"
    accel = argv[2] if len(argv) > 2 else "auto"
    sampler = argv[3] if len(argv) > 3 else "independent"
    integrator = argv[4] if len(argv) > 4 else "path"
    lights = argv[5] if len(argv) > 5 else RenderOptions.light_sampler
    triangles = argv[6] if len(argv) > 6 else RenderOptions.triangle_sampling
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    r = Renderer(load_scene(scene_file), RenderOptions(width=32, height=32, spp=4, bsdf=mode, accel=accel,
                                                       sampler=sampler, integrator=integrator,
                                                       light_sampler=lights, triangle_sampling=triangles,
                                                       progress=False))
    dr.kernel_history_clear()
    r.render()
    ops = sorted(k.get("operation_count", 0) for k in dr.kernel_history() if k.get("type") == dr.KernelType.JIT)
    print(scene_file, mode, accel, sampler, integrator, lights, triangles, ops[-3:])
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
