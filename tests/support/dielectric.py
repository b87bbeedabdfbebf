"""A stand-in for the material table's lobe-facing API, to test the lobes'
``params(table, si, active)`` without a scene.

It implements what the lobe contract promises (``table.value(name, si,
active)``, ``table.specs_of(kind)``) the way the contract describes it: a
field's per-material value is the module's :func:`derive` output where it
gives one, else the spec's parameter (defaults filled in from
:mod:`drpt.materials.bsdf_kinds`); ``value`` gathers it at ``si.material``. No
textures. ``asked`` records the fields gathered, so a test can check what
a kernel would trace.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import drjit as dr
import numpy as np
from drjit.auto import Array3f, Float, UInt32

from drpt.materials import bsdf_kinds


@dataclass
class Spec:
    """A leaf spec as the lobes see it: ``kind`` and its ``params``."""

    kind: str
    params: dict = field(default_factory=dict)


class _SI:
    def __init__(self, material):
        self.material = UInt32(np.asarray(material, np.uint32))


class FakeTable:
    def __init__(self, specs, module):
        self.specs = list(specs)
        self.module = module
        self.asked: list[str] = []
        rows = []
        for s in self.specs:
            vals = {**bsdf_kinds.defaults(s.kind), **s.params}
            if hasattr(module, "derive"):
                vals.update(module.derive(vals))
            rows.append(vals)
        self._arrays = {}
        for name, kind in module.FIELDS.items():
            col = [r[name] for r in rows]
            if kind == "rgb":
                a = np.array([v if isinstance(v, (tuple, list)) else (v, v, v) for v in col], np.float32)
                self._arrays[name] = (Array3f, Array3f(*(Float(a[:, i].copy()) for i in range(3))))
            else:
                self._arrays[name] = (Float, Float(np.array(col, np.float32)))

    def si(self, material):
        return _SI(material)

    def specs_of(self, kind):
        return [s for s in self.specs if s.kind == kind]

    def value(self, name, si, active):
        self.asked.append(name)
        t, arr = self._arrays[name]
        return dr.gather(t, arr, si.material, active)
