"""Small scenes written for the tests, in drpt's format.

``edge_scene``: thin stripes and emitters just outside the frame, for the pixel-filter and
camera tests that compare drpt with Mitsuba (the statistics are in :mod:`drpt.testing`).
"""

from __future__ import annotations


def _quad(x0, y0, x1, y1, z, mat):
    a, b, c, d = (x0, y0, z), (x1, y0, z), (x1, y1, z), (x0, y1, z)

    def f(p):
        return " ".join(repr(float(v)) for v in p)

    return (f"MaterialIndex {mat}\nTriangle {{ vertex0 {f(a)} vertex1 {f(b)} vertex2 {f(c)} }}\n"
            f"Triangle {{ vertex0 {f(a)} vertex1 {f(c)} vertex2 {f(d)} }}\n", 2)


def edge_scene(aperture=None, spheres=False) -> str:
    """An edge-rich scene for pixel-filter and camera tests (drpt's format):
    a grey wall at z = 0 seen head-on from z = 5 (40 degrees: about 0.076
    world units per pixel at 48 pixels), lit by a point light, with thin
    vertical and horizontal stripes (red diffuse, white and blue emitters,
    0.05 to 0.22 units wide) and two emitters just outside the right and top
    edges of the frame (0.2 pixels beyond it: only a filter that reaches
    beyond the image sees them). ``aperture = (radius, focus distance)``
    makes the camera a thin lens; ``spheres`` adds a red sphere at distance
    3 and a small blue emitting one at 2.7."""
    objs = [_quad(-3, -3, 3, 3, 0.0, 0)]
    if spheres:
        objs.append(("MaterialIndex 1\nSphere { center -0.3 0.2 2 radius 0.35 }\n"
                     "MaterialIndex 3\nSphere { center 0.5 -0.45 2.3 radius 0.12 }\n", 2))
    for k, x in enumerate([-1.6, -1.1, -0.62, -0.2, 0.33, 0.71, 1.0, 1.3]):
        objs.append(_quad(x, -1.7, x + 0.05 + 0.04 * (k % 4), 1.0, 0.01, 1 + k % 3))
    for k, y in enumerate([-1.4, -0.9, 0.9, 1.25]):
        objs.append(_quad(-1.9, y, 1.9, y + 0.06 + 0.05 * k, 0.02, 1 + (k + 1) % 3))
    objs.append(_quad(1.835, -1.5, 2.5, 1.5, 0.01, 2))  # just beyond the right edge (x = 1.82)
    objs.append(_quad(-1.5, 1.835, 1.5, 2.5, 0.01, 3))  # just beyond the top edge
    lens = "" if aperture is None else f" apertureRadius {aperture[0]} focusDistance {aperture[1]}"
    return (f"PerspectiveCamera {{ center 0 0 5 direction 0 0 -1 up 0 1 0 angle 40{lens} }}\n"
            "Lights { numLights 1 PointLight { position 0.5 0.8 3 color 12 12 12 } }\n"
            "Materials { numMaterials 4\n"
            "  Material { diffuseColor 0.6 0.6 0.6 }\n"
            "  Material { diffuseColor 0.9 0.15 0.1 }\n"
            "  Material { diffuseColor 0 0 0 Ke 3 3 3 }\n"
            "  Material { diffuseColor 0.05 0.05 0.05 Ke 0.5 2.5 4 }\n}\n"
            f"Group {{ numObjects {sum(o[1] for o in objs)}\n{''.join(o[0] for o in objs)}}}\n")
