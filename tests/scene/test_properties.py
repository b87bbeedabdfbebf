"""Property tests (Hypothesis) for the tokenizer and the OBJ and MTL readers.

* Tokenizer (drpt/scene/tokens.py): any text tokenizes; token lines are
  monotone and within the text's lines; tokens hold no whitespace, comment
  or glued brace; decimal numbers round-trip through ``parse_number`` and
  ``TokenStream.number``; any bytes read as text or raise ``SceneError``
  at a line of the file.
* OBJ and MTL readers: any bytes (and any mix of statements) parse or raise
  ``SceneError`` naming the file and one of its lines; a generated valid OBJ
  mesh (vertices, polygons, positive and negative indices, ``v//n`` and
  ``v/t/n`` corners) reads back the triangles of a fan triangulation
  computed here.

"Lines" are what an editor numbers: ``\\n``, ``\\r\\n`` or ``\\r`` end one.
Python's ``str.splitlines`` also breaks at ``\\v``, ``\\f``, ``\\x1c``-``\\x1e``,
``\\x85``, ``\\u2028`` and ``\\u2029``; texts holding those are tested apart
(``OTHER_BREAKS``). Every test is derandomized, so CI sees the same examples.
"""

from __future__ import annotations

import math
import re
import tempfile
import warnings
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drpt.errors import SceneError
from drpt.scene.mtl import load_mtl
from drpt.scene.obj import load_obj
from drpt.scene.tokens import TokenStream, parse_number, read_text, tokenize

SETTINGS = settings(max_examples=200, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow])
FEW = settings(SETTINGS, max_examples=80)

OTHER_BREAKS = "\v\f\x1c\x1d\x1e\x85\u2028\u2029"
_BREAK = re.compile(r"\r\n|\r|\n")


def editor_lines(text: str) -> int:
    return len(_BREAK.split(text))


# Text made of the characters the format cares about, plus anything else.
_SCENE_CHARS = st.sampled_from(list("{}#/ \t\n\r.+-eE0123456789abcXYZ_") + ["\r\n", "//", "Group", "1e308"])
scene_text = st.lists(st.one_of(_SCENE_CHARS, st.characters(exclude_categories=("Cs",))),
                      max_size=200).map("".join)
plain_text = scene_text.map(lambda t: t.translate({ord(c): " " for c in OTHER_BREAKS}))


# ------------------------------------------------------------------ tokens
def _check_tokens(text: str) -> None:
    tokens = tokenize(text)
    lines = [t.line for t in tokens]
    assert lines == sorted(lines)
    assert all(1 <= n <= editor_lines(text) for n in lines), (lines, editor_lines(text))
    for t in tokens:
        assert t.text in ("{", "}") or not (set(t.text) & set("{}#"))
        assert t.text and not any(c.isspace() for c in t.text)
        assert not t.text.startswith("//")


@SETTINGS
@given(plain_text)
def test_tokens_are_located_within_the_text(text):
    _check_tokens(text)


@SETTINGS
@given(st.tuples(scene_text, st.sampled_from(list(OTHER_BREAKS)), scene_text).map("".join))
def test_tokens_are_located_with_any_line_separator(text):
    _check_tokens(text)


@SETTINGS
@given(st.lists(st.lists(st.sampled_from(["a", "{", "}", "12", "x{y", "#c", "//c", "p//q"]),
                         max_size=6), max_size=8))
def test_token_lines_follow_the_lines(rows):
    text = "\n".join(" ".join(r) for r in rows)
    for t in tokenize(text):
        row = text.splitlines()[t.line - 1]
        assert t.text in row.split("#")[0]


@SETTINGS
@given(st.floats(allow_nan=False, allow_infinity=False))
def test_numbers_round_trip(x):
    for s in (repr(x), f"{x:.17g}", f"{x:.17e}"):
        if "inf" in s:  # .17g of a finite float never says inf; kept for safety
            continue
        assert parse_number(s) == x and math.copysign(1, parse_number(s)) == math.copysign(1, x), s


@SETTINGS
@given(st.lists(st.floats(allow_nan=False, allow_infinity=False), min_size=1, max_size=12),
       st.sampled_from([" ", "\n", "\t", "\r\n"]))
def test_token_stream_numbers_round_trip(xs, sep):
    text = sep.join(repr(x) for x in xs)
    ts = TokenStream(Path("x.txt"), text)
    assert [ts.number("n") for _ in xs] == xs
    assert ts.at_end()


@SETTINGS
@given(st.from_regex(r"[+-]?(\d{1,400}(\.\d{0,20})?|\.\d{1,20})([eE][+-]?\d{1,5})?", fullmatch=True))
def test_parse_number_is_float_when_finite(s):
    value = float(s)
    assert parse_number(s) == (value if math.isfinite(value) else None)


@SETTINGS
@given(st.sampled_from(["nan", "inf", "-inf", "Infinity", "0x10", "1_000", "1e", "--1", "1.2.3", "", "1e999"]))
def test_parse_number_refuses_non_decimal(s):
    assert parse_number(s) is None


@SETTINGS
@given(st.binary(max_size=300))
def test_read_text_decodes_or_reports_a_line(data):
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "s.txt"
        p.write_bytes(data)
        try:
            text = read_text(p)
        except SceneError as e:
            assert e.path == str(p) and e.line is not None
            assert 1 <= e.line <= len(re.split(rb"\r\n|\r|\n", data)), (e.line, data)
            assert len(str(e).splitlines()) == 1
        else:
            assert text == data.decode("utf-8-sig")


# ----------------------------------------------------------- OBJ and MTL
def _obj_line():
    num = st.one_of(st.floats(width=32).map(repr), st.integers(-9, 9).map(str),
                    st.sampled_from(["1e308", "-1e999", "nan", "0", "-0", "1_0"]))
    idx = st.one_of(st.integers(-6, 8).map(str), st.sampled_from(["4294967296", "-99999999999999999999", "x"]))
    corner = st.one_of(idx, st.tuples(idx, idx).map("/".join), st.tuples(idx, idx).map("//".join),
                       st.tuples(idx, idx, idx).map("/".join), st.sampled_from(["/", "//1", "1/2/3/4"]))
    # mostly well-formed statements, so that the reader gets past the first line
    return st.one_of(
        st.tuples(st.sampled_from(["v", "vn", "vt"]), st.lists(num, min_size=3, max_size=4)).map(
            lambda a: [a[0], *a[1]]),
        st.lists(idx, min_size=3, max_size=6).map(lambda c: ["f", *c]),
        st.lists(corner, min_size=3, max_size=6).map(lambda c: ["f", *c]),
        st.sampled_from([["usemtl", "m"], ["mtllib", "lib.mtl"], ["g", "x"], ["s", "1"], ["o"], ["#", "c"]]),
        st.tuples(st.sampled_from(["v", "vn", "vt"]), st.lists(num, max_size=8)).map(lambda a: [a[0], *a[1]]),
        st.lists(corner, max_size=3).map(lambda c: ["f", *c]),
        st.sampled_from([["usemtl"], ["usemtl", "nosuch"], ["mtllib", "none.mtl"], ["mtllib"], ["curv", "1"]]),
        st.text(max_size=20).map(lambda t: [t]),
    ).map(" ".join)


def _mtl_line():
    num = st.one_of(st.floats(width=32).map(repr), st.sampled_from(["1e308", "1e999", "nan", "-1", "x"]))
    keys = ["newmtl", "Kd", "Ks", "Ke", "Ns", "Ni", "d", "Tr", "illum", "Roughness", "Mentalness", "Pm",
            "map_Kd", "bump", "Ka", "KD", "newmtl m"]
    return st.one_of(
        st.tuples(st.sampled_from(keys), st.lists(num, min_size=1, max_size=3)).map(lambda a: " ".join([a[0], *a[1]])),
        st.sampled_from(["map_Kd -s 1 1 1 tex.png", "map_Kd tex.png", "map_Kd missing.png", "map_Kd -bad x",
                         "map_Kd -o", "d -halo 0.5", "illum 2.5", "rgb spectral", "Kd spectral x.spd"]),
        st.text(max_size=20),
    )


def _doc(line_strategy):
    return st.tuples(st.lists(line_strategy, max_size=12), st.sampled_from(["\n", "\r\n"])).map(
        lambda a: a[1].join(a[0]).encode("utf-8", "surrogatepass"))


any_obj = st.one_of(st.binary(max_size=300), _doc(_obj_line()))
any_mtl = st.one_of(st.binary(max_size=300), _doc(_mtl_line()),
                    _doc(_mtl_line()).map(lambda b: b"newmtl m\n" + b))

LIB = b"newmtl m\nKd 0.5 0.5 0.5\n"


def _read_or_report(data: bytes, name: str, load) -> None:
    """Write ``data`` as ``name`` beside a small MTL library and a texture;
    ``load`` must accept it or raise SceneError at one of its lines."""
    from drpt.imageio import write_image

    with tempfile.TemporaryDirectory() as d:
        folder = Path(d)
        (folder / "lib.mtl").write_bytes(LIB)
        write_image(folder / "tex.png", np.full((1, 1, 3), 0.5))
        p = folder / name
        p.write_bytes(data)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                load(p)
        except SceneError as e:
            assert e.path == str(p.resolve()), e
            assert e.line is not None, e
            assert 1 <= e.line <= len(re.split(rb"\r\n|\r|\n", data)), (str(e), data)
            assert len(str(e).splitlines()) == 1, str(e)


def _no_other_breaks(data: bytes) -> bool:
    text = data.decode("utf-8", "replace")
    return not any(c in text for c in OTHER_BREAKS)


@SETTINGS
@given(any_obj.filter(_no_other_breaks))
def test_obj_reads_or_reports_a_line(data):
    _read_or_report(data, "m.obj", load_obj)


@SETTINGS
@given(any_mtl.filter(_no_other_breaks))
def test_mtl_reads_or_reports_a_line(data):
    _read_or_report(data, "m.mtl", load_mtl)


_SEPARATED = st.tuples(st.lists(st.sampled_from(["v 0 0 0", "f 1 2 3", "# c", "", "newmtl a", "Kd 1"]), max_size=4),
                      st.sampled_from(list(OTHER_BREAKS)), st.sampled_from(["f 1 2 0", "v x", "Kd x"])).map(
    lambda a: (a[1].join(a[0] + [a[2]])).encode())


@FEW
@given(_SEPARATED)
def test_obj_lines_with_any_separator(data):
    _read_or_report(data, "m.obj", load_obj)


@FEW
@given(_SEPARATED)
def test_mtl_lines_with_any_separator(data):
    _read_or_report(data, "m.mtl", load_mtl)


# A valid mesh: statements in file order; each face names vertices defined so
# far, by positive or negative index, with or without a normal / uv.
@st.composite
def obj_mesh(draw):
    coords = st.floats(-1e6, 1e6, allow_nan=False, width=64)
    lines, verts, tris = ["vn 0 0 1", "vt 0.5 0.5"], [], []
    for _ in range(draw(st.integers(1, 12))):
        for _ in range(draw(st.integers(0, 5))):
            v = tuple(draw(coords) for _ in range(3))
            verts.append(v)
            lines.append("v " + " ".join(repr(c) for c in v) + draw(st.sampled_from(["", " 1.0"])))
        if len(verts) < 3:
            continue
        k = draw(st.integers(3, 7))
        ids = [draw(st.integers(0, len(verts) - 1)) for _ in range(k)]
        form = draw(st.sampled_from(["{}", "{}//1", "{}/1/1", "{}/1", "{}//-1"]))
        corners = [form.format(i + 1 if draw(st.booleans()) else i - len(verts)) for i in ids]
        lines.append(draw(st.sampled_from(["f ", "f\t", "f  "])) + " ".join(corners))
        tris += [(verts[ids[0]], verts[ids[j]], verts[ids[j + 1]]) for j in range(1, k - 1)]
    return "\n".join(lines) + draw(st.sampled_from(["", "\n"])), tris


@SETTINGS
@given(obj_mesh())
def test_obj_mesh_reads_back_its_triangles(mesh):
    text, tris = mesh
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "m.obj"
        p.write_text(text)
        got = load_obj(p)
    assert len(got) == len(tris)
    expect = np.array(tris, dtype=np.float64).reshape(-1, 3, 3)
    np.testing.assert_array_equal(got.positions, expect)
