"""Writes living_room: a textured living room lit by several lights and a sky, as Mitsuba XML.

A room of the kind interior-rendering tutorials describe (a box of painted walls,
a wooden floor, furniture under a ceiling lamp, daylight through a window), built
here from boxes, rectangles and spheres; nothing is copied from any file. y up,
meters, floor at y = 0; the room spans x in [-2.5, 2.5], z in [-2.5, 3.5], height
2.6. What it exercises, and why a path tracer finds it hard:

* textures: a plank floor (``floor.png``, a ``bitmap`` generated here, repeated
  2 x 3 times over the floor) and a rug of Mitsuba's ``checkerboard`` texture;
* materials: a ``roughplastic`` table (GGX, alpha 0.15), a gold ``conductor``
  sphere and a ``roughconductor`` copper box on it, diffuse walls, sofa and pot;
* alpha cut-outs: a plant of six leaf cards, each a ``mask`` whose opacity is a
  leaf silhouette (``leaf.png``, 0 or 1, read ``raw``) around a two-sided diffuse
  green, so most rays that reach a card pass through it;
* several emitters of very different power: a ceiling panel (0.6 x 0.6 m,
  radiance 6), a floor lamp (a sphere of radius 0.08, radiance 40, warm), a wall
  sconce (0.12 x 0.3 m, radiance 15, cool) and an ``envmap`` sky (``sky.exr``:
  blue above the horizon, a soft sun of peak radiance 150) that reaches the room
  only through the window in the back wall (1.2 x 1.1 m, no glass): next-event
  estimation toward the sky is occluded almost everywhere.

The camera at (0.4, 1.35, 3.2) looks at (-0.2, 0.9, -1), vertical field of view
62 degrees. The file declares ``spp`` (64), ``w`` and ``h`` (128) and
``max_depth`` (8) as ``<default>`` values (``-D``), a Gaussian pixel filter
(Mitsuba's default) and the ``path`` integrator; at 128 x 128 and 64 spp both
renderers take seconds. Files: ``living_room.xml``, ``floor.png``, ``leaf.png``,
``sky.exr`` (~40 kB).

    python scenes/make_living_room.py OUT_DIR
    python -m drpt render OUT_DIR/living_room.xml
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...imageio import write_image
from . import meshes

CAMERA = ((0.4, 1.35, 3.2), (-0.2, 0.9, -1.0))
FOV = 62.0
ROOM_X, ROOM_Z0, ROOM_Z1, ROOM_H = 2.5, -2.5, 3.5, 2.6
#: the window in the back wall (z = ROOM_Z0): x range, y range
WINDOW_X, WINDOW_Y = (-1.6, -0.4), (0.9, 2.0)
#: the sun's direction (toward the sun) and its angular radius (degrees, Gaussian sigma)
SUN_DIR = (-0.25, 0.55, -1.0)
SUN_SIGMA_DEG = 4.0
SUN_PEAK = 150.0

FILES = ("living_room.xml", "floor.png", "leaf.png", "sky.exr")


# ------------------------------------------------------------------ textures
def floor_texture(n: int = 128) -> np.ndarray:
    """Planks along u: 8 boards per tile, each its own tint, with a fine grain (linear RGB)."""
    rng = np.random.default_rng(7)
    v = (np.arange(n) + 0.5) / n
    u = (np.arange(n) + 0.5) / n
    board = np.floor(v * 8).astype(int)
    tint = rng.uniform(0.75, 1.15, 8)[board]
    grain = 0.9 + 0.1 * np.sin(2 * np.pi * (u[None, :] * 6 + 3 * v[:, None] + rng.uniform(0, 1, 8)[board][:, None]))
    seam = (np.abs(v * 8 - np.round(v * 8)) < 0.04)[:, None]
    base = np.array([0.42, 0.26, 0.13])
    img = base * (tint[:, None] * grain)[..., None]
    return np.where(seam[..., None], base * 0.35, img).astype(np.float32)


def leaf_texture(n: int = 64) -> np.ndarray:
    """A leaf silhouette, 1 inside and 0 outside: a pointed ellipse along v (the card's
    long axis), about 40% of the card."""
    u = (np.arange(n) + 0.5) / n * 2 - 1
    v = (np.arange(n) + 0.5) / n
    half_width = 0.75 * np.sin(np.pi * v) ** 1.5  # zero at both ends, widest in the middle
    inside = np.abs(u)[None, :] < half_width[:, None]
    return np.repeat(inside[..., None], 3, 2).astype(np.float32)


def sky_texture(width: int = 64, height: int = 32) -> np.ndarray:
    """A lat-long sky in Mitsuba's ``envmap`` layout (row 0 up; ``u = atan2(x, -z) / 2 pi``,
    ``v = acos(y) / pi``): a blue gradient above the horizon, a gray ground, a soft sun."""
    v = (np.arange(height) + 0.5) / height
    u = (np.arange(width) + 0.5) / width
    theta, phi = np.pi * v[:, None], 2 * np.pi * u[None, :]
    d = np.stack([np.sin(phi) * np.sin(theta), np.cos(theta) + 0 * phi, -np.cos(phi) * np.sin(theta)], -1)
    up = np.clip(d[..., 1], 0, 1)[..., None]
    sky = np.where(d[..., 1:2] > 0, np.array([0.35, 0.55, 1.0]) * (0.6 + 0.9 * up), np.array([0.25, 0.23, 0.2]))
    s = np.asarray(SUN_DIR, float) / np.linalg.norm(SUN_DIR)
    ang = np.arccos(np.clip(d @ s, -1, 1))
    sun = SUN_PEAK * np.exp(-0.5 * (ang / np.radians(SUN_SIGMA_DEG)) ** 2)
    return (sky + sun[..., None] * np.array([1.0, 0.92, 0.8])).astype(np.float32)


# ------------------------------------------------------------------ geometry
def _matrix(m: np.ndarray) -> str:
    return '<matrix value="' + " ".join(f"{x:.6g}" for x in np.asarray(m, float).ravel()) + '"/>'


def rect(center, half_u, half_v) -> str:
    """``to_world`` of Mitsuba's ``rectangle`` ([-1, 1]^2 in z = 0, facing +z) as the
    rectangle at ``center`` with half edges ``half_u``, ``half_v``, facing ``half_u x half_v``."""
    hu, hv = np.asarray(half_u, float), np.asarray(half_v, float)
    n = np.cross(hu, hv)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = hu, hv, n / np.linalg.norm(n), center
    return _matrix(m)


def box(center, half, yaw_deg: float = 0.0) -> str:
    """``to_world`` of Mitsuba's ``cube`` ([-1, 1]^3) as a box of half sizes ``half``
    turned by ``yaw_deg`` about +y."""
    r = meshes._yaw(yaw_deg)
    m = np.eye(4)
    m[:3, :3] = r * np.asarray(half, float)[None, :]
    m[:3, 3] = center
    return _matrix(m)


def _rgb(name: str, c) -> str:
    c = (c,) * 3 if np.isscalar(c) else c
    return f'<rgb name="{name}" value="{", ".join(f"{x:g}" for x in c)}"/>'


def _shape(kind: str, to_world: str, inner: str) -> str:
    return f'    <shape type="{kind}">\n        <transform name="to_world">{to_world}</transform>\n{inner}    </shape>'


def _walls() -> list[str]:
    """Floor, ceiling and four walls, all facing into the room; the back wall around
    the window as four rectangles."""
    X, z0, z1, H = ROOM_X, ROOM_Z0, ROOM_Z1, ROOM_H
    zc, zh = 0.5 * (z0 + z1), 0.5 * (z1 - z0)
    out = [
        _shape("rectangle", rect((0, 0, zc), (0, 0, zh), (X, 0, 0)), '        <ref id="floor"/>\n'),
        _shape("rectangle", rect((0, H, zc), (X, 0, 0), (0, 0, zh)), '        <ref id="ceiling"/>\n'),
        _shape("rectangle", rect((-X, H / 2, zc), (0, 0, -zh), (0, H / 2, 0)), '        <ref id="wall"/>\n'),
        _shape("rectangle", rect((X, H / 2, zc), (0, 0, zh), (0, H / 2, 0)), '        <ref id="wall"/>\n'),
        _shape("rectangle", rect((0, H / 2, z1), (-X, 0, 0), (0, H / 2, 0)), '        <ref id="wall"/>\n'),
    ]
    (wx0, wx1), (wy0, wy1) = WINDOW_X, WINDOW_Y
    for (x0, x1), (y0, y1) in [((-X, wx0), (0, H)), ((wx1, X), (0, H)), ((wx0, wx1), (0, wy0)),
                               ((wx0, wx1), (wy1, H))]:
        c = (0.5 * (x0 + x1), 0.5 * (y0 + y1), z0)
        out.append(_shape("rectangle", rect(c, (0.5 * (x1 - x0), 0, 0), (0, 0.5 * (y1 - y0), 0)),
                          '        <ref id="wall"/>\n'))
    return out


def _furniture() -> list[str]:
    out = []
    # the rug (checkerboard) just above the floor
    out.append(_shape("rectangle", rect((-0.2, 0.004, -0.2), (0, 0, 1.1), (1.5, 0, 0)), '        <ref id="rug"/>\n'))
    # the table: a top and four legs, rough plastic
    top = (-0.2, 0.72, -0.4)
    out.append(_shape("cube", box(top, (0.8, 0.025, 0.45)), '        <ref id="table"/>\n'))
    for sx in (-1, 1):
        for sz in (-1, 1):
            leg = (top[0] + 0.72 * sx, 0.35, top[2] + 0.38 * sz)
            out.append(_shape("cube", box(leg, (0.03, 0.35, 0.03)), '        <ref id="table"/>\n'))
    # on the table: a gold sphere and a copper box
    out.append('    <shape type="sphere">\n        <point name="center" x="0.15" y="0.865" z="-0.3"/>'
               '<float name="radius" value="0.12"/>\n        <ref id="gold"/>\n    </shape>')
    out.append(_shape("cube", box((-0.6, 0.825, -0.5), (0.08, 0.08, 0.08), 30.0), '        <ref id="copper"/>\n'))
    # the sofa against the left wall: seat, back, two arms
    for c, h in [((-2.05, 0.22, 0.2), (0.4, 0.22, 1.0)), ((-2.38, 0.55, 0.2), (0.1, 0.55, 1.0)),
                 ((-2.0, 0.35, -0.85), (0.45, 0.35, 0.08)), ((-2.0, 0.35, 1.25), (0.45, 0.35, 0.08))]:
        out.append(_shape("cube", box(c, h), '        <ref id="fabric"/>\n'))
    # the plant: a pot and six leaf cards (alpha-cut) fanning out from it
    pot = (1.6, 0.2, -1.7)
    out.append(_shape("cube", box(pot, (0.18, 0.2, 0.18), 15.0), '        <ref id="pot"/>\n'))
    for k in range(6):
        yaw = np.radians(60.0 * k + 10.0)
        tilt = np.radians(25.0 + 8.0 * (k % 3))
        out_dir = np.array([np.cos(yaw), 0.0, np.sin(yaw)])
        axis = np.cos(tilt) * np.array([0.0, 1.0, 0.0]) + np.sin(tilt) * out_dir  # the leaf's long axis
        side = np.cross(axis, out_dir)
        side /= np.linalg.norm(side)
        length = 0.55 + 0.05 * (k % 2)
        center = np.array(pot) + np.array([0, 0.2, 0]) + 0.5 * length * axis
        out.append(_shape("rectangle", rect(center, 0.16 * side, 0.5 * length * axis), '        <ref id="leaf"/>\n'))
    # the floor lamp's stand (the bulb is an emitter below)
    out.append(_shape("cube", box((1.9, 0.7, 0.6), (0.015, 0.7, 0.015)), '        <ref id="copper"/>\n'))
    return out


def _lights() -> list[str]:
    H = ROOM_H
    return [
        # ceiling panel, facing down
        _shape("rectangle", rect((0.0, H - 0.002, 0.3), (0.3, 0, 0), (0, 0, 0.3)),
               '        <emitter type="area"><rgb name="radiance" value="6, 5.7, 5.2"/></emitter>\n'),
        # floor lamp bulb
        '    <shape type="sphere">\n        <point name="center" x="1.9" y="1.5" z="0.6"/>'
        '<float name="radius" value="0.08"/>\n'
        '        <emitter type="area"><rgb name="radiance" value="40, 30, 18"/></emitter>\n    </shape>',
        # wall sconce on the right wall, facing -x
        _shape("rectangle", rect((ROOM_X - 0.002, 1.8, -1.2), (0, 0, 0.06), (0, 0.15, 0)),
               '        <emitter type="area"><rgb name="radiance" value="12, 14, 17"/></emitter>\n'),
        '    <emitter type="envmap">\n        <string name="filename" value="sky.exr"/>\n    </emitter>',
    ]


def xml() -> str:
    """The scene file's text."""
    (cx, cy, cz), (tx, ty, tz) = CAMERA
    bsdfs = f"""\
    <bsdf type="twosided" id="wall"><bsdf type="diffuse">{_rgb("reflectance", (0.7, 0.66, 0.58))}</bsdf></bsdf>
    <bsdf type="twosided" id="ceiling"><bsdf type="diffuse">{_rgb("reflectance", 0.8)}</bsdf></bsdf>
    <bsdf type="twosided" id="floor"><bsdf type="diffuse">
        <texture type="bitmap" name="reflectance"><string name="filename" value="floor.png"/>
            <transform name="to_uv"><scale x="2" y="3"/></transform></texture>
    </bsdf></bsdf>
    <bsdf type="twosided" id="rug"><bsdf type="diffuse">
        <texture type="checkerboard" name="reflectance">
            {_rgb("color0", (0.55, 0.12, 0.1))}{_rgb("color1", (0.75, 0.7, 0.6))}
            <transform name="to_uv"><scale x="6" y="8"/></transform></texture>
    </bsdf></bsdf>
    <bsdf type="twosided" id="table"><bsdf type="roughplastic">
        <string name="distribution" value="ggx"/><float name="alpha" value="0.15"/>
        {_rgb("diffuse_reflectance", (0.3, 0.17, 0.08))}
    </bsdf></bsdf>
    <bsdf type="conductor" id="gold"><string name="material" value="Au"/></bsdf>
    <bsdf type="roughconductor" id="copper"><string name="material" value="Cu"/>
        <string name="distribution" value="ggx"/><float name="alpha" value="0.25"/></bsdf>
    <bsdf type="twosided" id="fabric"><bsdf type="diffuse">{_rgb("reflectance", (0.12, 0.2, 0.35))}</bsdf></bsdf>
    <bsdf type="twosided" id="pot"><bsdf type="diffuse">{_rgb("reflectance", (0.55, 0.28, 0.16))}</bsdf></bsdf>
    <bsdf type="mask" id="leaf">
        <texture type="bitmap" name="opacity"><string name="filename" value="leaf.png"/>
            <boolean name="raw" value="true"/></texture>
        <bsdf type="twosided"><bsdf type="diffuse">{_rgb("reflectance", (0.12, 0.35, 0.08))}</bsdf></bsdf>
    </bsdf>"""
    parts = [
        '<scene version="3.0.0">',
        "    <!-- living_room (drpt.tools.scenegen.living_room): a textured room lit by a ceiling panel,",
        "         a floor lamp, a wall sconce and a sky through the window. -->",
        '    <default name="spp" value="64"/>',
        '    <default name="w" value="128"/>',
        '    <default name="h" value="128"/>',
        '    <default name="max_depth" value="8"/>',
        '    <integrator type="path"><integer name="max_depth" value="$max_depth"/></integrator>',
        '    <sensor type="perspective">',
        f'        <float name="fov" value="{FOV:g}"/><string name="fov_axis" value="y"/>',
        f'        <transform name="to_world"><lookat origin="{cx:g}, {cy:g}, {cz:g}" '
        f'target="{tx:g}, {ty:g}, {tz:g}" up="0, 1, 0"/></transform>',
        '        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>',
        '        <film type="hdrfilm"><integer name="width" value="$w"/><integer name="height" value="$h"/>'
        '</film>',
        "    </sensor>",
        bsdfs,
        *_walls(), *_furniture(), *_lights(),
        "</scene>",
    ]
    return "\n".join(parts) + "\n"


def main(out: Path) -> list[Path]:
    """Write the scene files into folder ``out`` (created if missing); return their paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "living_room.xml").write_text(xml())
    write_image(out / "floor.png", floor_texture())
    write_image(out / "leaf.png", leaf_texture(), gamma=1.0)
    write_image(out / "sky.exr", sky_texture())
    return [out / f for f in FILES]


def cli(argv=None) -> None:
    """``python scenes/make_living_room.py OUT_DIR``."""
    meshes.folder_cli(main, __doc__.splitlines()[0], argv)


if __name__ == "__main__":
    cli()
