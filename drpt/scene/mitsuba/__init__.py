"""Mitsuba 3 XML scenes (and 0.5/0.6 ones, which Mitsuba's parser upgrades), read into drpt.

:func:`load_mitsuba_xml` reads the file through Mitsuba's own parser
(``mitsuba.parser``: ``parse_file``, ``transform_upgrade``,
``transform_resolve``; no XML is parsed here), fills ``$name`` from
``defines`` (``-D name=value``), and maps the scene graph onto drpt's
:class:`~drpt.scene.model.Scene`:

========================  =====================================================
Mitsuba                   drpt
========================  =====================================================
``perspective``           :class:`PerspectiveCamera`: ``to_world``'s origin,
                          +z (direction) and +y (up); ``fov`` on any
                          ``fov_axis`` (x, y, diagonal, smaller, larger) or
                          ``focal_length``, converted to drpt's vertical fov
                          for the film's aspect. A mirroring or scaling
                          ``to_world`` is an error. ``principal_point_offset``
                          and the film's crop window: the camera's
                          :class:`~drpt.scene.model.FilmWindow`.
``thinlens``              the camera's ``aperture_radius`` and
                          ``focus_distance`` (default: far_clip, 1e4)
``hdrfilm``               ``Scene.settings`` width, height; its ``rfilter``
                          (box, tent, gaussian; default gaussian) as
                          ``settings.rfilter``/``rfilter_params``, which
                          become ``--filter`` unless it is given
``independent`` (etc.)    ``settings.spp`` = ``sample_count`` (default 4,
                          rounded up as Mitsuba's plugin rounds it),
                          ``settings.sampler`` (its name: ``--sampler``),
                          ``settings.seed`` = ``seed``, and ``jitter``,
                          ``strength`` (``--jitter``, ``--strength``)
``path``                  ``settings``: max_depth, rr_depth, hide_emitters
``moment``                its nested integrator; ``settings.moment`` names the
                          moment AOVs an EXR output gets
``direct``                ``path`` with max_depth 2 (the same expectation)
``obj`` ``ply``           triangles, loaded by Mitsuba's own mesh loaders
``serialized``            (:mod:`.geometry`): ``to_world``, ``face_normals``,
``rectangle`` ``cube``    ``flip_normals``, ``flip_tex_coords``, ``shape_index``
``sphere``                an analytic sphere (tessellated when flipped or not
                          similarity-transformed)
``disk`` ``cylinder``     tessellated (256 segments)
``shapegroup``            flattened: each ``instance`` adds the group's shapes
``instance``              under its ``to_world``
``area``                  the shape's material's ``emission`` (radiance)
``point``                 :class:`PointLight` (intensity, inverse square)
``spot``                  :class:`SpotLight` (with a bitmap ``texture``)
``projector``             :class:`ProjectorLight` (constant or bitmap irradiance)
``directional``           :class:`DirectionalLight` (irradiance)
``constant``              ``Background.color`` (radiance of escaping rays)
``envmap``                :class:`Skybox` with ``scale`` and ``rotation``
``<bsdf>``                ``Material.bsdf``, a :class:`drpt.materials.spec.BSDFSpec`
                          tree (:mod:`.materials`); a shape without one gets
                          Mitsuba's default (diffuse 0.5; black on an emitter)
``bitmap``                :class:`drpt.materials.spec.Texture` on a texturable param
                          (filter_type, wrap_mode, raw, to_uv)
``checkerboard``          :class:`drpt.materials.spec.Checkerboard` (procedural)
``mesh_attribute``        :class:`drpt.materials.spec.MeshAttribute` (vertex/face)
``rawconstant``           its value
``orthographic``          :class:`OrthographicCamera`
========================  =====================================================

Files are found as Mitsuba's file resolver finds them (``<path>`` folders,
the scene's folder; :meth:`.nodes.Node.resolve_file`); nested plugins are
found by kind whatever their ``name`` (:meth:`.nodes.Node.children`); a
spectrum given by wavelength is the color Mitsuba's RGB variants make of it
(:meth:`.nodes.Node.color`).

Each distinct (BSDF node, area radiance) pair of shapes becomes one
:class:`~drpt.scene.model.Material`, named after the BSDF's ``id``.

Errors and warnings. Anything the parser refuses (malformed XML, an
undefined ``$var``, an unresolved ``<ref>``, a value of the wrong syntax) and
anything drpt refuses (a parameter of the wrong type, a missing mesh file,
a plugin drpt cannot render: media, other integrators,
volume textures, ...) raises a one-line
:class:`~drpt.errors.SceneError` naming the XML file, the line Mitsuba's
parser gives (``mitsuba.parser.file_location``) and the plugin. With
``ignore_unsupported`` an unsupported plugin is left out (or replaced by the
stated fallback) with a warning each. Parameters that a plugin does not
read (files from older exporters: ``strict_normals`` on ``path``,
``int_ior`` on ``roughconductor``) are listed in one warning; with
``strict`` the first is an error. Parameters drpt reads but that change
nothing in its image (film pixel formats, clip planes) are
read silently.
"""

from __future__ import annotations

from pathlib import Path

from ...errors import DrptError
from ..model import Scene
from .precheck import not_utf8
from .reader import Reader

__all__ = ["load_mitsuba_xml", "parse_defines"]


def load_mitsuba_xml(path: str | Path, defines: dict[str, str] | None = None, *,
                     ignore_unsupported: bool = False, strict: bool = False) -> Scene:
    """Read the Mitsuba XML scene at ``path`` (``$name`` from ``defines``)."""
    try:
        return Reader(path, defines, ignore_unsupported=ignore_unsupported, strict=strict).read()
    except UnicodeDecodeError:  # a name or value of bytes that are not UTF-8, which Mitsuba kept
        raise not_utf8(Path(path).expanduser().resolve(), defines) from None


def parse_defines(items) -> dict[str, str]:
    """``["name=value", ...]`` (the ``-D`` flags) as a dict; a malformed one is a DrptError."""
    out: dict[str, str] = {}
    for item in items or ():
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise DrptError(f"-D needs name=value, got {item!r}")
        out[name.strip()] = value
    return out
