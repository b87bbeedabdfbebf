"""OBJ loader: index forms, triangulation, normals, materials, located errors."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from drpt.errors import Loc, SceneError
from drpt.scene.obj import load_obj

SEED = Path(__file__).resolve().parents[3] / "shared" / "seed"

QUAD_V = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"


def write(tmp_path: Path, text: str, name: str = "m.obj") -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def test_plain_indices(tmp_path):
    m = load_obj(write(tmp_path, QUAD_V + "f 1 2 3\nf 1 3 4\n"))
    assert len(m) == 2
    np.testing.assert_array_equal(m.positions[1], [[0, 0, 0], [1, 1, 0], [0, 1, 0]])
    assert m.normals is None and m.uvs is None
    assert m.face_material.tolist() == [-1, -1]
    assert m.positions.dtype == np.float64 and m.positions.shape == (2, 3, 3)


@pytest.mark.parametrize("form, has_t, has_n", [
    ("{v}", False, False), ("{v}/{v}", True, False), ("{v}//{v}", False, True), ("{v}/{v}/{v}", True, True),
])
def test_index_forms(tmp_path, form, has_t, has_n):
    text = QUAD_V + "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n" + "vn 0 0 2\n" * 4
    text += "f " + " ".join(form.format(v=i) for i in (1, 2, 3)) + "\n"
    m = load_obj(write(tmp_path, text))
    np.testing.assert_array_equal(m.positions[0], [[0, 0, 0], [1, 0, 0], [1, 1, 0]])
    assert (m.uvs is not None) == has_t
    assert (m.normals is not None) == has_n
    if has_t:
        np.testing.assert_array_equal(m.uvs[0], [[0, 0], [1, 0], [1, 1]])
    if has_n:
        np.testing.assert_allclose(m.normals[0], [[0, 0, 1]] * 3)  # normalized


def test_negative_indices_relative_to_definition(tmp_path):
    text = "v 9 9 9\n" + QUAD_V + "vt 0.5 0.25\nvn 0 1 0\nf -4/-1/-1 -3/-1/-1 -2/-1/-1\nv 5 5 5\nf -1 -2 -3\n"
    m = load_obj(write(tmp_path, text))
    np.testing.assert_array_equal(m.positions[0], [[0, 0, 0], [1, 0, 0], [1, 1, 0]])
    np.testing.assert_array_equal(m.positions[1], [[5, 5, 5], [0, 1, 0], [1, 1, 0]])
    np.testing.assert_array_equal(m.uvs[0], [[0.5, 0.25]] * 3)
    # the second face has no normals: it gets its geometric normal
    g = np.cross(m.positions[1, 1] - m.positions[1, 0], m.positions[1, 2] - m.positions[1, 0])
    np.testing.assert_allclose(m.normals[1], [g / np.linalg.norm(g)] * 3)
    np.testing.assert_allclose(m.normals[0], [[0, 1, 0]] * 3)


def test_polygon_fan(tmp_path):
    text = "v 0 0 0\nv 2 0 0\nv 3 1 0\nv 1 2 0\nv -1 1 0\nf 1 2 3 4 5\n"
    m = load_obj(write(tmp_path, text))
    assert len(m) == 3
    v = np.array([[0, 0, 0], [2, 0, 0], [3, 1, 0], [1, 2, 0], [-1, 1, 0]], float)
    np.testing.assert_array_equal(m.positions, v[[[0, 1, 2], [0, 2, 3], [0, 3, 4]]])


def test_mixed_polygon_sizes_and_materials(tmp_path):
    (tmp_path / "a.mtl").write_text("newmtl red\nKd 1 0 0\n")
    (tmp_path / "b.mtl").write_text("newmtl blue\nKd 0 0 1\n")
    text = ("mtllib a.mtl b.mtl\n" + QUAD_V
            + "f 1 2 3 4\nusemtl blue\nf 1 2 3\nusemtl red\nf 4 3 2 1\nusemtl blue\nf 2 3 4\n")
    m = load_obj(write(tmp_path, text))
    assert len(m) == 2 + 1 + 2 + 1
    assert m.material_names == ["blue", "red"]
    assert m.face_material.tolist() == [-1, -1, 0, 1, 1, 0]
    assert [x.kd for x in m.face_materials()] == [(0, 0, 1), (1, 0, 0)]


def test_normal_normalization_and_zero_normal(tmp_path):
    text = QUAD_V + "vn 0 0.707107 0\nvn 0 0 0\nf 1//1 2//1 3//2\n"
    m = load_obj(write(tmp_path, text))
    np.testing.assert_allclose(np.linalg.norm(m.normals, axis=2), 1.0)
    np.testing.assert_allclose(m.normals[0, 0], [0, 1, 0])
    np.testing.assert_allclose(m.normals[0, 2], [0, 0, 1])  # zero vn -> geometric normal


def test_degenerate_face_kept(tmp_path):
    m = load_obj(write(tmp_path, "v 0 0 0\nv 1 1 1\nv 2 2 2\nvn 0 0 1\nf 1 2 3\nf 1//1 1//1 1//1\n"))
    assert len(m) == 2
    assert np.isfinite(m.normals).all()
    np.testing.assert_allclose(np.linalg.norm(m.normals, axis=2), 1.0)


def test_misc_statements(tmp_path):
    text = ("# comment\n\no thing\ng group\ns 1\ns off\nv 0 0 0 1   # w ignored\nv 1 0 0\nv 0 1 0\n"
            "vt 0.5\nl 1 2\np 1\nf 1/1 2/1 3/1 # trailing\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = load_obj(write(tmp_path, text))
    assert len(m) == 1
    np.testing.assert_array_equal(m.uvs[0], [[0.5, 0]] * 3)


def test_unknown_statement_warns_once(tmp_path):
    text = QUAD_V + "cstype bspline\ncstype bspline\nfoo\nf 1 2 3\n"
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        m = load_obj(write(tmp_path, text))
    msgs = [str(w.message) for w in rec]
    assert len(msgs) == 2 and "m.obj:5" in msgs[0] and "'foo'" in msgs[1]
    assert len(m) == 1


def test_fast_and_general_paths_agree(tmp_path):
    """Tabs and mixed corner forms go through the general path; the result
    must equal the hot path's."""
    base = QUAD_V + "vt 0 0\nvt 1 0\nvt 1 1\nvn 0 0 1\nvn 0 1 0\n"
    fast = load_obj(write(tmp_path, base + "f 1/1/1 2/2/2 3/3/2 4/1/1\n", "a.obj"))
    slow = load_obj(write(tmp_path, base + "f\t1/1/1 2/2/2 -2/3/-1 4/-3/1\n", "b.obj"))
    np.testing.assert_array_equal(fast.positions, slow.positions)
    np.testing.assert_array_equal(fast.normals, slow.normals)
    np.testing.assert_array_equal(fast.uvs, slow.uvs)


@pytest.mark.parametrize(
    "body, line, fragment",
    [
        ("f 1 2 0\n", 5, "index 0"),
        ("f 1 2 5\n", 5, "out of range"),
        ("\nf 1 2 -5\n", 6, "out of range"),
        ("f 1/3 2/1 3/1\nvt 0 0\n", 5, "texture coordinate index"),  # no vt yet
        ("vn 0 0 1\nf 1//2 2//1 3//1\n", 6, "normal index 2"),
        ("f 1 2\n", 5, "at least 3"),
        ("f 1/1/1/1 2 3\n", 5, "bad face corner"),
        ("f 1 a 3\n", 5, "bad vertex index 'a'"),
        ("v 1 2\n", 5, "needs 3"),
        ("v 1 2 1.0.0\n", 5, "1.0.0"),
        ("v 1 2 nan\n", 5, "nan"),
        ("v 1 2 inf\n", 5, "inf"),
        ("v 1 2 3_0\n", 5, "3_0"),
        ("vn 1 abc 3\n", 5, "abc"),
        ("vt\n", 5, "needs 1"),
        ("usemtl\n", 5, "without a material name"),
        ("usemtl ghost\nf 1 2 3\n", 5, "ghost"),
        ("mtllib nothere.mtl\n", 5, "nothere.mtl"),
    ],
)
def test_errors(tmp_path, body, line, fragment):
    p = write(tmp_path, QUAD_V + body, "bad.obj")
    with pytest.raises(SceneError) as e:
        load_obj(p)
    assert f"bad.obj:{line}:" in str(e.value), str(e.value)
    assert fragment in str(e.value)


def test_forward_index_accepted(tmp_path):
    # Positive indices are checked against the whole file (as most loaders do).
    m = load_obj(write(tmp_path, "v 0 0 0\nf 1 2 3\nv 1 0 0\nv 0 1 0\n"))
    assert len(m) == 1


def test_error_in_mtl_reported_in_mtl(tmp_path):
    (tmp_path / "x.mtl").write_text("newmtl a\nKd 1 oops 1\n")
    p = write(tmp_path, "mtllib x.mtl\n" + QUAD_V)
    with pytest.raises(SceneError) as e:
        load_obj(p)
    assert "x.mtl:2:" in str(e.value)


def test_missing_file_reported_at_reference(tmp_path):
    ref = tmp_path / "scene.txt"
    with pytest.raises(SceneError) as e:
        load_obj(tmp_path / "gone.obj", ref=Loc(ref, 12))
    assert str(e.value).startswith(f"{ref}:12:") and "gone.obj" in str(e.value)


def test_non_utf8(tmp_path):
    p = tmp_path / "u.obj"
    p.write_bytes(QUAD_V.encode() + b"g \xff\xfe\n")
    with pytest.raises(SceneError) as e:
        load_obj(p)
    assert "u.obj:5:" in str(e.value)


def test_large_mesh_is_fast(tmp_path):
    n = 101  # 100 x 100 quads -> 20k triangles
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    lines = [f"v {a} {b} 0" for a, b in zip(i.ravel(), j.ravel())]
    lines += ["vn 0 0 1"]
    for a in range(n - 1):
        for b in range(n - 1):
            k = a * n + b + 1
            lines.append(f"f {k}//1 {k + n}//1 {k + n + 1}//1 {k + 1}//1")
    p = write(tmp_path, "\n".join(lines) + "\n")
    m = load_obj(p)
    assert len(m) == 2 * (n - 1) ** 2


def test_seed_cornellbox_obj():
    obj = SEED / "scenes" / "cornellbox.obj"
    if not obj.is_file():
        pytest.skip("seed files not available")
    m = load_obj(obj)
    faces = sum(1 for line in obj.read_text().splitlines() if line.startswith("f "))
    assert len(m) == faces  # all triangles already
    np.testing.assert_allclose(np.linalg.norm(m.normals, axis=2), 1.0)
    assert "cornellbox_light" in m.material_names
