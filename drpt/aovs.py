"""AOVs (arbitrary output variables): first-hit quantities written beside the beauty image.

The vocabulary is that of Mitsuba 3's ``aov`` integrator (``src/integrators/aov.cpp``): an
AOV is a ``name:type`` pair and its EXR channels are ``<name>.<suffix>``:

============== ========== =====================================================
type           channels   value at the camera ray's first hit (0 on a miss)
============== ========== =====================================================
``albedo``     ``R G B``  the material's diffuse reflectance (its diffuse color, else
                          ``pi f(wi, n)``, 0 for delta lobes: Mitsuba's
                          ``eval_diffuse_reflectance``)
``depth``      ``T``      the ray distance ``t`` (from a Mitsuba perspective sensor's
                          ``near_clip`` plane, where Mitsuba's rays start)
``position``   ``X Y Z``  the world-space hit point
``uv``         ``U V``    Mitsuba's texture coordinates (``(u, 1 - v)`` of OBJ uvs)
``geo_normal`` ``X Y Z``  the geometric normal (triangle winding, sphere outward)
``sh_normal``  ``X Y Z``  the shading normal (interpolated vertex normals)
``prim_index`` ``I``      the face's index in its shape (0 on analytic shapes; Mitsuba
                          numbers the faces of meshes it merges, those sharing a BSDF,
                          on from one mesh to the next)
``shape_index`` ``I``     the shape's place in Mitsuba's ``scene.shapes()``, from 1 (as
                          Mitsuba's scalar variants number them; its JIT variants write
                          pointer bits): the shapes that are not meshes in file order,
                          then the meshes in file order (Mitsuba's own order of several
                          meshes varies from load to load); Mitsuba XML scenes only
============== ========== =====================================================

On the command line (``--aovs``) a bare type names itself (``depth`` is ``depth:depth``)
and ``normal`` is ``sh_normal``. Mitsuba's ``dp_du``, ``dp_dv``, ``duv_dx`` and ``duv_dy``
are not supported.

Two more kinds feed the denoiser (:mod:`drpt.denoise`) and are not written:
``guide_albedo`` and ``guide_normal``, the albedo and shading normal of the first
*non-delta* surface (the camera ray follows mirror and glass lobes to it), as Intel Open
Image Denoise expects its auxiliary images.

This module imports no kernel; :mod:`drpt.render.aov` traces the values.
"""

from __future__ import annotations

from .errors import DrptError

#: AOV type -> channel suffixes (Mitsuba's)
CHANNELS: dict[str, tuple[str, ...]] = {
    "albedo": ("R", "G", "B"),
    "depth": ("T",),
    "position": ("X", "Y", "Z"),
    "uv": ("U", "V"),
    "geo_normal": ("X", "Y", "Z"),
    "sh_normal": ("X", "Y", "Z"),
    "prim_index": ("I",),
    "shape_index": ("I",),
}
#: the kinds read from the scene's shape data (Mitsuba XML only)
INDEX_KINDS = ("prim_index", "shape_index")
#: Mitsuba's types drpt does not compute
UNSUPPORTED = ("dp_du", "dp_dv", "duv_dx", "duv_dy")
ALIASES = {"normal": "sh_normal"}
#: the denoiser's auxiliary images (first non-delta hit), never written as layers
GUIDES: dict[str, tuple[str, ...]] = {"guide_albedo": ("R", "G", "B"), "guide_normal": ("X", "Y", "Z")}


def parse_aovs(text: str, where: str = "--aovs") -> tuple[tuple[str, str], ...]:
    """``"albedo,nn:sh_normal,dd.y:depth"`` -> ``(("albedo", "albedo"), ("nn", "sh_normal"),
    ("dd.y", "depth"))``. A bad entry is a :class:`~drpt.errors.DrptError` naming ``where``."""
    out: list[tuple[str, str]] = []
    for item in (t.strip() for t in text.split(",")):
        if not item:
            continue
        name, colon, kind = item.rpartition(":")
        if not colon:
            name = kind = item
        name, kind = name.strip(), ALIASES.get(kind.strip(), kind.strip())
        if not name:
            raise DrptError(f"{where}: AOV {item!r} has an empty name (use NAME:TYPE or TYPE)")
        if kind in UNSUPPORTED:
            raise DrptError(f"{where}: AOV type '{kind}' is not supported (drpt has "
                            f"{', '.join(CHANNELS)})")
        if kind not in CHANNELS:
            raise DrptError(f"{where}: unknown AOV type {kind!r} (use {', '.join(CHANNELS)}, "
                            "or normal for sh_normal)")
        if any(n == name for n, _ in out):
            raise DrptError(f"{where}: AOV name {name!r} is given twice")
        out.append((name, kind))
    return tuple(out)


def check_aovs(aovs) -> None:
    """Raise :class:`~drpt.errors.DrptError` unless ``aovs`` is a sequence of ``(name,
    type)`` pairs of supported types with distinct names (``RenderOptions.aovs``)."""
    names = set()
    for item in aovs:
        if not (isinstance(item, (tuple, list)) and len(item) == 2 and item[1] in CHANNELS
                and isinstance(item[0], str) and item[0]):
            raise DrptError(f"AOVs must be (name, type) pairs with a type of "
                            f"{', '.join(CHANNELS)}, got {item!r} (parse_aovs reads a list)")
        if item[0] in names:
            raise DrptError(f"AOV name {item[0]!r} is given twice")
        names.add(item[0])


def traced(aovs, denoise: bool = False) -> list[tuple[str, str]]:
    """The ``(name, kind)`` pairs a render traces: the AOVs, then the denoiser's guides."""
    out = [(n, k) for n, k in aovs]
    if denoise:
        out += [(k, k) for k in GUIDES]
    return out


def channel_count(kinds) -> int:
    """Channels of the AOV (or denoiser guide) ``kinds`` together."""
    return sum(len(CHANNELS.get(k) or GUIDES[k]) for k in kinds)


def split(aovs, denoise: bool, values) -> tuple[dict, dict]:
    """``(layers, guides)`` of an ``(H, W, C)`` array of the traced AOVs' means:
    ``layers`` maps each EXR channel ``<name>.<suffix>`` to its ``(H, W)`` image,
    ``guides`` each guide kind to its ``(H, W, 3)`` image."""
    layers, guides, c = {}, {}, 0
    for name, kind in traced(aovs, denoise):
        suffixes = CHANNELS.get(kind) or GUIDES[kind]
        block = values[..., c:c + len(suffixes)]
        c += len(suffixes)
        if kind in GUIDES:
            guides[kind] = block
        else:
            layers.update({f"{name}.{s}": block[..., i] for i, s in enumerate(suffixes)})
    return layers, guides
