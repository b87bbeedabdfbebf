"""drpt.errors: the location type Loc, SceneError and SceneWarning built on it, and the
one-line format of located messages."""

from __future__ import annotations

import dataclasses
import pickle
import warnings
from pathlib import Path

import pytest

from drpt.errors import DrptError, Loc, SceneError, SceneWarning, located, showwarning


def test_loc_prints_file_and_line_or_what_is_known():
    assert str(Loc("a.mtl", 3)) == "a.mtl:3"
    assert str(Loc("a.mtl")) == "a.mtl"
    assert str(Loc()) == "<input>"
    assert str(Loc(None, 7)) == "<input>:7"


def test_loc_is_a_value():
    p = Path("/x/scene.txt")
    assert Loc(p, 2) == Loc(str(p), 2) and hash(Loc(p, 2)) == hash(Loc(str(p), 2))
    assert Loc(p, 2).file == "/x/scene.txt" and isinstance(Loc(p).file, str)
    assert Loc(p, 2) != Loc(p, 3) and Loc(p, 2) != Loc("/x/other.txt", 2)
    assert Loc("a", True).line == 1 and type(Loc("a", True).line) is int
    with pytest.raises(dataclasses.FrozenInstanceError):
        Loc("a", 1).line = 2


def test_located_is_the_one_format():
    assert located("bad", Loc("m.obj", 4)) == "m.obj:4: bad"
    assert located("bad", Loc("m.obj")) == "m.obj: bad"
    assert located("bad", None) == "bad"


def test_scene_error_takes_a_loc():
    e = SceneError(Loc("s.txt", 12), "expected a number")
    assert str(e) == "s.txt:12: expected a number" and isinstance(e, DrptError)
    assert (e.loc, e.path, e.line, e.message) == (Loc("s.txt", 12), "s.txt", 12, "expected a number")
    assert str(SceneError(Loc("s.txt"), "empty")) == "s.txt: empty"
    back = pickle.loads(pickle.dumps(e))  # a Dask worker's error comes back whole
    assert type(back) is SceneError and back.loc == e.loc and str(back) == str(e)
    with pytest.raises(TypeError, match="takes a Loc"):
        SceneError("s.txt", "the old (path, line, message) form")  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        SceneError("s.txt", 3, "the old (path, line, message) form")  # type: ignore[call-arg]


def test_scene_warning_carries_its_loc_and_prints_as_warn(capsys):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        warnings.warn(SceneWarning(Loc("lib.mtl", 5), "MTL statement 'zz' is not supported"), stacklevel=1)
    (w,) = caught
    assert w.category is SceneWarning and w.message.loc == Loc("lib.mtl", 5)
    assert str(w.message) == "lib.mtl:5: MTL statement 'zz' is not supported"
    showwarning(w.message, w.category, w.filename, w.lineno)
    assert str(SceneWarning(None, "no place")) == "no place"
    assert capsys.readouterr().err == "drpt: warning: lib.mtl:5: MTL statement 'zz' is not supported\n"
    with pytest.raises(TypeError, match="takes a Loc"):
        SceneWarning("lib.mtl:5", "a string is not a Loc")  # type: ignore[arg-type]
